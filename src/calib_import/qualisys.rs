//! Qualisys Track Manager calibration (`.qca.txt`, XML), read as Pose2Sim reads it: the
//! video cameras of `<cameras><camera serial=... model=...>` (a model naming "video" or
//! "none"; marker cameras are left out), named by serial number in natural order.
//!
//! - `<fov_video left top right bottom>`: the image is `right - left + 1` by
//!   `bottom - top + 1` pixels, cropped from the sensor at (`left`, `top`).
//! - `<intrinsic>`: `focalLengthU/V`, `centerPointU/V`, `radialDistortion1/2`,
//!   `tangentalDistortion1/2` in 1/64 pixel; the principal point is the sensor's, so the
//!   crop's corner is taken off.
//! - `<transform x y z r11 ... r33>`: the camera's pose in the world (camera to world),
//!   millimetres, the matrix read by column; Qualisys's camera looks along its -z with y up,
//!   so a half-turn about x gives OpenCV's camera (z forward, y down).

use super::{revalidate, Imported};
use crate::camera::{check_name, Camera};
use crate::error::{Error, Result};
use nalgebra::{Matrix3, Vector3};
use std::path::Path;

/// Qualisys stores lengths in pixels times 64.
const SUBPIXELS: f64 = 64.0;

/// The key that sorts names as people count: `cam2` before `cam10`.
fn natural_key(name: &str) -> Vec<(u8, u64, String)> {
    let mut out = Vec::new();
    let mut digits = String::new();
    let mut text = String::new();
    for c in name.chars() {
        if c.is_ascii_digit() {
            if !text.is_empty() {
                out.push((1, 0, std::mem::take(&mut text).to_lowercase()));
            }
            digits.push(c);
        } else {
            if !digits.is_empty() {
                out.push((
                    0,
                    digits.parse().unwrap_or(u64::MAX),
                    std::mem::take(&mut digits),
                ));
            }
            text.push(c);
        }
    }
    if !digits.is_empty() {
        out.push((0, digits.parse().unwrap_or(u64::MAX), digits));
    }
    if !text.is_empty() {
        out.push((1, 0, text.to_lowercase()));
    }
    out
}

/// Imports a Qualisys `.qca.txt` calibration.
pub fn from_qca(path: &Path) -> Result<Imported> {
    let text = crate::fsutil::read_to_string(path)?;
    let doc = roxmltree::Document::parse(&text)
        .map_err(|e| Error::invalid(path, format!("not XML: {e}")))?;
    let mut cameras = Vec::new();
    let mut skipped = Vec::new();
    for cam in doc.descendants().filter(|n| {
        n.has_tag_name("camera") && n.parent().is_some_and(|p| p.has_tag_name("cameras"))
    }) {
        let serial = cam.attribute("serial").unwrap_or("").to_string();
        let model = cam.attribute("model").unwrap_or("").to_lowercase();
        if !(model.contains("video") || model.contains("none")) {
            skipped.push(serial);
            continue;
        }
        let bad = |what: String| {
            Error::invalid(
                path,
                format!("camera {}: {what}", crate::text::quoted(&serial)),
            )
        };
        let child = |tag: &str| {
            cam.children()
                .find(|n| n.has_tag_name(tag))
                .ok_or_else(|| bad(format!("no <{tag}> element")))
        };
        let attr = |node: roxmltree::Node, key: &str| -> Result<f64> {
            node.attribute(key)
                .and_then(|v| v.trim().parse::<f64>().ok())
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    bad(format!(
                        "<{}> needs a number '{key}'",
                        node.tag_name().name()
                    ))
                })
        };
        check_name(&serial).map_err(|m| bad(m.0))?;
        let fov = child("fov_video")?;
        let (left, top) = (attr(fov, "left")?, attr(fov, "top")?);
        let (right, bottom) = (attr(fov, "right")?, attr(fov, "bottom")?);
        let (w, h) = (right - left + 1.0, bottom - top + 1.0);
        if !(w >= 1.0 && h >= 1.0 && w < 1e6 && h < 1e6 && w.fract() == 0.0 && h.fract() == 0.0) {
            return Err(bad(format!("<fov_video> gives a {w} x {h} image")));
        }
        let i = child("intrinsic")?;
        let sub = |key: &str| -> Result<f64> { Ok(attr(i, key)? / SUBPIXELS) };
        let optional = |key: &str| -> Result<f64> {
            if i.attribute(key).is_some() {
                sub(key)
            } else {
                Ok(0.0)
            }
        };
        let tr = child("transform")?;
        let m = |key: &str| attr(tr, key);
        // Read by column: r11 r12 r13 fill the first column.
        let columns = [
            m("r11")?,
            m("r12")?,
            m("r13")?,
            m("r21")?,
            m("r22")?,
            m("r23")?,
            m("r31")?,
            m("r32")?,
            m("r33")?,
        ];
        let camera_to_world = Matrix3::from_column_slice(&columns);
        let centre = Vector3::new(m("x")?, m("y")?, m("z")?) / 1000.0;
        // World to camera, then Qualisys's camera axes turned to OpenCV's.
        let flip = Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0));
        let r = flip * camera_to_world.transpose();
        let t = -(r * centre);
        let camera = Camera {
            name: serial.clone(),
            width: w as u32,
            height: h as u32,
            fx: sub("focalLengthU")?,
            fy: sub("focalLengthV")?,
            cx: sub("centerPointU")? - left,
            cy: sub("centerPointV")? - top,
            skew: 0.0,
            dist: [
                sub("radialDistortion1")?,
                sub("radialDistortion2")?,
                sub("tangentalDistortion1")?,
                sub("tangentalDistortion2")?,
                optional("radialDistortion3")?,
            ],
            r: crate::camera::nearest_rotation(&r),
            t,
        };
        camera.validate().map_err(|m| bad(m.0))?;
        cameras.push(camera);
    }
    if cameras.is_empty() {
        return Err(Error::invalid(
            path,
            format!(
                "holds no video camera (<cameras><camera model=\"... Video\">){}",
                if skipped.is_empty() {
                    String::new()
                } else {
                    format!("; {} marker camera(s) left out", skipped.len())
                }
            ),
        ));
    }
    cameras.sort_by_key(|c| natural_key(&c.name));
    let mut warnings = Vec::new();
    if !skipped.is_empty() {
        warnings.push(format!(
            "{} marker camera(s) left out (only video cameras film the subject): {}",
            skipped.len(),
            skipped.join(", ")
        ));
    }
    revalidate(path, cameras, warnings)
}
