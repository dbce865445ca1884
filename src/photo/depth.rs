//! Depth maps of a closed mesh through every camera, for visibility tests.

use crate::camera::Camera;
use crate::geometry::TriMesh;
use rayon::prelude::*;

/// Depth maps of a closed mesh through every camera (metres along the optical axis;
/// infinity where the mesh is not seen), by z-buffer rasterization of its triangles.
pub fn depth_maps(cams: &[Camera], mesh: &TriMesh) -> Vec<Vec<f32>> {
    cams.par_iter()
        .map(|cam| crate::geometry::raster::depth_map(cam, &mesh.vertices, &mesh.triangles))
        .collect()
}

/// The farthest depth of the 2 x 2 pixels around the projection `(x, y)`: a vertex is
/// hidden only if every pixel around it sees something closer.
pub fn farthest_around(depth: &[f32], width: usize, height: usize, x: f64, y: f64) -> f32 {
    let (x0, y0) = (x.floor().max(0.0) as usize, y.floor().max(0.0) as usize);
    let (x1, y1) = ((x0 + 1).min(width - 1), (y0 + 1).min(height - 1));
    depth[y0 * width + x0]
        .max(depth[y0 * width + x1])
        .max(depth[y1 * width + x0])
        .max(depth[y1 * width + x1])
}

/// Which cameras see a surface point: the rule of the reliability stage and of the
/// photo-consistency refinement.
pub struct Visibility<'a> {
    cams: &'a [Camera],
    centres: Vec<nalgebra::Vector3<f64>>,
    /// The cameras' depth maps of the surface itself ([`depth_maps`]).
    depth: &'a [Vec<f32>],
    /// Cosine of the largest angle between the normal and the direction to a camera.
    cos_max: f64,
    /// How much closer than the point a depth map may be before it counts as hidden,
    /// metres.
    tolerance: f64,
}

impl<'a> Visibility<'a> {
    pub fn new(
        cams: &'a [Camera],
        depth: &'a [Vec<f32>],
        max_view_angle_deg: f64,
        tolerance: f64,
    ) -> Visibility<'a> {
        Visibility {
            cams,
            centres: cams.iter().map(Camera::centre).collect(),
            depth,
            cos_max: max_view_angle_deg.to_radians().cos(),
            tolerance,
        }
    }

    /// The cameras that see `v` (unit normal `n`) into `seen`: v faces the camera within
    /// the angle, projects into its image, and the depth map (the farthest of the 2 x 2
    /// pixels around v's projection) is not closer than v by more than the tolerance.
    pub fn seeing(
        &self,
        v: &nalgebra::Vector3<f64>,
        n: &nalgebra::Vector3<f64>,
        seen: &mut Vec<usize>,
    ) {
        seen.clear();
        for (c, cam) in self.cams.iter().enumerate() {
            let to_cam = self.centres[c] - v;
            if n.dot(&to_cam) <= self.cos_max * to_cam.norm() {
                continue;
            }
            let (px, z) = cam.project_with_depth(v);
            if z <= 0.0 || !cam.in_image(&px) {
                continue;
            }
            let (w, h) = (cam.width as usize, cam.height as usize);
            let hidden_behind =
                farthest_around(&self.depth[c], w, h, px.x, px.y) + self.tolerance as f32;
            if (z as f32) <= hidden_behind {
                seen.push(c);
            }
        }
    }
}
