//! Caps on what the pipeline reads, so that a damaged or hostile capture gets a clear error
//! instead of exhausting memory. Each cap has a default and an environment variable to raise
//! it (the error names the variable).

use crate::error::Refusal;
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
/// One video's decoded frames, bounded by their raw size before decoding: 32768 MB.
const DECODED: Cap = Cap {
    env: "HULLPOSE_MAX_DECODED_MB",
    default: 32_768,
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
    /// The cap in units: the environment variable when set (a positive whole number, else
    /// an error naming it), the default otherwise.
    fn units(&self) -> Result<u64> {
        let Some(value) = std::env::var_os(self.env) else {
            return Ok(self.default);
        };
        let text = value.to_string_lossy();
        match text.trim().parse::<u64>() {
            Ok(n) if n > 0 => Ok(n),
            _ => Err(self.bad_variable(&text)),
        }
    }

    /// The error for an environment variable that holds no cap.
    fn bad_variable(&self, value: &str) -> Error {
        Error::Usage(format!(
            "the environment variable {}={value:?} is not a positive whole number of {}; set \
             it to one (the default is {}) or unset it",
            self.env, self.unit_name, self.default
        ))
    }

    /// The cap in the base unit (bytes, pixels).
    fn limit(&self) -> Result<u64> {
        Ok(self.units()?.saturating_mul(self.unit))
    }

    /// The error for a file over the cap (`size` in the base unit, when known).
    fn refuse(&self, path: &Path, what: &str, size: Option<u64>) -> Result<Error> {
        let amount = match size {
            Some(size) => format!(
                "is {:.1} {},",
                size as f64 / self.unit as f64,
                self.unit_name
            ),
            None => "holds".to_string(),
        };
        Ok(Error::invalid(
            path,
            format!(
                "{what} {amount} more than the {} {} allowed; if the file is genuine, raise the \
                 cap with the environment variable {}",
                self.units()?,
                self.unit_name,
                self.env
            ),
        ))
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
    let limit = cap.limit()?;
    let mut bytes = Vec::new();
    file.take(limit.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|e| Error::io(path, e))?;
    if bytes.len() as u64 > limit {
        return Err(cap.refuse(path, what, None)?);
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
    if pixels > IMAGE.limit()? {
        return Err(IMAGE.refuse(path, &format!("the image ({width}x{height})"), Some(pixels))?);
    }
    Ok(())
}

/// Checks the `bytes` a decoding of `path` may write (`what` says what is decoded)
/// against the decoded-video cap.
pub fn check_decoded(path: &Path, what: &str, bytes: u64) -> Result<()> {
    if bytes > DECODED.limit()? {
        return Err(DECODED.refuse(path, what, Some(bytes))?);
    }
    Ok(())
}

/// The largest allocation an image decoder may make, bytes: the pixel cap at 4 bytes per
/// pixel (RGBA 8-bit) plus slack.
pub fn image_alloc_bytes() -> Result<u64> {
    Ok(IMAGE.limit()?.saturating_mul(4).saturating_add(64 << 20))
}

/// The most smoothing iterations a mesh may be given (each costs a pass over the mesh; far
/// beyond a few hundred, Taubin smoothing only burns time).
pub const MAX_SMOOTHING_ITERATIONS: usize = 1000;

/// Refuses a smoothing iteration count (`key` names it) above [`MAX_SMOOTHING_ITERATIONS`].
pub fn check_smoothing(key: &str, iterations: usize) -> std::result::Result<(), Refusal> {
    if iterations > MAX_SMOOTHING_ITERATIONS {
        return Err(format!(
            "{key} = {iterations} is over {MAX_SMOOTHING_ITERATIONS}; 10 (the default) suits \
             most captures"
        )
        .into());
    }
    Ok(())
}
