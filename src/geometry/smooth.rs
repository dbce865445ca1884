//! Taubin smoothing (lambda|mu): alternating shrinking and inflating Laplacian steps that
//! remove the voxel staircase without the shrinkage of plain Laplacian smoothing.

use super::mesh::TriMesh;
use nalgebra::Vector3;
use rayon::prelude::*;

/// Smooths `mesh` in place with `iterations` lambda/mu pairs (lambda = 0.5, mu = -0.53,
/// uniform weights over each vertex's edge neighbours).
pub fn taubin(mesh: &mut TriMesh, iterations: usize) {
    if iterations == 0 {
        return;
    }
    let n = mesh.vertices.len();
    let neighbours = mesh.vertex_neighbours();
    let step = |factor: f64, v: &mut Vec<Vector3<f64>>| {
        let moved: Vec<Vector3<f64>> = (0..n)
            .into_par_iter()
            .map(|i| {
                let nb = &neighbours[i];
                if nb.is_empty() {
                    return v[i];
                }
                let mean =
                    nb.iter().map(|&j| v[j as usize]).sum::<Vector3<f64>>() / nb.len() as f64;
                v[i] + factor * (mean - v[i])
            })
            .collect();
        *v = moved;
    };
    for _ in 0..iterations {
        step(0.5, &mut mesh.vertices);
        step(-0.53, &mut mesh.vertices);
    }
}
