//! The signed distance of a point to the visual hull's surface, below the voxel size
//! (method.md "Stage 2"): each silhouette, distance-transformed, says how far the point's
//! projection lies from the silhouette's outline, and that many pixels at the point's depth
//! are the distance to the camera's silhouette cone. The hull is the intersection of the
//! cones, so its signed distance is about the largest of the cones' (negative inside).
//!
//! A carved occupancy puts its surface where voxels keep or lose their footprint, up to a
//! voxel outside the cones; the zero level of this distance lies on them, within the
//! silhouettes' own pixel precision.

use super::distance::signed_distance;
use super::grid::GridSpec;
use crate::camera::Camera;
use image::GrayImage;
use nalgebra::{Vector2, Vector3};

/// One camera's silhouette as a signed distance, pixels (negative inside), sampled at pixel
/// centres (integer coordinates), exact up to `far` pixels from the outline: it is computed
/// on the silhouette's bounding box grown by `far` + 1 pixels only, and every pixel beyond
/// that box reads `far` (its true distance is larger).
struct OutlineDistance {
    /// The computed window: its first column and row, and its size, pixels.
    x0: usize,
    y0: usize,
    width: usize,
    height: usize,
    /// The image's size, pixels.
    image_width: usize,
    image_height: usize,
    values: Vec<f32>,
    far: f32,
}

impl OutlineDistance {
    fn new(mask: &GrayImage, far: f64) -> OutlineDistance {
        let (iw, ih) = (mask.width() as usize, mask.height() as usize);
        let raw = mask.as_raw();
        let (mut lo, mut hi) = ([usize::MAX; 2], [0usize; 2]);
        for (i, _) in raw.iter().enumerate().filter(|(_, &m)| m >= 128) {
            let (x, y) = (i % iw, i / iw);
            lo = [lo[0].min(x), lo[1].min(y)];
            hi = [hi[0].max(x), hi[1].max(y)];
        }
        // Inside the window the transform is exact: an outside pixel's nearest inside pixel
        // lies in the silhouette's box, an inside pixel's nearest outside pixel next to it.
        let grow = far.clamp(0.0, (iw + ih) as f64).ceil() as usize + 1;
        let (x0, y0, width, height) = if lo[0] == usize::MAX {
            (0, 0, iw, ih) // no silhouette: every pixel is outside
        } else {
            let (x0, y0) = (lo[0].saturating_sub(grow), lo[1].saturating_sub(grow));
            let (x1, y1) = ((hi[0] + grow).min(iw - 1), (hi[1] + grow).min(ih - 1));
            (x0, y0, x1 + 1 - x0, y1 + 1 - y0)
        };
        let inside: Vec<bool> = (0..width * height)
            .map(|i| raw[(y0 + i / width) * iw + x0 + i % width] >= 128)
            .collect();
        let window = GridSpec {
            origin: Vector3::zeros(),
            voxel: 1.0,
            dims: [width, height, 1],
        };
        OutlineDistance {
            x0,
            y0,
            width,
            height,
            image_width: iw,
            image_height: ih,
            values: signed_distance(&window, &inside),
            far: far as f32,
        }
    }

    /// The value at pixel (x, y) of the image.
    fn value(&self, x: usize, y: usize) -> f32 {
        match (x.checked_sub(self.x0), y.checked_sub(self.y0)) {
            (Some(x), Some(y)) if x < self.width && y < self.height => {
                self.values[y * self.width + x]
            }
            _ => self.far,
        }
    }

    /// Bilinear interpolation at pixel position `px` (inside the image).
    fn at(&self, px: &Vector2<f64>) -> f64 {
        let x = px.x.clamp(0.0, (self.image_width - 1) as f64);
        let y = px.y.clamp(0.0, (self.image_height - 1) as f64);
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = (
            (x0 + 1).min(self.image_width - 1),
            (y0 + 1).min(self.image_height - 1),
        );
        let (fx, fy) = (x - x0 as f64, y - y0 as f64);
        let v = |x: usize, y: usize| self.value(x, y) as f64;
        (1.0 - fy) * ((1.0 - fx) * v(x0, y0) + fx * v(x1, y0))
            + fy * ((1.0 - fx) * v(x0, y1) + fx * v(x1, y1))
    }
}

/// The silhouettes of one frame, ready for [`ConeDistance::at`].
pub struct ConeDistance<'a> {
    cams: &'a [Camera],
    outlines: Vec<OutlineDistance>,
    /// Cameras allowed to disagree (the hull's `all_but`).
    all_but: usize,
    /// Fewer seeing cameras: the point counts as outside (the hull's `min_views`).
    min_views: usize,
}

