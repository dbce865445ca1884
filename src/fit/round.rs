//! One round's step (a) (method.md "Stage 6"): pose the model, find rho_c and the pairs
//! both ways, weigh each pair by its method, and hold what they ask of the model as
//! [`Targets`] for the solver.
//!
//! Paper eq. 4, with each pair weighted by its own two ends (model vertex v, observed u):
//! `E(p) = sum_pairs rho_c(v)/R_c * rho_p(u)/R_p * |v - u|^2`.

use super::pairs::{find_pairs, normals_agree, search_cell, Partner, Prepared};
use super::probe::{Probe, RHO_C_REBUILDING, RHO_C_SCANNING, RHO_C_STALENESS};
use super::solve::{Plane, Targets};
use super::{Fitter, Method, Observation, Unexplained};
use crate::skeleton::skinning::pose_vertices;
use crate::skeleton::{Pose, PosedBones};
use nalgebra::Vector3;
use rayon::prelude::*;

/// A model vertex's pair takes its observed partner's tangent plane when their normals'
/// dot product is above this (45 degrees), its own otherwise (BENCHMARKS.md).
const PLANE_AGREEMENT: f64 = 0.7;

/// `proposed` gives a pair no weight when its two normals' dot product is below this (more
/// than 120 degrees apart): on the humanoid such pairs fold a hand into the chest it
/// crosses (worst frame 1.9 cm with them, 1.1 cm without; from 0 to -0.7 the same within 1
/// mm, -0.85 gives 2.2 cm; BENCHMARKS.md).
const OPPOSED_NORMALS: f64 = -0.5;

/// Everything one round's pairs give: the held targets and the energy's bookkeeping.
pub(super) struct Round {
    pub targets: Targets,
    /// Sum of w |v - u|^2 over pairs (m^2) and of w.
    pub weighted_sq: f64,
    pub weight_sum: f64,
    pub pairs: usize,
    pub downweighted: usize,
    /// R_c R_p.
    pub normalizer: f64,
    pub contact_share: f64,
    /// `weighted_sq` and `normalizer` with rho_c taken as 1 (see [`Round::score`]).
    pub scored_sq: f64,
    pub score_normalizer: f64,
    /// Reliable observed vertices (rho_p at least 0.5) farther than [`UNEXPLAINED_DISTANCE`]
    /// from the posed model ([`Unexplained`]).
    pub unexplained: Unexplained,
}

/// An observed vertex is unexplained when the posed model is farther than this from it,
/// metres: a part the fit lost leaves the surface it should cover without a model partner.
/// Fits from the true pose leave almost none at 3 cm on the humanoid's dance (BENCHMARKS.md).
pub const UNEXPLAINED_DISTANCE: f64 = 0.03;

impl Round {
    /// Paper eq. 4 with these pairs and weights.
    pub fn energy(&self) -> f64 {
        self.weighted_sq / self.normalizer
    }

    /// The round's score, comparable between starts and frames, m^2: the method's own
    /// energy with these pairs but without rho_c. The observed surface's weights do not
    /// depend on the pose, so a fit cannot lower the score by pressing parts together, as it
    /// can lower eq. 4 through rho_c (on the humanoid, choosing starts by eq. 4 picked a
    /// pose 5 cm off at t23). A baseline is scored with its own weights only, never with
    /// rho_p it does not use. (The `proposed` and `rho_p` methods pair alike, so this is
    /// the `rho_p` method's energy at the same pose.)
    pub fn score(&self) -> f64 {
        self.scored_sq / self.score_normalizer
    }
}

/// A pair's weight in eq. 4 and its weight without rho_c ([`Round::score`]).
type Weights = (f64, f64);

/// The pairs of a round with their weights: model->observed (indexed by model vertex),
/// then observed->model (indexed by observed vertex).
struct Weighed {
    forward: Vec<Partner>,
    forward_weights: Vec<Weights>,
    backward: Vec<Partner>,
    backward_weights: Vec<Weights>,
}

/// Whether a pair pulls its model vertex (a pair without a partner weighs 0).
fn pulls_on(w: f64) -> bool {
    w > 0.0
}

