//! Stage 4, photo-consistency reliability of every surface vertex (method.md "Stage 4").
//!
//! For a vertex u with unit normal n (area-weighted vertex normal of the refined surface):
//! - **Visibility**: camera c sees u when u faces it within `max_view_angle_deg`
//!   (n . (c - u) / |c - u| > cos max_view_angle; 90 degrees is plain "facing"; the default
//!   60 drops oblique views, which see the patch foreshortened more than twice and too
//!   coarsely to correlate with frontal ones) and c's depth map of the surface
//!   itself (rasterized; the farthest of the 2 x 2 pixels around u's projection) is not
//!   closer than u by more than `depth_tolerance` voxels.
//! - **Patches**: `window` x `window` points spaced `patch_spacing` voxels on u's tangent
//!   plane, projected into each camera that sees u (affinely, from the projections of u and
//!   of two tangent steps) and sampled bilinearly in grey. Sampled on the surface, patches
//!   correspond under wide baselines and have the same metric size at any resolution.
//! - **ZNCC(u)**: the mean zero-mean normalized cross-correlation over all pairs of those
//!   cameras (a flat patch correlates 0), in [-1, 1]; -1 when fewer than two cameras see u.
//! - **rho_p(u)** = 1 / (1 + exp(-alpha_p (ZNCC(u) - tau_p))) (paper eq. 3).
//!
//! Patches are normalized once per camera (zero mean, unit norm), so each pair costs one dot
//! product.

use crate::camera::Camera;
use crate::error::Refusal;
use crate::geometry::TriMesh;
use crate::photo::{depth_maps, mean_pair_zncc, GreyImage, Visibility};
use nalgebra::Vector3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Parameters of the reliability stage (pipeline.yaml key `reliability`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReliabilityParams {
    /// Patch edge, samples (odd). Default 7.
    pub window: usize,
    /// Distance between patch samples on the tangent plane, voxels. Default 0.5.
    pub patch_spacing: f64,
    /// Largest angle between the normal and the direction to a camera that sees the vertex,
    /// degrees. Default 60.
    pub max_view_angle_deg: f64,
    /// How much closer than the vertex a camera's depth map may be before the vertex counts
    /// as hidden, voxels. Default 1.5.
    pub depth_tolerance: f64,
    /// Gaussian smoothing of the grey images before sampling, pixels. Default 0.6: removes
    /// pixel noise and the aliasing of texture near the pixel scale, which otherwise
    /// decorrelate views of the same surface. More smoothing also widens the texture's
    /// correlation length, so patches of phantom surface, which see different true
    /// surface in different views, correlate more: on the tripod's phantom frames 1.0
    /// gives false vertices a mean rho_p of 0.017-0.024 against 0.014-0.020 at 0.6, for
    /// an ROC AUC 0.002-0.003 lower (README "Reliability").
    pub image_sigma: f64,
    /// Largest shift along the normal searched for the best ZNCC, voxels. Default 0.25: a
    /// patch a fraction of a voxel off its true depth is misaligned between views, and the
    /// refined surface lies within about 0.4 voxel of the truth (graph-cut accuracy90 at
    /// the paper setting); the search tests shifts of a quarter voxel up to this and keeps
    /// the best mean. On the tripod, 0.5 and 1.0 separate true from false vertices no
    /// better (ROC AUC over seen vertices within 0.003) at 1.7 and 2.3 times the time
    /// (BENCHMARKS "tried"). 0 scores the vertex exactly where it lies.
    pub normal_search: f64,
    /// Slope alpha_p of rho_p (paper eq. 3). Default 5.0.
    pub alpha_p: f64,
    /// Threshold tau_p of rho_p (paper eq. 3). Default 0.95.
    pub tau_p: f64,
}

impl Default for ReliabilityParams {
    fn default() -> Self {
        ReliabilityParams {
            window: 7,
            patch_spacing: 0.5,
            max_view_angle_deg: 60.0,
            depth_tolerance: 1.5,
            image_sigma: 0.6,
            normal_search: 0.25,
            alpha_p: 5.0,
            tau_p: 0.95,
        }
    }
}

/// Checks parameters that do not depend on the data.
pub fn validate(p: &ReliabilityParams) -> std::result::Result<(), Refusal> {
    if p.window < 3 || p.window.is_multiple_of(2) || p.window > 31 {
        return Err(format!(
            "reliability.window must be an odd number of samples from 3 to 31, got {}",
            p.window
        )
        .into());
    }
    let positive = |v: f64| v > 0.0 && v.is_finite();
    if !positive(p.patch_spacing) || !positive(p.depth_tolerance) || !positive(p.alpha_p) {
        return Err(
            "reliability: patch_spacing, depth_tolerance and alpha_p must be positive numbers"
                .into(),
        );
    }
    if !(p.max_view_angle_deg > 0.0 && p.max_view_angle_deg <= 90.0) {
        return Err(format!(
            "reliability.max_view_angle_deg must lie in (0, 90], got {}",
            p.max_view_angle_deg
        )
        .into());
    }
    let in_range = |v: f64| (0.0..=10.0).contains(&v);
    if !in_range(p.image_sigma) || !in_range(p.normal_search) {
        return Err(
            "reliability: image_sigma (pixels) and normal_search (voxels) must lie in [0, 10]"
                .into(),
        );
    }
    if !p.tau_p.is_finite() {
        return Err("reliability.tau_p must be a finite number".into());
    }
    Ok(())
}

/// rho_p of a ZNCC value (paper eq. 3).
pub fn rho_p(zncc: f64, p: &ReliabilityParams) -> f64 {
    1.0 / (1.0 + (-p.alpha_p * (zncc - p.tau_p)).exp())
}

/// The observed surface of one frame with its reliability: what the fit reads.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Observed {
    /// Vertices, world metres.
    pub vertices: Vec<Vector3<f32>>,
    /// Unit outward normals.
    pub normals: Vec<Vector3<f32>>,
    /// ZNCC per vertex, [-1, 1]; -1 when fewer than two cameras see it.
    pub zncc: Vec<f32>,
    /// rho_p per vertex, (0, 1).
    pub rho_p: Vec<f32>,
    /// Number of cameras that see each vertex.
    pub cameras: Vec<u8>,
}