impl<'a> ConeDistance<'a> {
    /// The cones of `masks`, for points in `region`, exact where the distance is within
    /// `reach` metres of the surface; farther, [`ConeDistance::at`] may return a smaller
    /// distance of the same sign, still beyond `reach` (each silhouette is transformed only
    /// near its outline, which makes this several times cheaper).
    pub fn new(
        cams: &'a [Camera],
        masks: &[GrayImage],
        all_but: usize,
        min_views: usize,
        region: &GridSpec,
        reach: f64,
    ) -> ConeDistance<'a> {
        use rayon::prelude::*;
        ConeDistance {
            cams,
            outlines: cams
                .par_iter()
                .zip(masks)
                .map(|(cam, mask)| OutlineDistance::new(mask, reach_in_pixels(cam, region, reach)))
                .collect(),
            all_but,
            min_views,
        }
    }

    /// Signed distance of `x` to the hull's surface, metres (negative inside), near the
    /// surface: per camera whose image holds x's projection, the projection's distance to
    /// the silhouette's outline times depth over focal length; of these, the largest (the
    /// `all_but + 1`-th largest with cameras allowed to disagree). `None` when fewer than
    /// `min_views` cameras see x.
    pub fn at(&self, x: &Vector3<f64>) -> Option<f64> {
        let mut per_camera: Vec<f64> = self
            .cams
            .iter()
            .zip(&self.outlines)
            .filter_map(|(cam, outline)| {
                let (px, z) = cam.project_with_depth(x);
                (z > 0.0 && cam.in_image(&px))
                    .then(|| outline.at(&px) * z * 2.0 / (cam.fx + cam.fy))
            })
            .collect();
        if per_camera.len() < self.min_views.max(self.all_but + 1) {
            return None;
        }
        per_camera.sort_by(|a, b| b.total_cmp(a));
        Some(per_camera[self.all_but])
    }
}

/// How many pixels `reach` metres span at most in `cam`'s image for points of `region`
/// (nearest at one of the box's corners, depth being linear), plus one so that bilinear
/// interpolation next to the window's border stays beyond it; infinite when the camera is
/// within the box.
fn reach_in_pixels(cam: &Camera, region: &GridSpec, reach: f64) -> f64 {
    let (lo, hi) = (region.origin, region.max_corner());
    let nearest = (0..8)
        .map(|k| {
            let corner = Vector3::new(
                if k & 1 == 0 { lo.x } else { hi.x },
                if k & 2 == 0 { lo.y } else { hi.y },
                if k & 4 == 0 { lo.z } else { hi.z },
            );
            cam.project_with_depth(&corner).1
        })
        .fold(f64::INFINITY, f64::min);
    if nearest <= 1e-3 {
        return f64::INFINITY;
    }
    reach * cam.fx.max(cam.fy) / nearest + 1.0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A disc's outline distance is the distance to its circle, within a pixel.
    #[test]
    fn outline_distance_of_a_disc() {
        let (w, h, r) = (120u32, 100u32, 30.0);
        let c = Vector2::new(60.0, 50.0);
        let mask = GrayImage::from_fn(w, h, |x, y| {
            let inside = (Vector2::new(x as f64, y as f64) - c).norm() <= r;
            image::Luma([if inside { 255 } else { 0 }])
        });
        let d = OutlineDistance::new(&mask, f64::INFINITY);
        for k in 0..40 {
            let angle = k as f64 * 0.157;
            for off in [-12.0, -3.3, 0.0, 2.5, 9.0] {
                let p = c + (r + off) * Vector2::new(angle.cos(), angle.sin());
                assert!(
                    (d.at(&p) - off).abs() < 0.8,
                    "angle {angle}, offset {off}: {}",
                    d.at(&p)
                );
            }
        }
    }

    /// Transformed near its outline only, the distance agrees with the full transform
    /// wherever that lies within `far` pixels, and elsewhere keeps its sign and stays beyond.
    #[test]
    fn windowed_outline_distance_agrees_near_the_outline() {
        let (w, h) = (200u32, 150u32);
        let mask = GrayImage::from_fn(w, h, |x, y| {
            let (dx, dy) = (x as f64 - 90.0, y as f64 - 70.0);
            let blob = (dx / 40.0).powi(2) + (dy / 25.0).powi(2) <= 1.0;
            let arm = (100..160).contains(&x) && (60..66).contains(&y);
            image::Luma([if blob || arm { 255 } else { 0 }])
        });
        let full = OutlineDistance::new(&mask, f64::INFINITY);
        let far = 6.0;
        let near = OutlineDistance::new(&mask, far);
        assert!(near.width * near.height < full.width * full.height / 2);
        for y in 0..h as usize {
            for x in 0..w as usize {
                let (a, b) = (full.value(x, y), near.value(x, y));
                if a.abs() <= far as f32 {
                    assert_eq!(a, b, "pixel ({x}, {y})");
                } else {
                    assert!(
                        a.signum() == b.signum() && b.abs() >= far as f32,
                        "({x}, {y})"
                    );
                }
            }
        }
    }
}
