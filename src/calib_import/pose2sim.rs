//! Pose2Sim / anipose calibration TOML: one table per camera (`[cam_01]`, any name but
//! `metadata`) with `name`, `size = [width, height]`, `matrix` (3x3 K), `distortions`
//! (k1 k2 p1 p2, or with k3), `rotation` (the world-to-camera rotation as a Rodrigues
//! vector, OpenCV's convention), `translation` (world to camera) and optional `fisheye`.
//! Pose2Sim writes metres; anipose writes its calibration board's unit (often mm):
//! `--units` scales the translations. The pixel convention is OpenCV's, which is ours.

use super::{revalidate, Imported};
use crate::camera::check_name;
use crate::error::{Error, Result};
use nalgebra::{Matrix3, Rotation3, Vector3};
use std::path::Path;

/// Reads a numeric TOML value (integer or float).
fn number(v: &toml::Value) -> Option<f64> {
    v.as_float().or_else(|| v.as_integer().map(|i| i as f64))
}

/// A flat list of `n` numbers from `table[key]` (nested arrays flattened row by row).
fn numbers(
    path: &Path,
    section: &str,
    table: &toml::Table,
    key: &str,
    lengths: &[usize],
) -> Result<Vec<f64>> {
    let bad = |what: String| Error::invalid(path, format!("[{section}] key '{key}': {what}"));
    let value = table.get(key).ok_or_else(|| bad("missing".into()))?;
    let mut out = Vec::new();
    // Depth-first, in order: rows of a matrix one after the other.
    fn flatten(v: &toml::Value, out: &mut Vec<f64>) -> bool {
        match v {
            toml::Value::Array(items) => items.iter().all(|i| flatten(i, out)),
            other => number(other).map(|x| out.push(x)).is_some(),
        }
    }
    let ok = flatten(value, &mut out);
    if !ok || !lengths.contains(&out.len()) || out.iter().any(|x| !x.is_finite()) {
        return Err(bad(format!(
            "expected {} finite numbers",
            lengths
                .iter()
                .map(|n| n.to_string())
                .collect::<Vec<_>>()
                .join(" or ")
        )));
    }
    Ok(out)
}

/// Imports a Pose2Sim or anipose calibration TOML; translations are multiplied by
/// `metres_per_unit` (1 for Pose2Sim's metres, 0.001 for millimetres).
pub fn from_toml(path: &Path, metres_per_unit: f64) -> Result<Imported> {
    let text = crate::fsutil::read_to_string(path)?;
    let doc: toml::Table = text.parse().map_err(|e: toml::de::Error| {
        Error::invalid(
            path,
            format!("not TOML: {}", crate::yaml::shorten(&e.to_string())),
        )
    })?;
    let mut cameras = Vec::new();
    let mut warnings = Vec::new();
    for (section, value) in &doc {
        if section == "metadata" {
            continue;
        }
        let Some(table) = value.as_table() else {
            warnings.push(format!("key '{section}' is not a camera table; ignored"));
            continue;
        };
        let name = match table.get("name") {
            Some(toml::Value::String(s)) => s.clone(),
            Some(toml::Value::Integer(i)) => i.to_string(),
            _ => section.clone(),
        };
        check_name(&name).map_err(|m| {
            Error::invalid(
                path,
                format!("[{section}]: camera {}: {m}", crate::text::quoted(&name)),
            )
        })?;
        if table.get("fisheye").and_then(toml::Value::as_bool) == Some(true) {
            return Err(Error::invalid(
                path,
                format!(
                    "[{section}]: a fisheye camera; only the pinhole model with k1 k2 p1 p2 k3 is \
                     supported"
                ),
            ));
        }
        let size = numbers(path, section, table, "size", &[2])?;
        let whole = |v: f64| ((1.0..1e6).contains(&v) && v.fract() == 0.0).then_some(v as u32);
        let (Some(width), Some(height)) = (whole(size[0]), whole(size[1])) else {
            return Err(Error::invalid(
                path,
                format!("[{section}] key 'size': [width, height] must be whole numbers of pixels"),
            ));
        };
        let k = numbers(path, section, table, "matrix", &[9])?;
        if k[3] != 0.0 || k[6] != 0.0 || k[7] != 0.0 || k[8] != 1.0 {
            return Err(Error::invalid(
                path,
                format!("[{section}] key 'matrix' must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]]"),
            ));
        }
        let d = numbers(path, section, table, "distortions", &[4, 5])?;
        let mut dist = [0.0; 5];
        dist[..d.len()].copy_from_slice(&d);
        let rot = numbers(path, section, table, "rotation", &[3, 9])?;
        let r = if rot.len() == 3 {
            *Rotation3::new(Vector3::new(rot[0], rot[1], rot[2])).matrix()
        } else {
            Matrix3::from_row_slice(&rot)
        };
        let t: Vec<f64> = numbers(path, section, table, "translation", &[3])?
            .iter()
            .map(|v| v * metres_per_unit)
            .collect();
        let cam = super::camera_from_k(name, (width, height), &k, dist, r, &t);
        cam.validate().map_err(|m| {
            Error::invalid(
                path,
                format!(
                    "[{section}]: camera {}: {m}",
                    crate::text::quoted(&cam.name)
                ),
            )
        })?;
        cameras.push(cam);
    }
    if cameras.is_empty() {
        return Err(Error::invalid(path, "holds no camera table ([cam_01] with name, size, matrix, distortions, rotation, translation)"));
    }
    warnings.extend(super::unit_warning(&cameras));
    revalidate(path, cameras, warnings)
}
