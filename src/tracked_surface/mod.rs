//! The tracked surface: each frame, the posed body model's mesh (the reference frame's
//! topology: the same vertices and triangles in every frame) deformed to the frame's
//! evidence, so that a dress, a sleeve or hair the rigid skin cannot carry is followed.
//!
//! Each vertex i gets a target t_i: the posed model p_i (linear blend skinning of the
//! fitted pose), plus the previous tracked frame's offset carried by the skinning,
//! t_i = p_i + β A_i r_i (A_i the rotation nearest the skinning weights' blend of the
//! bones' rotations, r_i the
//! previous frame's offset brought back to the reference pose, β = `surface.memory`: the
//! temporal smoothness, and the guard against drift, since without evidence an offset
//! fades by β a frame). The unknown offsets δ_i = x_i − t_i minimise ([`solve`])
//!
//!   E(δ) = Σ_i w_i |N_i (x_i − c_i)|²            the observed surface
//!        + s Σ_i Σ_k |Q_ik (x_i − q_ik)|²         the silhouettes
//!        + λ_e Σ_(i,j) edge |δ_i − δ_j|²            the target's shape (`surface.shape`)
//!        + λ_a Σ_i |δ_i|²                            the target where nothing is seen
//!
//! - c_i: the observed vertex nearest x_i within `surface.reach` whose normal agrees with
//!   x_i's (n_i·n_c ≥ 0.5, so the far side of a thin limb is not taken);
//!   N_i = n_c n_cᵀ + 0.1 I (point to plane, so the surface may slide along itself);
//!   w_i = rho_p(c_i) · rho_c(i) · n_i·n_c: the paper's weights decide where the surface
//!   may follow the reconstruction (rho_p: photo-consistent, not a phantom; rho_c: the
//!   posed model's vertex is not in contact with another part, where the reconstruction
//!   merges the two).
//! - q_ik: for a vertex that projects outside camera k's silhouette by more than
//!   `surface.silhouette_tolerance` pixels, the point at its depth on the ray through the
//!   nearest silhouette pixel; Q_ik = I − r rᵀ (r the viewing ray) leaves the depth free.
//!   So a phantom or a contact gap the masks do not confirm is not copied, and no part of
//!   the surface leaves a mask. s = `surface.silhouette`.
//!
//! The correspondences are found again `surface.rounds` times, each round solving the
//! quadratic energy from the last one's offsets.

pub mod silhouette_field;
pub mod solve;

use crate::camera::Camera;
use crate::error::Refusal;
use crate::fit::contact::{ContactParams, ContactSearch};
use crate::fit::Observation;
use crate::geometry::nearest::NearestTree;
use crate::geometry::TriMesh;
use crate::skeleton::model::BodyModel;
use crate::skeleton::pose::PosedBones;
use crate::skeleton::skinning;
use crate::skeleton::Pose;
use nalgebra::{Matrix3, Vector2, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use silhouette_field::NearestInside;

/// The tracked surface's parameters (pipeline.yaml section `surface`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SurfaceParams {
    /// How far from the posed model an observed vertex may be followed, metres.
    pub reach: f64,
    /// λ_e: weight of the edges' offset differences (larger: a stiffer surface).
    pub shape: f64,
    /// λ_a: weight of the offsets themselves (holds the target where nothing is seen).
    pub anchor: f64,
    /// β: share of the previous frame's offset carried into the next frame's target, in
    /// [0, 1] (0: every frame starts from the bare posed model).
    pub memory: f64,
    /// s: weight of the silhouette terms against an observed surface term of weight 1.
    pub silhouette: f64,
    /// How far outside a silhouette a vertex may project before it is pulled back, pixels.
    pub silhouette_tolerance: f64,
    /// How often the correspondences are found again.
    pub rounds: usize,
}

impl Default for SurfaceParams {
    fn default() -> Self {
        SurfaceParams {
            reach: 0.05,
            shape: 1.0,
            anchor: 0.01,
            memory: 0.8,
            silhouette: 1.0,
            silhouette_tolerance: 1.0,
            rounds: 3,
        }
    }
}

/// Checks the parameters' ranges.
pub fn validate(p: &SurfaceParams) -> std::result::Result<(), Refusal> {
    let checks: [(&str, f64, f64, f64); 6] = [
        ("reach", p.reach, 0.0, 0.5),
        ("shape", p.shape, 0.0, 1e4),
        ("anchor", p.anchor, 1e-6, 1e4),
        ("memory", p.memory, 0.0, 1.0),
        ("silhouette", p.silhouette, 0.0, 1e4),
        ("silhouette_tolerance", p.silhouette_tolerance, 0.0, 1e3),
    ];
    for (key, value, lo, hi) in checks {
        if !(value.is_finite() && (lo..=hi).contains(&value)) {
            return Err(
                format!("key 'surface.{key}': {value} is not between {lo} and {hi}").into(),
            );
        }
    }
    if !(1..=50).contains(&p.rounds) {
        return Err(format!("key 'surface.rounds': {} is not between 1 and 50", p.rounds).into());
    }
    Ok(())
}

