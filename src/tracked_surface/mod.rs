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
//!        + ρ Σ_(i,k) rim |Q_ik (x_i − u_ik)|²       the rims
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
//! - u_ik: for a rim vertex of camera k (|n_i·r| ≤ 0.3) that is the nearest, in the
//!   image, to outline pixels of the mask lying farther from it than the tolerance and a
//!   projected edge (pixels no part of the surface explains), the point at its depth on
//!   the ray through their mean, within twice `surface.reach` (Vlasic et al. 2008's rim
//!   constraint: the mask's outline is the surface's). ρ = `surface.rim`.
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
    /// ρ: weight of the rim terms (outline pixels the surface leaves unexplained pull its
    /// nearest outline vertex out to them).
    pub rim: f64,
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
            rim: 1.0,
            rounds: 3,
        }
    }
}

/// Checks the parameters' ranges.
pub fn validate(p: &SurfaceParams) -> std::result::Result<(), Refusal> {
    let checks: [(&str, f64, f64, f64); 7] = [
        ("reach", p.reach, 0.0, 0.5),
        ("shape", p.shape, 0.0, 1e4),
        ("anchor", p.anchor, 1e-6, 1e4),
        ("memory", p.memory, 0.0, 1.0),
        ("silhouette", p.silhouette, 0.0, 1e4),
        ("silhouette_tolerance", p.silhouette_tolerance, 0.0, 1e3),
        ("rim", p.rim, 0.0, 1e4),
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
    /// The worst camera's silhouette IoU of the tracked surface and of the bare posed
    /// model, [0, 1] ([`crate::fit::health::silhouette_iou`], at the health's resolution;
    /// set by the surface stage, 0 when not measured).
    pub iou_worst: f64,
    pub iou_worst_posed: f64,
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
    /// The model's mean edge length, metres.
    edge: f64,
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
            edge: model.mesh.mean_edge_length(),
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
            let mut terms = terms;
            if p.rim > 0.0 {
                let pulls: Vec<Vec<(usize, Vector3<f64>)>> = (evidence.cameras.par_iter())
                    .zip(evidence.silhouettes)
                    .map(|(cam, field)| rim_targets(cam, field, &current, &normals, self.edge, p))
                    .collect();
                for (cam, pulls) in evidence.cameras.iter().zip(pulls) {
                    for (i, q) in pulls {
                        let ray = (current.vertices[i] - cam.centre()).normalize();
                        let m = (Matrix3::identity() - ray * ray.transpose()) * p.rim;
                        terms[i].0 += m;
                        terms[i].1 += m * (q - targets[i]);
                        terms[i].3 += 1;
                    }
                }
            }
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

/// Rim vertices: their normal this close to perpendicular to the viewing ray (|n·r|).
const RIM_COSINE: f64 = 0.3;

/// The rim terms of one camera: every outline pixel of its silhouette is given to the
/// nearest rim vertex in the image (one whose normal is nearly perpendicular to its
/// viewing ray); an outline pixel farther from it than the tolerance and a projected edge
/// is not explained by the surface, and the vertex is pulled to the mean of its
/// unexplained pixels, at its own depth (free along the ray), when that lies within
/// twice `surface.reach`. (vertex, target) pairs.
fn rim_targets(
    cam: &Camera,
    field: &NearestInside,
    mesh: &TriMesh,
    normals: &[Vector3<f64>],
    edge: f64,
    p: &SurfaceParams,
) -> Vec<(usize, Vector3<f64>)> {
    let limit = 2.0 * p.reach;
    let focal = cam.fx.max(cam.fy);
    let rim: Vec<(usize, Vector2<f64>, f64)> = (0..mesh.vertices.len())
        .filter_map(|i| {
            let x = mesh.vertices[i];
            let ray = (x - cam.centre()).normalize();
            if normals[i].dot(&ray).abs() > RIM_COSINE {
                return None;
            }
            let (px, depth) = cam.project_with_depth(&x);
            (depth > 0.0 && cam.in_image(&px)).then_some((i, px, depth))
        })
        .collect();
    if rim.is_empty() {
        return Vec::new();
    }
    let points: Vec<Vector3<f64>> = rim
        .iter()
        .map(|r| Vector3::new(r.1.x, r.1.y, 0.0))
        .collect();
    let tree = NearestTree::new(&points);
    let mut sums: std::collections::BTreeMap<usize, (Vector2<f64>, usize)> = Default::default();
    for &(x, y) in &field.contour {
        let px = Vector2::new(x as f64, y as f64);
        let Some((k, d2)) = tree.nearest(&Vector3::new(px.x, px.y, 0.0)) else {
            continue;
        };
        let (_, _, depth) = rim[k];
        let explained = p.silhouette_tolerance + 0.5 + focal * edge / depth;
        if d2.sqrt() > explained {
            let e = sums.entry(k).or_insert((Vector2::zeros(), 0));
            e.0 += px;
            e.1 += 1;
        }
    }
    sums.into_iter()
        .filter_map(|(k, (sum, count))| {
            let (i, px, depth) = rim[k];
            let to = sum / count as f64;
            ((to - px).norm() * depth / focal <= limit).then(|| (i, cam.backproject(to, depth)))
        })
        .collect()
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A sphere meshed from its distance field (1 cm samples).
    fn sphere(r: f64) -> TriMesh {
        crate::geometry::isosurface::sphere(r, Vector3::zeros(), 0.01)
    }

    /// A 20 cm sphere seen by a camera whose mask is the outline of a 23 cm sphere: the
    /// outline vertices are pulled out to the mask's outline (3 cm farther from the view
    /// axis, at their own depth); with the mask of the sphere itself nothing is pulled.
    #[test]
    fn an_outline_the_surface_leaves_unexplained_pulls_its_rim_out() {
        let cam = Camera::look_at(
            "c",
            320,
            240,
            400.0,
            Vector3::new(0.0, -3.0, 0.0),
            Vector3::zeros(),
            Vector3::z(),
        );
        let mesh = sphere(0.2);
        let normals = mesh.vertex_normals();
        let edge = mesh.mean_edge_length();
        let p = SurfaceParams::default();
        // The disk a sphere of radius r at 3 m covers in the image.
        let mask_of = |r: f64| {
            let centre = cam.project(&Vector3::zeros()).unwrap();
            let radius = 400.0 * r / (9.0 - r * r).sqrt();
            image::GrayImage::from_fn(320, 240, |x, y| {
                let d = (Vector2::new(x as f64, y as f64) - centre).norm();
                image::Luma([if d <= radius { 255 } else { 0 }])
            })
        };
        let larger = NearestInside::new(&mask_of(0.23));
        let pulls = rim_targets(&cam, &larger, &mesh, &normals, edge, &p);
        assert!(pulls.len() > 20, "{} pulls", pulls.len());
        let axis_distance = |v: &Vector3<f64>| v.x.hypot(v.z);
        for (i, q) in &pulls {
            let moved = axis_distance(q) - axis_distance(&mesh.vertices[*i]);
            assert!(
                (0.01..0.05).contains(&moved),
                "vertex {i} moved out {moved} m"
            );
        }
        let own = NearestInside::new(&mask_of(0.2));
        let pulls = rim_targets(&cam, &own, &mesh, &normals, edge, &p);
        assert!(
            pulls.len() <= 2,
            "{} pulls on the surface's own outline",
            pulls.len()
        );
    }
}
