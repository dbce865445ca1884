//! Pose evaluation: the mean joint position error per frame against ground_truth/joints.csv
//! (shared/dataset-format.md: the mean, over all bones, of the distances between estimated
//! and true heads and between estimated and true tails), as a table, a CSV and a PNG plot.

use crate::error::{Error, Result};
use crate::joints::JointRow;
use crate::plot::{LinePlot, Series, COLOURS};
use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::Path;

/// Mean joint error per frame (metres) of `estimate` against `truth`, for every frame of
/// the estimate. A bone missing from the truth at an estimated frame is an error naming it.
pub fn joint_errors(
    truth: &[JointRow],
    estimate: &[JointRow],
    truth_path: &Path,
) -> Result<Vec<(u32, f64)>> {
    let index: HashMap<(u32, &str), &JointRow> = truth
        .iter()
        .map(|r| ((r.frame, r.bone.as_str()), r))
        .collect();
    let mut per_frame: std::collections::BTreeMap<u32, (f64, usize)> = Default::default();
    for r in estimate {
        let t = index.get(&(r.frame, r.bone.as_str())).ok_or_else(|| {
            Error::invalid(
                truth_path,
                format!("has no row for frame {} bone '{}'", r.frame, r.bone),
            )
        })?;
        let e = per_frame.entry(r.frame).or_insert((0.0, 0));
        e.0 += (r.head - t.head).norm() + (r.tail - t.tail).norm();
        e.1 += 2;
    }
    Ok(per_frame
        .into_iter()
        .map(|(f, (sum, n))| (f, sum / n as f64))
        .collect())
}

/// Errors of several methods (name, per-frame errors in metres) over the same frames.
pub type MethodErrors = Vec<(String, Vec<(u32, f64)>)>;

/// The CSV: `frame,<method>...` in centimetres.
pub fn to_csv(errors: &MethodErrors) -> String {
    let mut s = String::from("frame");
    for (m, _) in errors {
        let _ = write!(s, ",{m}_cm");
    }
    s.push('\n');
    for (i, (frame, _)) in errors
        .first()
        .map_or(&Vec::new(), |e| &e.1)
        .iter()
        .enumerate()
    {
        let _ = write!(s, "{frame}");
        for (_, e) in errors {
            let _ = write!(s, ",{:.4}", e.get(i).map_or(f64::NAN, |x| x.1) * 100.0);
        }
        s.push('\n');
    }
    s
}

/// A printed table in centimetres, with each method's worst frame.
pub fn table(errors: &MethodErrors) -> String {
    let mut s = format!("{:>6}", "frame");
    for (m, _) in errors {
        let _ = write!(s, " {m:>9}");
    }
    s += "   (mean joint error, cm)\n";
    for (i, (frame, _)) in errors
        .first()
        .map_or(&Vec::new(), |e| &e.1)
        .iter()
        .enumerate()
    {
        let _ = write!(s, "{frame:>6}");
        for (_, e) in errors {
            let _ = write!(s, " {:>9.2}", e.get(i).map_or(f64::NAN, |x| x.1) * 100.0);
        }
        s.push('\n');
    }
    let _ = write!(s, "{:>6}", "worst");
    for (_, e) in errors {
        let _ = write!(
            s,
            " {:>9.2}",
            e.iter().map(|x| x.1).fold(0.0, f64::max) * 100.0
        );
    }
    s.push('\n');
    s
}

/// The plot of error against frame, one line per method, with a 1 cm reference line.
pub fn plot(errors: &MethodErrors, title: &str) -> image::RgbImage {
    LinePlot {
        title: title.to_string(),
        x_label: "frame".into(),
        y_label: "mean joint error (cm)".into(),
        series: errors
            .iter()
            .enumerate()
            .map(|(i, (m, e))| Series {
                name: m.clone(),
                colour: COLOURS[i % COLOURS.len()],
                points: e.iter().map(|&(f, x)| (f as f64, x * 100.0)).collect(),
            })
            .collect(),
        references: vec![(1.0, "1 cm".into())],
    }
    .render()
}

/// Writes the CSV and the PNG into `dir` as `<stem>.csv` and `<stem>.png`.
pub fn write(
    dir: &Path,
    stem: &str,
    errors: &MethodErrors,
    title: &str,
) -> Result<Vec<std::path::PathBuf>> {
    let csv = dir.join(format!("{stem}.csv"));
    crate::fsutil::write_atomic(&csv, to_csv(errors).as_bytes())?;
    let png = dir.join(format!("{stem}.png"));
    crate::imageio::write_rgb(&png, &plot(errors, title))?;
    Ok(vec![csv, png])
}
