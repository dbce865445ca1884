//! What every synthetic scene provides, and the camera ring they share.

use super::body::{Body, Pose};
use crate::camera::Camera;
use crate::rng::Rng;
use nalgebra::Vector3;

/// A synthetic scene: a body, its poses over frames, and the cameras filming it.
pub struct Scene {
    /// Sequence name (the folder under data/).
    pub name: String,
    pub body: Body,
    /// One pose per frame; the skeleton's reference frame holds the rest pose.
    pub poses: Vec<Pose>,
    pub cameras: Vec<Camera>,
    /// Pairs of bones whose flesh is meant to touch, per frame: (frame, bone a, bone b).
    pub contacts: Vec<(u32, usize, usize)>,
}

/// Camera ring layout.
pub struct RingSpec {
    /// Number of cameras.
    pub count: usize,
    /// Ring radius around the vertical axis through the origin, metres.
    pub radius: f64,
    /// Camera heights, cycled over the ring, metres.
    pub heights: Vec<f64>,
    /// The point every camera looks at.
    pub target: Vector3<f64>,
    /// Focal length for a 1024-pixel-wide image (scaled with the width), pixels.
    pub focal_1024: f64,
    pub width: u32,
    pub height: u32,
}

/// Cameras evenly spread on a ring (with a small seeded jitter of azimuth, principal point
/// and lens distortion, as real rigs have), named cam00, cam01, ...
pub fn camera_ring(spec: &RingSpec, seed: u64) -> Vec<Camera> {
    let mut rng = Rng::new(seed, 77);
    let scale = spec.width as f64 / 1024.0;
    (0..spec.count)
        .map(|i| {
            let az =
                (i as f64 / spec.count as f64 * 360.0 + 7.0 + rng.range(-2.0, 2.0)).to_radians();
            let centre = Vector3::new(
                spec.radius * az.cos(),
                spec.radius * az.sin(),
                spec.heights[i % spec.heights.len()],
            );
            let mut cam = Camera::look_at(
                &format!("cam{i:02}"),
                spec.width,
                spec.height,
                spec.focal_1024 * scale,
                centre,
                spec.target,
                Vector3::z(),
            );
            cam.fy *= 1.0 + rng.range(-0.002, 0.002);
            cam.cx += rng.range(-3.0, 3.0) * scale;
            cam.cy += rng.range(-3.0, 3.0) * scale;
            cam.dist = [
                -0.04 + rng.range(-0.01, 0.01),
                0.015 + rng.range(-0.005, 0.005),
                rng.range(-2e-4, 2e-4),
                rng.range(-2e-4, 2e-4),
                0.0,
            ];
            cam
        })
        .collect()
}

/// Samples a motion defined on `natural` key frames at `frames` evenly spaced times: the
/// key frames themselves when `frames == natural`.
pub fn sample_times(natural: usize, frames: usize) -> Vec<f64> {
    if frames <= 1 {
        return vec![0.0];
    }
    (0..frames)
        .map(|i| i as f64 * (natural - 1) as f64 / (frames - 1) as f64)
        .collect()
}

/// Piecewise-linear interpolation of `ys` at `xs` (xs ascending), clamped at the ends.
pub fn interp(xs: &[f64], ys: &[f64], x: f64) -> f64 {
    if x <= xs[0] {
        return ys[0];
    }
    for k in 1..xs.len() {
        if x <= xs[k] {
            let t = (x - xs[k - 1]) / (xs[k] - xs[k - 1]);
            return ys[k - 1] + t * (ys[k] - ys[k - 1]);
        }
    }
    *ys.last().unwrap()
}
