//! Grey images for photo-consistency: luminance as f32, Gaussian smoothing, and bilinear
//! sampling of affine pixel grids.

use nalgebra::Vector2;
use rayon::prelude::*;

/// A grey image as f32 with bilinear sampling.
pub struct GreyImage {
    w: usize,
    h: usize,
    px: Vec<f32>,
}

impl GreyImage {
    pub fn from_rgb(img: &image::RgbImage) -> GreyImage {
        GreyImage {
            w: img.width() as usize,
            h: img.height() as usize,
            px: img
                .pixels()
                .map(|p| 0.299 * p.0[0] as f32 + 0.587 * p.0[1] as f32 + 0.114 * p.0[2] as f32)
                .collect(),
        }
    }

    /// The image smoothed by a separable Gaussian of `sigma` pixels (kernel radius 3 sigma,
    /// clamped at the borders); `sigma <= 0` returns a copy.
    pub fn blurred(&self, sigma: f64) -> GreyImage {
        if sigma <= 0.0 {
            return GreyImage {
                w: self.w,
                h: self.h,
                px: self.px.clone(),
            };
        }
        let r = (3.0 * sigma).ceil() as usize;
        let kernel: Vec<f32> = (0..=2 * r)
            .map(|i| {
                let d = i as f64 - r as f64;
                (-(d * d) / (2.0 * sigma * sigma)).exp() as f32
            })
            .collect();
        let total: f32 = kernel.iter().sum();
        let kernel: Vec<f32> = kernel.iter().map(|k| k / total).collect();
        let (w, h) = (self.w, self.h);
        // Horizontal pass, row by row, on a row padded by clamping. Each output row is
        // written (not accumulated) first: accumulating into freshly zeroed memory would
        // fault every page twice (the shared zero page, then a copy on write).
        let mut tmp = vec![0.0f32; w * h];
        tmp.par_chunks_mut(w)
            .zip(self.px.par_chunks(w))
            .for_each_init(
                || vec![0.0f32; w + 2 * r],
                |padded, (out, row)| {
                    padded[..r].fill(row[0]);
                    padded[r..r + w].copy_from_slice(row);
                    padded[r + w..].fill(row[w - 1]);
                    weighted_rows(&kernel, |k| &padded[k..k + w], out);
                },
            );
        // Vertical pass: each output row is a weighted sum of whole rows.
        let tmp_row = |y: i64| {
            let sy = y.clamp(0, h as i64 - 1) as usize;
            &tmp[sy * w..(sy + 1) * w]
        };
        let mut px = vec![0.0f32; w * h];
        px.par_chunks_mut(w).enumerate().for_each(|(y, out)| {
            let top = y as i64 - r as i64;
            weighted_rows(&kernel, |k| tmp_row(top + k as i64), out);
        });
        GreyImage {
            w: self.w,
            h: self.h,
            px,
        }
    }

    /// Samples bilinearly the `window` x `window` grid `origin + i du + j dv` (pixels,
    /// i and j from -window/2 to window/2) into `out`; false when a sample leaves the image.
    pub fn sample_grid(
        &self,
        origin: Vector2<f64>,
        du: Vector2<f64>,
        dv: Vector2<f64>,
        window: usize,
        out: &mut [f32],
    ) -> bool {
        let half = (window / 2) as f64;
        // The grid is affine: inside the image iff its four corners are. A small margin
        // below the last row and column keeps every sample's right and lower neighbours in
        // the image despite f32 rounding.
        if self.w.max(self.h) > i32::MAX as usize {
            return false; // beyond the 32-bit pixel indices below (no real image is)
        }
        let (wm, hm) = ((self.w - 1) as f64 - 1e-3, (self.h - 1) as f64 - 1e-3);
        for (si, sj) in [(-half, -half), (half, -half), (-half, half), (half, half)] {
            let q = origin + du * si + dv * sj;
            if !(q.x >= 0.0 && q.y >= 0.0 && q.x <= wm && q.y <= hm) {
                return false;
            }
        }
        let x0 = (origin.x - half * (du.x + dv.x)) as f32;
        let y0 = (origin.y - half * (du.y + dv.y)) as f32;
        let (dux, duy, dvx, dvy) = (du.x as f32, du.y as f32, dv.x as f32, dv.y as f32);
        let w = self.w;
        let p = &self.px;
        for (j, row) in out.chunks_exact_mut(window).take(window).enumerate() {
            let (rx, ry) = (x0 + dvx * j as f32, y0 + dvy * j as f32);
            for (i, o) in row.iter_mut().enumerate() {
                let (x, y) = (rx + dux * i as f32, ry + duy * i as f32);
                // SAFETY: the grid is affine and its four corners lie in
                // [0, w - 1 - 1e-3] x [0, h - 1 - 1e-3] (checked above), so every sample
                // does: x and y are finite, non-negative and below w - 1 and h - 1, and
                // k + w + 1 < w h.
                // (32-bit conversions: the images are far smaller than 2^31 pixels.)
                let (xi, yi): (i32, i32) = unsafe { (x.to_int_unchecked(), y.to_int_unchecked()) };
                let (fx, fy) = (x - xi as f32, y - yi as f32);
                let k = yi as usize * w + xi as usize;
                let (a, b, c, d) = unsafe {
                    (
                        *p.get_unchecked(k),
                        *p.get_unchecked(k + 1),
                        *p.get_unchecked(k + w),
                        *p.get_unchecked(k + w + 1),
                    )
                };
                let top = a + (b - a) * fx;
                let bottom = c + (d - c) * fx;
                *o = top + (bottom - top) * fy;
            }
        }
        true
    }
}

/// `out` = sum over k of `kernel[k] * row(k)`, written before it is accumulated.
fn weighted_rows<'a>(kernel: &[f32], row: impl Fn(usize) -> &'a [f32], out: &mut [f32]) {
    out.iter_mut()
        .zip(row(0))
        .for_each(|(o, v)| *o = kernel[0] * v);
    for (k, kv) in kernel.iter().enumerate().skip(1) {
        out.iter_mut().zip(row(k)).for_each(|(o, v)| *o += kv * v);
    }
}

/// Grey images of a frame.
pub fn grey(images: &[image::RgbImage]) -> Vec<GreyImage> {
    images.par_iter().map(GreyImage::from_rgb).collect()
}