impl Fitter<'_> {
    /// Step (a): pose the model, its normals and rho_c, pairs both ways and their weights.
    pub(super) fn round(&self, prepared: &Prepared, pose: &Pose, probe: &Probe) -> Round {
        let p = &self.params;
        let method = p.method;
        let obs = &prepared.obs;
        let (posed, normals) = probe.time("pose, normals", || self.posed_sample(pose));
        let find_rho_c = || {
            if method.uses_rho_c() {
                let (weights, parts) =
                    probe.time("rho_c", || self.contact.weights(&posed, &normals));
                probe.add_time(RHO_C_STALENESS, parts.staleness);
                probe.add_time(RHO_C_REBUILDING, parts.rebuilding);
                probe.add_time(RHO_C_SCANNING, parts.scanning);
                probe.add_contact_lists(weights.len() - parts.rebuilt, weights.len());
                weights
            } else {
                vec![1.0; posed.len()]
            }
        };
        let cos_limit = p.normal_angle_deg.to_radians().cos();
        let agree = |v: usize, u: usize| normals_agree(&normals[v], &obs.normals[u], cos_limit);
        let compatible = (method == Method::Normals).then_some((&normals[..], cos_limit));
        let find = || {
            find_pairs(
                prepared,
                &posed,
                compatible,
                search_cell(p.model_spacing),
                probe,
            )
        };
        // rho_c and the pairs depend only on the posed model: found side by side, so that
        // one's sequential parts (tree builds) overlap the other's parallel searches.
        let (rho_c, (forward, backward)) = rayon::join(find_rho_c, find);
        probe.time("pairs, weights", || {
            let weigh = |v: usize, u: usize, d2: f64| -> Weights {
                if !d2.is_finite() {
                    return (0.0, 0.0);
                }
                let w = match method {
                    Method::Icp => 1.0,
                    Method::Normals => f64::from(u8::from(agree(v, u))),
                    Method::RhoC => rho_c[v],
                    Method::RhoP => obs.rho_p[u],
                    // A pair whose normals face apart joins two sides that cannot touch
                    // (a hand's back and the chest it crosses): it weighs 0.
                    Method::Proposed if normals[v].dot(&obs.normals[u]) < OPPOSED_NORMALS => 0.0,
                    Method::Proposed => rho_c[v] * obs.rho_p[u],
                };
                let without_rho_c = match method {
                    Method::RhoC => 1.0,
                    Method::Proposed => obs.rho_p[u],
                    Method::Icp | Method::Normals | Method::RhoP => w,
                };
                (w, without_rho_c)
            };
            let forward_weights = forward
                .par_iter()
                .enumerate()
                .map(|(v, &(u, d2))| weigh(v, u, d2))
                .collect();
            let backward_weights = backward
                .par_iter()
                .enumerate()
                .map(|(u, &(v, d2))| weigh(v, u, d2))
                .collect();
            let pairs = Weighed {
                forward,
                forward_weights,
                backward,
                backward_weights,
            };
            let planes = if method == Method::Proposed {
                planes(&pairs, &normals, obs)
            } else {
                Vec::new()
            };
            let targets = Targets {
                pulls: pulls(&pairs, posed.len(), obs, prepared.prior.as_ref()),
                planes,
            };
            self.bookkeeping(&pairs, targets, &rho_c, obs)
        })
    }

    /// The thinned model posed at `pose`, and its normals (each turned with its vertex's
    /// dominant bone).
    pub(super) fn posed_sample(&self, pose: &Pose) -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>) {
        let m = &self.sample;
        let bones = PosedBones::new(&m.skeleton, pose);
        let posed = pose_vertices(&bones, &m.mesh.vertices, &m.weights);
        let normals = self
            .sample_normals
            .iter()
            .zip(&m.labels)
            .map(|(n, &l)| bones.rotations[l] * n)
            .collect();
        (posed, normals)
    }

    /// The round with its targets: eq. 4's sums and normalizer, and the shares the
    /// diagnostics report.
    fn bookkeeping(
        &self,
        w: &Weighed,
        targets: Targets,
        rho_c: &[f64],
        obs: &Observation,
    ) -> Round {
        let method = self.params.method;
        // The sums over all pairs, serially in the pairs' order (forward, then backward):
        // the same bits on every run.
        let (mut weighted_sq, mut weight_sum, mut downweighted) = (0.0, 0.0, 0usize);
        let mut scored_sq = 0.0;
        let pairs = w
            .forward
            .iter()
            .zip(&w.forward_weights)
            .chain(w.backward.iter().zip(&w.backward_weights));
        for (&(_, d2), &(w, ws)) in pairs {
            if w < 0.5 {
                downweighted += 1;
            }
            if pulls_on(w) {
                weighted_sq += w * d2;
                weight_sum += w;
            }
            if ws > 0.0 {
                scored_sq += ws * d2;
            }
        }
        let n = w.forward.len();
        let unexplained = self.unexplained(w, obs);
        let r_c: f64 = rho_c.iter().sum();
        let r_p: f64 = if method.uses_rho_p() {
            obs.rho_p.iter().sum()
        } else {
            obs.vertices.len() as f64
        };
        let score_normalizer = n as f64
            * match method {
                Method::Proposed | Method::RhoP => obs.rho_p.iter().sum(),
                _ => obs.vertices.len() as f64,
            };
        Round {
            targets,
            weighted_sq,
            weight_sum,
            pairs: w.forward.len() + w.backward.len(),
            downweighted,
            normalizer: (r_c * r_p).max(1e-300),
            contact_share: rho_c.iter().filter(|&&r| r < 0.5).count() as f64 / n.max(1) as f64,
            scored_sq,
            score_normalizer: score_normalizer.max(1e-300),
            unexplained,
        }
    }

    /// The reliable observed vertices whose nearest model vertex is farther than
    /// [`UNEXPLAINED_DISTANCE`], and the bone most of their model partners move with.
    fn unexplained(&self, w: &Weighed, obs: &Observation) -> Unexplained {
        let mut per_bone = vec![0usize; self.sample.skeleton.bones.len()];
        let far = UNEXPLAINED_DISTANCE * UNEXPLAINED_DISTANCE;
        for (u, &(v, d2)) in w.backward.iter().enumerate() {
            if d2.is_finite() && d2 > far && obs.rho_p[u] >= 0.5 {
                per_bone[self.sample.labels[v]] += 1;
            }
        }
        let vertices = per_bone.iter().sum();
        let bone = (vertices > 0)
            .then(|| (0..per_bone.len()).max_by_key(|&b| (per_bone[b], std::cmp::Reverse(b))))
            .flatten();
        Unexplained { vertices, bone }
    }
}

