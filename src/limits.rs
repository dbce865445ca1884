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

    /// The error for a file that holds more than the cap (its size unknown beyond it).
    fn refuse_over(&self, path: &Path, what: &str) -> Error {
        Error::invalid(
            path,
            format!(
                "{what} holds more than the {} {} allowed; if the file is genuine, raise the \
                 cap with the environment variable {}",
                self.units(),
                self.unit_name,
                self.env
            ),
        )
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

/// Opens the input file at `path` for reading, refusing anything that is not a regular file
/// (a FIFO would block, a device such as /dev/urandom never ends, a folder cannot be read):
/// checked before opening (following symlinks), and again on the opened handle, which is
/// opened without blocking so that a FIFO swapped in between cannot hang the run.
pub fn open_regular(path: &Path) -> Result<std::fs::File> {
    use std::os::unix::fs::OpenOptionsExt;
    let not_regular = |kind: &str| {
        Error::invalid(
            path,
            format!("is {kind}, not a regular file; give the path of a regular file"),
        )
    };
    let kind = |meta: &std::fs::Metadata| {
        use std::os::unix::fs::FileTypeExt;
        let t = meta.file_type();
        if t.is_dir() {
            "a folder"
        } else if t.is_fifo() {
            "a FIFO (named pipe)"
        } else if t.is_char_device() || t.is_block_device() {
            "a device"
        } else if t.is_socket() {
            "a socket"
        } else {
            "not a regular file"
        }
    };
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        return Err(not_regular(kind(&meta)));
    }
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)
        .map_err(|e| Error::io(path, e))?;
    let meta = file.metadata().map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        return Err(not_regular(kind(&meta)));
    }
    Ok(file)
}

/// Reads the regular file at `path` whole, reading at most `cap` bytes plus one whatever
/// its metadata claims, and refusing it when it holds more.
fn read_capped(path: &Path, cap: &Cap, what: &str) -> Result<Vec<u8>> {
    use std::io::Read;
    let file = open_regular(path)?;
    let limit = cap.bytes();
    let mut bytes = Vec::new();
    file.take(limit.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|e| Error::io(path, e))?;
    if bytes.len() as u64 > limit {
        return Err(cap.refuse_over(path, what));
    }
    Ok(bytes)
}

/// Reads a text input (YAML, CSV, COLMAP text, OpenCV FileStorage) within the text cap.
pub fn read_text_file(path: &Path) -> Result<Vec<u8>> {
    read_capped(path, &TEXT, "the text file")
}

/// Reads a cached artifact (grid, observation, body model) within the mesh cap.
pub fn read_cache_file(path: &Path) -> Result<Vec<u8>> {
    read_capped(path, &MESH, "the cached artifact")
}

/// Reads a mesh file (PLY, OBJ) within the mesh cap.
pub fn read_mesh_file(path: &Path) -> Result<Vec<u8>> {
    read_capped(path, &MESH, "the mesh file")
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
