//! Caps on what the pipeline reads, so that a damaged or hostile capture gets a clear error
//! instead of exhausting memory. Each cap has a default and an environment variable to raise
//! it (the error names the variable).

use crate::error::{Error, Result};
use std::path::Path;

/// One cap: its environment variable, default, and unit.
struct Cap {
    env: &'static str,
    default: u64,
    unit: u64,
    unit_name: &'static str,
}

/// Text inputs (YAML, CSV, COLMAP text, OpenCV FileStorage): 64 MB.
const TEXT: Cap = Cap {
    env: "HULLPOSE_MAX_TEXT_MB",
    default: 64,
    unit: 1 << 20,
    unit_name: "MB",
};
/// Mesh files (PLY, OBJ): 2048 MB.
const MESH: Cap = Cap {
    env: "HULLPOSE_MAX_MESH_MB",
    default: 2048,
    unit: 1 << 20,
    unit_name: "MB",
};
/// Image size, checked from the header before decoding: 100 megapixels.
const IMAGE: Cap = Cap {
    env: "HULLPOSE_MAX_IMAGE_MEGAPIXELS",
    default: 100,
    unit: 1_000_000,
    unit_name: "megapixels",
};

impl Cap {
    /// The cap in units (the environment variable when it holds a positive number).
    fn units(&self) -> u64 {
        std::env::var(self.env)
            .ok()
            .and_then(|v| v.trim().parse::<u64>().ok())
            .filter(|&v| v > 0)
            .unwrap_or(self.default)
    }

    fn bytes(&self) -> u64 {
        self.units().saturating_mul(self.unit)
    }

    fn refuse(&self, path: &Path, what: &str, size: u64) -> Error {
        Error::invalid(
            path,
            format!(
                "{what} is {:.1} {}, more than the {} {} allowed; if the file is genuine, \
                 raise the cap with the environment variable {}",
                size as f64 / self.unit as f64,
                self.unit_name,
                self.units(),
                self.unit_name,
                self.env
            ),
        )
    }
}

/// The size of the file at `path`, checked against `cap`.
fn check_file(path: &Path, cap: &Cap, what: &str) -> Result<u64> {
    let size = std::fs::metadata(path)
        .map_err(|e| Error::io(path, e))?
        .len();
    if size > cap.bytes() {
        return Err(cap.refuse(path, what, size));
    }
    Ok(size)
}

/// Checks a text input's size before it is read.
pub fn check_text_file(path: &Path) -> Result<u64> {
    check_file(path, &TEXT, "the text file")
}

/// Checks a mesh file's size before it is read.
pub fn check_mesh_file(path: &Path) -> Result<u64> {
    check_file(path, &MESH, "the mesh file")
}

/// Checks an image's dimensions (from its header) before it is decoded.
pub fn check_image(path: &Path, width: u32, height: u32) -> Result<()> {
    let pixels = width as u64 * height as u64;
    if pixels > IMAGE.units().saturating_mul(IMAGE.unit) {
        return Err(IMAGE.refuse(path, &format!("the image ({width}x{height})"), pixels));
    }
    Ok(())
}

/// The largest allocation an image decoder may make, bytes: the pixel cap at 4 bytes per
/// pixel (RGBA 8-bit) plus slack.
pub fn image_alloc_bytes() -> u64 {
    IMAGE
        .units()
        .saturating_mul(IMAGE.unit)
        .saturating_mul(4)
        .saturating_add(64 << 20)
}