impl Observed {
    /// `mesh` as an observed surface without photo-consistency (a masks-only capture):
    /// rho_p 1 on every vertex, ZNCC 0 and no camera counted.
    pub fn unweighted(mesh: &TriMesh) -> Observed {
        let n = mesh.vertices.len();
        Observed {
            vertices: mesh.vertices.iter().map(|v| v.cast()).collect(),
            normals: mesh.vertex_normals().iter().map(|v| v.cast()).collect(),
            zncc: vec![0.0; n],
            rho_p: vec![1.0; n],
            cameras: vec![0; n],
        }
    }

    /// The colour of every vertex as in the paper's figure: blue where consistent, red where
    /// not (by rho_p relative to its value at ZNCC = 1), grey where fewer than two cameras
    /// see it.
    pub fn colours(&self, p: &ReliabilityParams) -> Vec<[u8; 3]> {
        let top = rho_p(1.0, p) as f32;
        (0..self.vertices.len())
            .map(|i| {
                if self.cameras[i] < 2 {
                    return [150, 150, 150];
                }
                let t = (self.rho_p[i] / top).clamp(0.0, 1.0);
                [(230.0 * (1.0 - t)) as u8 + 20, 30, (230.0 * t) as u8 + 20]
            })
            .collect()
    }
}

/// ZNCC and the number of cameras that see it, for every vertex of `mesh` (normals
/// `normals`), voxel size `h` metres, cameras' depth maps `depth` of the mesh itself.
pub fn vertex_zncc(
    cams: &[Camera],
    images: &[GreyImage],
    depth: &[Vec<f32>],
    mesh: &TriMesh,
    normals: &[Vector3<f64>],
    h: f64,
    p: &ReliabilityParams,
) -> (Vec<f32>, Vec<u8>) {
    let visibility = Visibility::new(cams, depth, p.max_view_angle_deg, p.depth_tolerance * h);
    let steps = (p.normal_search / 0.25).floor() as i64;
    mesh.vertices
        .par_iter()
        .zip(normals.par_iter())
        .map_init(
            || (Vec::new(), Vec::<f32>::new()),
            |(seen, patches): &mut (Vec<usize>, Vec<f32>), (v, n)| {
                visibility.seeing(v, n, seen);
                let k = seen.len();
                if k < 2 {
                    return (-1.0, k as u8);
                }
                // Mean pair correlation with the patch shifted by `s` quarter voxels along
                // the normal.
                let mut score = |s: i64| {
                    let x = v + n * (s as f64 * 0.25 * h);
                    mean_pair_zncc(
                        cams,
                        images,
                        seen,
                        &x,
                        n,
                        p.window,
                        p.patch_spacing * h,
                        patches,
                    )
                };
                // Coarse to fine: half-voxel steps, then the quarter steps around the best.
                let (mut best, mut at) = (f32::NEG_INFINITY, 0);
                for s in (-steps..=steps).filter(|s| s % 2 == 0) {
                    let z = score(s);
                    if z > best {
                        (best, at) = (z, s);
                    }
                }
                for s in [at - 1, at + 1] {
                    if s.abs() <= steps {
                        best = best.max(score(s));
                    }
                }
                (best.clamp(-1.0, 1.0), k as u8)
            },
        )
        .unzip()
}

/// The reliability of every vertex of a frame's refined surface.
pub fn observe(
    cams: &[Camera],
    images: &[GreyImage],
    mesh: &TriMesh,
    h: f64,
    p: &ReliabilityParams,
) -> Observed {
    let normals = mesh.vertex_normals();
    let depth = depth_maps(cams, mesh);
    let images: Vec<GreyImage> = images
        .par_iter()
        .map(|g| g.blurred(p.image_sigma))
        .collect();
    let images = &images;
    let (zncc, cameras) = vertex_zncc(cams, images, &depth, mesh, &normals, h, p);
    Observed {
        vertices: mesh.vertices.iter().map(|v| v.cast()).collect(),
        normals: normals.iter().map(|v| v.cast()).collect(),
        rho_p: zncc.iter().map(|&z| rho_p(z as f64, p) as f32).collect(),
        zncc,
        cameras,
    }
}