/// A frame's evidence: its observed surface and its silhouettes.
pub struct Evidence<'a> {
    pub observed: &'a Observation,
    pub cameras: &'a [Camera],
    /// One per camera, in the cameras' order.
    pub silhouettes: &'a [NearestInside],
}

/// The previous tracked frame: its pose and its tracked vertices (world metres).
pub struct Previous<'a> {
    pub pose: &'a Pose,
    pub vertices: &'a [Vector3<f64>],
}

/// What tracking one frame did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TrackStats {
    /// Share of the vertices that followed an observed vertex in the last round.
    pub followed_share: f64,
    /// Vertices pulled back into a silhouette in the last round.
    pub silhouette_pulls: usize,
    /// Median and largest distance of the tracked vertices from the bare posed model,
    /// metres.
    pub median_offset: f64,
    pub max_offset: f64,
    /// Conjugate-gradient iterations over all rounds.
    pub iterations: usize,
}

/// Tracks a sequence's frames for one body model.
pub struct Tracker<'a> {
    model: &'a BodyModel,
    params: SurfaceParams,
    neighbours: Vec<Vec<(u32, f64)>>,
    /// 1 per vertex.
    mass: Vec<f64>,
    coarse: solve::Coarse,
    contact: ContactSearch,
}

/// Normals that disagree more than this with the observed vertex's are not followed.
const MIN_AGREEMENT: f64 = 0.5;
/// Point-to-point share of the observed surface term (beside point to plane).
const POINT_SHARE: f64 = 0.1;
/// Conjugate gradients' relative residual and iteration cap per round.
const CG_TOLERANCE: f64 = 1e-3;
const CG_ITERATIONS: usize = 10;
/// Cell of the patches the smooth part of the offsets is solved on first, metres.
const PATCH_CELL: f64 = 0.03;

/// Each vertex's rotation A_i of the module's notes: the rotation nearest to the skinning
/// weights' blend of its bones' rotations (the blend itself nears a singular matrix where
/// two bones turn apart, and its inverse would throw an offset far away).
fn blended_rotations(bones: &PosedBones, model: &BodyModel) -> Vec<Matrix3<f64>> {
    model
        .weights
        .par_iter()
        .map(|w| {
            let blend: Matrix3<f64> = w
                .iter()
                .map(|&(b, wb)| bones.rotations[b].matrix() * wb)
                .sum();
            crate::camera::nearest_rotation(&blend)
        })
        .collect()
}

impl<'a> Tracker<'a> {
    pub fn new(model: &'a BodyModel, params: SurfaceParams, contact: ContactParams) -> Tracker<'a> {
        let neighbours = solve::unit_neighbours(&model.mesh.vertex_neighbours());
        Tracker {
            model,
            params,
            mass: vec![1.0; neighbours.len()],
            coarse: solve::Coarse::new(&model.mesh.vertices, &neighbours, PATCH_CELL),
            neighbours,
            contact: ContactSearch::new(model, contact),
        }
    }

    /// The targets t_i of `pose` given the previous tracked frame, and the bare posed
    /// model p_i.
    fn targets(
        &self,
        pose: &Pose,
        previous: Option<&Previous>,
    ) -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>) {
        let bones = PosedBones::new(&self.model.skeleton, pose);
        let posed = skinning::pose_vertices(&bones, &self.model.mesh.vertices, &self.model.weights);
        let Some(prev) = previous.filter(|p| p.vertices.len() == posed.len()) else {
            return (posed.clone(), posed);
        };
        let prev_bones = PosedBones::new(&self.model.skeleton, prev.pose);
        let prev_posed =
            skinning::pose_vertices(&prev_bones, &self.model.mesh.vertices, &self.model.weights);
        let (now, then) = (
            blended_rotations(&bones, self.model),
            blended_rotations(&prev_bones, self.model),
        );
        let beta = self.params.memory;
        let targets = (0..posed.len())
            .into_par_iter()
            .map(|i| {
                // No carried offset goes farther than the surface may follow.
                let offset =
                    (prev.vertices[i] - prev_posed[i]).cap_magnitude(2.0 * self.params.reach);
                posed[i] + beta * (now[i] * (then[i].transpose() * offset))
            })
            .collect();
        (targets, posed)
    }

