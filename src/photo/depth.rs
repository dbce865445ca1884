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

/// Depth maps of a closed mesh through every camera (metres along the optical axis;
/// infinity where the mesh is not seen), by splatting its vertices: each vertex writes its
/// depth over a square about as wide as `spacing` metres (the mesh's vertex spacing) appears
/// at that depth. Cheaper than rasterizing and exact enough for a visibility test with a
/// tolerance of more than a voxel.
pub fn splatted_depth_maps(cams: &[Camera], mesh: &TriMesh, spacing: f64) -> Vec<Vec<f32>> {
    cams.par_iter()
        .map(|cam| {
            let (w, h) = (cam.width as i64, cam.height as i64);
            let mut depth = vec![f32::INFINITY; (w * h) as usize];
            for v in &mesh.vertices {
                let (px, z) = cam.project_with_depth(v);
                if z <= 0.0 {
                    continue;
                }
                let r = (0.75 * cam.fx.max(cam.fy) * spacing / z).ceil() as i64;
                let (cx, cy) = (px.x.round() as i64, px.y.round() as i64);
                for y in (cy - r).max(0)..=(cy + r).min(h - 1) {
                    for x in (cx - r).max(0)..=(cx + r).min(w - 1) {
                        let d = &mut depth[(y * w + x) as usize];
                        *d = d.min(z as f32);
                    }
                }
            }
            depth
        })
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
