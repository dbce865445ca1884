//! PNG writing (atomic, fast compression).

use crate::error::Result;
use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::{ExtendedColorType, ImageEncoder};
use std::path::Path;

fn write_png(path: &Path, data: &[u8], w: u32, h: u32, color: ExtendedColorType) -> Result<()> {
    crate::fsutil::write_atomic_with(path, |out| {
        PngEncoder::new_with_quality(out, CompressionType::Fast, FilterType::Adaptive)
            .write_image(data, w, h, color)
            .map_err(|e| std::io::Error::other(e.to_string()))
    })
}

/// Writes an 8-bit RGB PNG atomically.
pub fn write_rgb(path: &Path, img: &image::RgbImage) -> Result<()> {
    write_png(
        path,
        img.as_raw(),
        img.width(),
        img.height(),
        ExtendedColorType::Rgb8,
    )
}

/// Writes an 8-bit grey PNG atomically.
pub fn write_gray(path: &Path, img: &image::GrayImage) -> Result<()> {
    write_png(
        path,
        img.as_raw(),
        img.width(),
        img.height(),
        ExtendedColorType::L8,
    )
}