    /// Tracks one frame: the posed model of `pose`, deformed to `evidence`. Returns the
    /// tracked mesh, the bare posed model's vertices and what tracking did.
    pub fn frame(
        &self,
        pose: &Pose,
        previous: Option<&Previous>,
        evidence: &Evidence,
    ) -> (TriMesh, Vec<Vector3<f64>>, TrackStats) {
        let p = &self.params;
        let (targets, posed) = self.targets(pose, previous);
        let triangles = &self.model.mesh.triangles;
        let posed_mesh = TriMesh {
            vertices: posed.clone(),
            triangles: triangles.clone(),
        };
        let (rho_c, _) = self.contact.weights(&posed, &posed_mesh.vertex_normals());
        let obs = evidence.observed;
        let tree = NearestTree::new(&obs.vertices);
        let n = targets.len();
        let mut offsets = vec![Vector3::zeros(); n];
        let mut stats = TrackStats::default();
        for _ in 0..p.rounds {
            let current = TriMesh {
                vertices: (targets.iter().zip(&offsets)).map(|(t, d)| t + d).collect(),
                triangles: triangles.clone(),
            };
            let normals = current.vertex_normals();
            let terms: Vec<(Matrix3<f64>, Vector3<f64>, bool, usize)> = (0..n)
                .into_par_iter()
                .map(|i| {
                    let x = current.vertices[i];
                    let mut block = Matrix3::zeros();
                    let mut pull = Vector3::zeros();
                    let mut followed = false;
                    if p.reach > 0.0 && rho_c[i] > 0.0 {
                        if let Some((j, d2)) = tree.nearest(&x) {
                            let agree = normals[i].dot(&obs.normals[j]);
                            if d2 <= p.reach * p.reach && agree >= MIN_AGREEMENT {
                                let w = obs.rho_p[j] * rho_c[i] * agree;
                                let nc = obs.normals[j];
                                let m =
                                    (nc * nc.transpose() + Matrix3::identity() * POINT_SHARE) * w;
                                block += m;
                                pull += m * (obs.vertices[j] - targets[i]);
                                followed = w > 0.1;
                            }
                        }
                    }
                    let mut pulls = 0;
                    if p.silhouette > 0.0 {
                        for (cam, field) in evidence.cameras.iter().zip(evidence.silhouettes) {
                            let Some(q) = silhouette_target(cam, field, &x, p.silhouette_tolerance)
                            else {
                                continue;
                            };
                            let ray = (x - cam.centre()).normalize();
                            let m = (Matrix3::identity() - ray * ray.transpose()) * p.silhouette;
                            block += m;
                            pull += m * (q - targets[i]);
                            pulls += 1;
                        }
                    }
                    (block, pull, followed, pulls)
                })
                .collect();
            stats.followed_share = terms.iter().filter(|t| t.2).count() as f64 / n.max(1) as f64;
            stats.silhouette_pulls = terms.iter().filter(|t| t.3 > 0).count();
            let system = solve::System {
                neighbours: &self.neighbours,
                mass: &self.mass,
                blocks: terms.iter().map(|t| t.0).collect(),
                rhs: terms.iter().map(|t| t.1).collect(),
                shape: p.shape,
                anchor: p.anchor,
            };
            stats.iterations += system
                .solve_two_level(&self.coarse, &mut offsets, CG_TOLERANCE, CG_ITERATIONS)
                .iterations;
        }
        let vertices: Vec<Vector3<f64>> =
            (targets.iter().zip(&offsets)).map(|(t, d)| t + d).collect();
        let mut moved: Vec<f64> = (vertices.iter().zip(&posed))
            .map(|(x, p)| (x - p).norm())
            .collect();
        moved.sort_by(f64::total_cmp);
        stats.median_offset = moved.get(moved.len() / 2).copied().unwrap_or(0.0);
        stats.max_offset = moved.last().copied().unwrap_or(0.0);
        (
            TriMesh {
                vertices,
                triangles: triangles.clone(),
            },
            posed,
            stats,
        )
    }
}

/// Where a vertex at `x` projecting outside `cam`'s silhouette by more than `tolerance`
/// pixels is pulled: the point at its depth on the ray through the nearest silhouette
/// pixel. `None` when it projects inside (or within the tolerance), outside the image, or
/// behind the camera.
fn silhouette_target(
    cam: &Camera,
    field: &NearestInside,
    x: &Vector3<f64>,
    tolerance: f64,
) -> Option<Vector3<f64>> {
    let (px, depth) = cam.project_with_depth(x);
    if depth <= 0.0 || !cam.in_image(&px) {
        return None;
    }
    let (sx, sy) = field.nearest(px.x.round() as i64, px.y.round() as i64)?;
    let to = Vector2::new(sx as f64, sy as f64);
    ((to - px).norm() > tolerance + 0.5).then(|| cam.backproject(to, depth))
}