/// Each of the `n` model vertices' pulls: its own pair, then the observed vertices whose
/// nearest it is, in their order (a counting sort), summed vertex by vertex in parallel;
/// each vertex's sum runs in the same order as one pass over the pairs. With the motion
/// prior (each vertex's predicted position and the prior's weight), every vertex is also
/// pulled towards its prediction.
fn pulls(
    w: &Weighed,
    n: usize,
    obs: &Observation,
    prior: Option<&(Vec<Vector3<f64>>, f64)>,
) -> Vec<(u32, f64, Vector3<f64>)> {
    let mut starts = vec![0u32; n + 1];
    for (&(v, _), &(wt, _)) in w.backward.iter().zip(&w.backward_weights) {
        if pulls_on(wt) {
            starts[v + 1] += 1;
        }
    }
    for v in 0..n {
        starts[v + 1] += starts[v];
    }
    let mut next = starts.clone();
    let mut pullers = vec![0u32; starts[n] as usize];
    for (u, (&(v, _), &(wt, _))) in w.backward.iter().zip(&w.backward_weights).enumerate() {
        if pulls_on(wt) {
            pullers[next[v] as usize] = u as u32;
            next[v] += 1;
        }
    }
    let (w_sum, target): (Vec<f64>, Vec<Vector3<f64>>) = (0..n)
        .into_par_iter()
        .map(|v| {
            let (mut total, mut sum) = (0.0, Vector3::zeros());
            let (u, _) = w.forward[v];
            let (wt, _) = w.forward_weights[v];
            if pulls_on(wt) {
                total += wt;
                sum += wt * obs.vertices[u];
            }
            for &u in &pullers[starts[v] as usize..starts[v + 1] as usize] {
                let wt = w.backward_weights[u as usize].0;
                total += wt;
                sum += wt * obs.vertices[u as usize];
            }
            (total, sum)
        })
        .unzip();
    let data = (0..n).map(|v| (v as u32, w_sum[v], target[v] / w_sum[v]));
    match prior {
        None => data.filter(|p| p.1 > 0.0).collect(),
        Some((predicted, weight)) => {
            // Point pulls count POINT_SHARE in the held energy.
            let w = weight / super::POINT_SHARE;
            data.zip(predicted)
                .map(|((v, wv, c), p)| {
                    if wv > 0.0 {
                        (v, w + wv, (p * w + c * wv) / (w + wv))
                    } else {
                        (v, w, *p)
                    }
                })
                .collect()
        }
    }
}

/// Each weighted pair as a plane: a model vertex's own pair through its observed partner's
/// tangent plane where the two normals agree ([`PLANE_AGREEMENT`]), its own where they do
/// not (a phantom surface, or the far side of another part); an observed vertex's pair
/// through its model partner's.
fn planes(w: &Weighed, normals: &[Vector3<f64>], obs: &Observation) -> Vec<Plane> {
    let observed_normal = |v: usize, u: usize| {
        if normals[v].dot(&obs.normals[u]) > PLANE_AGREEMENT {
            obs.normals[u]
        } else {
            normals[v]
        }
    };
    let plane = |v: usize, u: usize, weight: f64, normal: Vector3<f64>| Plane {
        vertex: v as u32,
        weight,
        point: obs.vertices[u],
        normal,
    };
    let own = w.forward.iter().zip(&w.forward_weights).enumerate();
    let theirs = w.backward.iter().zip(&w.backward_weights).enumerate();
    own.filter(|(_, (_, &(wt, _)))| pulls_on(wt))
        .map(|(v, (&(u, _), &(wt, _)))| plane(v, u, wt, observed_normal(v, u)))
        .chain(
            theirs
                .filter(|(_, (_, &(wt, _)))| pulls_on(wt))
                .map(|(u, (&(v, _), &(wt, _)))| plane(v, u, wt, normals[v])),
        )
        .collect()
}
