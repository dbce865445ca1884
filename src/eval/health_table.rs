//! The fit's health over the frames (`pipeline evaluate`, with or without ground truth):
//! the silhouette IoU and joint-motion columns of the run's fit.csv as a table and a plot.

use crate::error::Result;
use crate::plot::{LinePlot, Series, COLOURS};
use crate::stages::fit::{parse_health, HealthRow};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The health rows of the run's fit.csv (`output`/fit.csv), if it exists and has them.
pub fn read(output: &Path) -> Result<Vec<HealthRow>> {
    let path = output.join("fit.csv");
    if !path.is_file() {
        return Ok(Vec::new());
    }
    parse_health(&path, &crate::fsutil::read_to_string(&path)?)
}

/// A printed table of health rows.
pub fn table(rows: &[HealthRow]) -> String {
    let mut s = format!(
        "{:>6}  {:>13}  {:>6}  {:>9}  {:>10}  {:>10}  {:>13}  {:>11}  {:>14}  flags\n",
        "frame",
        "status",
        "rounds",
        "IoU worst",
        "(camera)",
        "IoU median",
        "joint motion",
        "unexplained",
        "recovery"
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{:>6}  {:>13}  {:>6}  {:>9.3}  {:>10}  {:>10.3}  {:>10.1} cm  {:>7} cm2  {:>14}  {}",
            r.frame,
            r.status,
            r.iterations,
            r.iou_worst,
            r.iou_worst_camera,
            r.iou_median,
            100.0 * r.joint_motion,
            r.unexplained_cm2.map_or("-".into(), |a| format!("{a:.0}")),
            r.recovery,
            r.flags
        );
    }
    s
}

/// The plot of the worst and median silhouette IoU over the frames, with the reference
/// frame's worst IoU times 0.9 (where tracking has clearly lost the silhouettes) as a
/// reference line; written to `dir`/fit_health.png.
pub fn write_plot(dir: &Path, rows: &[HealthRow]) -> Result<PathBuf> {
    let reference = rows
        .iter()
        .find(|r| r.status == "reference")
        .map_or(1.0, |r| r.iou_worst);
    let series = |name: &str, colour: usize, f: fn(&HealthRow) -> f64| Series {
        name: name.into(),
        colour: COLOURS[colour],
        points: rows.iter().map(|r| (r.frame as f64, f(r))).collect(),
    };
    let plot = LinePlot {
        title: "fit health: the posed model against the silhouettes".into(),
        x_label: "frame".into(),
        y_label: "silhouette IoU".into(),
        series: vec![
            series("worst camera", 0, |r| r.iou_worst),
            series("median", 1, |r| r.iou_median),
        ],
        references: vec![(0.9 * reference, "0.9 x t0 worst".into())],
    };
    let path = dir.join("fit_health.png");
    crate::imageio::write_rgb(&path, &plot.render())?;
    Ok(path)
}
