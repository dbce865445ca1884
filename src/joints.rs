//! Joint positions per frame and bone: the CSV schema shared by ground truth and the
//! pipeline's pose output (`frame,bone,head_x,head_y,head_z,tail_x,tail_y,tail_z`, metres).

use crate::error::{Error, Result};
use nalgebra::Vector3;
use std::fmt::Write as _;
use std::path::Path;

/// The CSV header line.
pub const HEADER: &str = "frame,bone,head_x,head_y,head_z,tail_x,tail_y,tail_z";

/// One row: a bone's head and tail at one frame, world metres.
#[derive(Debug, Clone, PartialEq)]
pub struct JointRow {
    pub frame: u32,
    pub bone: String,
    pub head: Vector3<f64>,
    pub tail: Vector3<f64>,
}

/// Parses joints.csv text; `path` names the file in errors.
pub fn parse(path: &Path, text: &str) -> Result<Vec<JointRow>> {
    Ok(parse_frame_bone_rows(path, text, HEADER)?
        .into_iter()
        .map(|(frame, bone, v)| JointRow {
            frame,
            bone,
            head: Vector3::new(v[0], v[1], v[2]),
            tail: Vector3::new(v[3], v[4], v[5]),
        })
        .collect())
}

/// Parses a CSV of `frame,bone` and six finite numbers per row under `header` (the schema
/// of joints.csv and poses.csv).
pub fn parse_frame_bone_rows(
    path: &Path,
    text: &str,
    header: &str,
) -> Result<Vec<(u32, String, [f64; 6])>> {
    let mut lines = text.lines().enumerate();
    match lines.next() {
        Some((_, h)) if h.trim() == header => {}
        _ => {
            return Err(Error::invalid(
                path,
                format!("the first line must be the header '{header}'"),
            ))
        }
    }
    let mut rows = Vec::new();
    for (i, line) in lines {
        if line.trim().is_empty() {
            continue;
        }
        let bad = |msg: &str| Error::invalid(path, format!("line {}: {msg}", i + 1));
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        if f.len() != 8 {
            return Err(bad(&format!("expected 8 fields, found {}", f.len())));
        }
        let frame = f[0]
            .parse()
            .map_err(|_| bad("the frame must be a non-negative integer"))?;
        let mut v = [0.0; 6];
        for k in 0..6 {
            v[k] = f[k + 2]
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| bad(&format!("field {} is not a finite number", k + 3)))?;
        }
        rows.push((frame, f[1].to_string(), v));
    }
    Ok(rows)
}

/// Reads joints.csv.
pub fn read(path: &Path) -> Result<Vec<JointRow>> {
    parse(path, &crate::fsutil::read_to_string(path)?)
}

/// The CSV text for `rows`.
pub fn to_csv(rows: &[JointRow]) -> String {
    let mut s = format!("{HEADER}\n");
    for r in rows {
        let _ = writeln!(
            s,
            "{},{},{:?},{:?},{:?},{:?},{:?},{:?}",
            r.frame, r.bone, r.head.x, r.head.y, r.head.z, r.tail.x, r.tail.y, r.tail.z
        );
    }
    s
}

/// Writes joints.csv atomically.
pub fn write(path: &Path, rows: &[JointRow]) -> Result<()> {
    crate::fsutil::write_atomic(path, to_csv(rows).as_bytes())
}
