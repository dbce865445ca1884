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
/// centres (integer coordinates).
struct OutlineDistance {
    width: usize,
    height: usize,
    values: Vec<f32>,
}

impl OutlineDistance {
    fn new(mask: &GrayImage) -> OutlineDistance {
        let (width, height) = (mask.width() as usize, mask.height() as usize);
        let inside: Vec<bool> = mask.as_raw().iter().map(|&m| m >= 128).collect();
        let image = GridSpec {
            origin: Vector3::zeros(),
            voxel: 1.0,
            dims: [width, height, 1],
        };
        OutlineDistance {
            width,
            height,
            values: signed_distance(&image, &inside),
        }
    }

    /// Bilinear interpolation at pixel position `px` (inside the image).
    fn at(&self, px: &Vector2<f64>) -> f64 {
        let x = px.x.clamp(0.0, (self.width - 1) as f64);
        let y = px.y.clamp(0.0, (self.height - 1) as f64);
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
        let (fx, fy) = (x - x0 as f64, y - y0 as f64);
        let v = |x: usize, y: usize| self.values[y * self.width + x] as f64;
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
    pub fn new(
        cams: &'a [Camera],
        masks: &[GrayImage],
        all_but: usize,
        min_views: usize,
    ) -> ConeDistance<'a> {
        use rayon::prelude::*;
        ConeDistance {
            cams,
            outlines: masks.par_iter().map(OutlineDistance::new).collect(),
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
        let d = OutlineDistance::new(&mask);
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
}
