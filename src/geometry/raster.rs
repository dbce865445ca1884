//! A z-buffer triangle rasterizer through the full camera model (distortion included).
//!
//! Triangle edges are straight in the camera's normalized (undistorted) image plane, not in
//! the distorted pixel grid. So every pixel centre is first mapped to normalized coordinates
//! (a per-camera table, [`PixelRays`]), and coverage, depth and perspective-correct
//! barycentrics are computed there: exact for any distortion, and identical to casting the
//! pixel's viewing ray at the triangle.

use crate::camera::Camera;
use nalgebra::{Vector2, Vector3};
use rayon::prelude::*;

/// The undistorted normalized coordinates of every pixel centre of one camera.
pub struct PixelRays {
    pub width: u32,
    pub height: u32,
    /// Row-major, `width * height` entries.
    pub normalized: Vec<Vector2<f64>>,
}

impl PixelRays {
    pub fn new(cam: &Camera) -> PixelRays {
        let (w, h) = (cam.width as usize, cam.height as usize);
        let mut normalized = vec![Vector2::zeros(); w * h];
        normalized
            .par_chunks_mut(w)
            .enumerate()
            .for_each(|(y, row)| {
                for (x, n) in row.iter_mut().enumerate() {
                    *n = cam.pixel_to_normalized(Vector2::new(x as f64, y as f64));
                }
            });
        PixelRays {
            width: cam.width,
            height: cam.height,
            normalized,
        }
    }
}

/// What a pixel sees of the mesh: the nearest triangle, its perspective-correct
/// barycentric weights, and the depth along the optical axis (metres).
#[derive(Debug, Clone, Copy)]
pub struct Fragment {
    pub triangle: u32,
    pub bary: [f64; 3],
    pub depth: f64,
}

/// Nearest depth accepted, metres: triangles with a vertex closer than this are skipped.
const NEAR: f64 = 0.05;

/// Rasterizes `triangles` over `vertices` (world metres) into one fragment per pixel
/// (`None` where the mesh is not seen). Back faces are culled, so meshes must be closed and
/// outward oriented.
pub fn rasterize(
    cam: &Camera,
    rays: &PixelRays,
    vertices: &[Vector3<f64>],
    triangles: &[[u32; 3]],
) -> Vec<Option<Fragment>> {
    let (w, h) = (rays.width as usize, rays.height as usize);
    let centre = cam.centre();
    let cam_pts: Vec<Vector3<f64>> = vertices.iter().map(|v| cam.to_camera(v)).collect();
    let mut frags: Vec<Option<Fragment>> = vec![None; w * h];
    for (ti, t) in triangles.iter().enumerate() {
        let c = t.map(|i| cam_pts[i as usize]);
        if c.iter().any(|p| p.z < NEAR) {
            continue;
        }
        let [a, b, d] = t.map(|i| vertices[i as usize]);
        if (b - a).cross(&(d - a)).dot(&(centre - a)) <= 0.0 {
            continue; // back face
        }
        let n = c.map(|p| Vector2::new(p.x / p.z, p.y / p.z));
        let area = (n[1] - n[0]).perp(&(n[2] - n[0]));
        if area.abs() < 1e-18 {
            continue;
        }
        // Pixel bounding box from the distorted projections, widened for edge curvature.
        let px = n.map(|q| cam.normalized_to_pixel(q));
        let lo_x = px.iter().map(|p| p.x).fold(f64::INFINITY, f64::min) - 2.0;
        let hi_x = px.iter().map(|p| p.x).fold(f64::NEG_INFINITY, f64::max) + 2.0;
        let lo_y = px.iter().map(|p| p.y).fold(f64::INFINITY, f64::min) - 2.0;
        let hi_y = px.iter().map(|p| p.y).fold(f64::NEG_INFINITY, f64::max) + 2.0;
        if hi_x < 0.0 || hi_y < 0.0 || lo_x > (w - 1) as f64 || lo_y > (h - 1) as f64 {
            continue;
        }
        let (x0, x1) = (
            lo_x.max(0.0).ceil() as usize,
            hi_x.min((w - 1) as f64).floor() as usize,
        );
        let (y0, y1) = (
            lo_y.max(0.0).ceil() as usize,
            hi_y.min((h - 1) as f64).floor() as usize,
        );
        for y in y0..=y1 {
            for x in x0..=x1 {
                let q = rays.normalized[y * w + x];
                let l0 = (n[1] - q).perp(&(n[2] - q)) / area;
                let l1 = (n[2] - q).perp(&(n[0] - q)) / area;
                let l2 = 1.0 - l0 - l1;
                if l0 < 0.0 || l1 < 0.0 || l2 < 0.0 {
                    continue;
                }
                // Perspective-correct weights: screen weights divided by depth, normalized.
                let inv = [l0 / c[0].z, l1 / c[1].z, l2 / c[2].z];
                let s = inv[0] + inv[1] + inv[2];
                let depth = 1.0 / s;
                let slot = &mut frags[y * w + x];
                if slot.is_none_or(|f| depth < f.depth) {
                    *slot = Some(Fragment {
                        triangle: ti as u32,
                        bary: inv.map(|v| v / s),
                        depth,
                    });
                }
            }
        }
    }
    frags
}

/// The depth map (metres along the optical axis; infinity where nothing is seen) of a
/// triangle mesh through `cam`, for visibility tests: vertices are projected through the
/// full camera model and triangles filled in pixel space with perspective-correct depth.
/// Edges are straight in pixels, which for triangles a few pixels wide differs from
/// [`rasterize`] by far less than a pixel. Triangles facing away from the camera are
/// skipped: the mesh must be closed with its triangles wound counter-clockwise seen from
/// outside (as every mesh of the pipeline is) and the camera outside it, so that the nearest
/// surface along every ray is a front face. No pixel table, so it is cheap enough to run per
/// frame and camera.
pub fn depth_map(cam: &Camera, vertices: &[Vector3<f64>], triangles: &[[u32; 3]]) -> Vec<f32> {
    let (w, h) = (cam.width as usize, cam.height as usize);
    let projected: Vec<(Vector2<f64>, f64)> =
        vertices.iter().map(|v| cam.project_with_depth(v)).collect();
    let mut depth = vec![f32::INFINITY; w * h];
    for t in triangles {
        let [(a, za), (b, zb), (c, zc)] = t.map(|i| projected[i as usize]);
        if za < NEAR || zb < NEAR || zc < NEAR {
            continue;
        }
        // Pixel y runs down and depth forward: a counter-clockwise front face projects
        // with a negative signed area.
        let area = (b - a).perp(&(c - a));
        if area > -1e-12 {
            continue;
        }
        let (hi_x, hi_y) = (a.x.max(b.x).max(c.x), a.y.max(b.y).max(c.y));
        if hi_x < 0.0 || hi_y < 0.0 {
            continue;
        }
        // Truncation is floor here (non-negative values): no call to floor or ceil.
        let lo_x = ceil_of_non_negative(a.x.min(b.x).min(c.x).max(0.0));
        let lo_y = ceil_of_non_negative(a.y.min(b.y).min(c.y).max(0.0));
        let hi_x = hi_x.min((w - 1) as f64) as usize;
        let hi_y = hi_y.min((h - 1) as f64) as usize;
        if lo_x > hi_x || lo_y > hi_y {
            continue;
        }
        let inv = [1.0 / za, 1.0 / zb, 1.0 / zc];
        for y in lo_y..=hi_y {
            for x in lo_x..=hi_x {
                let q = Vector2::new(x as f64, y as f64);
                let l0 = (b - q).perp(&(c - q)) / area;
                let l1 = (c - q).perp(&(a - q)) / area;
                let l2 = 1.0 - l0 - l1;
                if l0 < 0.0 || l1 < 0.0 || l2 < 0.0 {
                    continue;
                }
                let z = (1.0 / (l0 * inv[0] + l1 * inv[1] + l2 * inv[2])) as f32;
                let d = &mut depth[y * w + x];
                *d = d.min(z);
            }
        }
    }
    depth
}

/// The ceiling of a non-negative number, as an index.
fn ceil_of_non_negative(v: f64) -> usize {
    let t = v as usize;
    if (t as f64) < v {
        t + 1
    } else {
        t
    }
}
