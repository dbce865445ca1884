//! rho_c, the model-side observability weight (method.md "Stage 6", paper eq. 2): low where
//! a model vertex touches or penetrates another part of the body.
//!
//! For a model vertex v of part a, v' is the nearest vertex of another part allowed by the
//! contact rule, and d(v) = +|v - v'| when (v - v') . n(v') >= 0 (v outside the other part),
//! else -|v - v'|; rho_c(v) = 1 / (1 + exp(-alpha_c (d - tau_c))).
//!
//! At every joint the two bones' vertices touch by construction, so the rule that picks v'
//! ignores that proximity: either whole parts that meet v's part at a joint
//! ([`ContactRule::Adjacent`]), or single vertices that already lay within a distance of v
//! in the reference pose ([`ContactRule::RestDistance`]).
//!
//! Exact, and fast: beyond a cut-off distance rho_c > 1 - 1e-4 and is taken as 1, so each
//! vertex only needs the allowed vertices near it. Those are listed with one k-d tree per
//! part (parts whose bounding box lies farther are not searched): the candidates that could
//! still be the nearest after a small motion. Each vertex's list serves the following
//! rounds until it or the parts near it have moved enough to need a new one; only those
//! vertices' lists are built again.

use crate::geometry::mesh::point_bounds;
use crate::geometry::nearest::{key, key_distance2_f32, NearestTree};
use crate::skeleton::model::BodyModel;
use crate::skeleton::skinning::joint_neighbours;
use nalgebra::Vector3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::Mutex;

/// Which vertices of other parts may be a vertex's contact partner v'.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ContactRule {
    /// Vertices of parts that do not meet v's part at a joint (parent, children, bones
    /// sharing its head).
    Adjacent,
    /// Vertices of any other part that lay farther than `contact_rest_distance` from v in
    /// the reference pose t0 (contact is proximity the reference pose did not have).
    RestDistance,
}

/// rho_c's parameters (pipeline.yaml key `fit.contact`, metric units).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ContactParams {
    /// Sigmoid slope, per metre. Default 200 (the paper's 2.0 per cm).
    pub alpha_c: f64,
    /// Distance at which rho_c = 0.5, metres. Default 0.025 (the paper's 2.5 cm).
    pub tau_c: f64,
    /// Which vertices may be contact partners: `rest_distance` (default) or `adjacent`.
    pub rule: ContactRule,
    /// For [`ContactRule::RestDistance`]: reference-pose distance above which two vertices
    /// of different parts may be in contact, metres. Default 0.075 (3 tau_c).
    pub rest_distance: f64,
}

impl Default for ContactParams {
    fn default() -> Self {
        ContactParams {
            alpha_c: 200.0,
            tau_c: 0.025,
            rule: ContactRule::RestDistance,
            rest_distance: 0.075,
        }
    }
}

/// Paper eq. 2.
pub fn rho_c(d: f64, p: &ContactParams) -> f64 {
    1.0 / (1.0 + (-p.alpha_c * (d - p.tau_c)).exp())
}

/// Seconds one [`ContactSearch::weights`] call spent in each of its parts.
#[derive(Debug, Clone, Copy, Default)]
pub struct ContactTimes {
    /// Finding the vertices whose partner lists no longer serve.
    pub staleness: f64,
    /// Building those lists again (the parts' k-d trees and the searches).
    pub rebuilding: f64,
    /// Scanning every list for the nearest partner, and the weights.
    pub scanning: f64,
    /// How many vertices' lists were built again.
    pub rebuilt: usize,
}

/// The model's parts and the rule's exclusions, prepared once per sequence.
pub struct ContactSearch {
    /// Reference (t0) vertices and their part labels.
    rest: Vec<Vector3<f64>>,
    labels: Vec<usize>,
    params: ContactParams,
    /// Vertex indices of each part.
    parts: Vec<Vec<u32>>,
    /// `searched[a][b]`: whether part a looks for contact partners in part b.
    searched: Vec<Vec<bool>>,
    /// Beyond this distance rho_c > 1 - 1e-4 and is taken as 1, metres.
    cutoff: f64,
    /// Every vertex's possible partners, kept from round to round while they serve
    /// (`None` before the first call).
    partners: Mutex<Option<PartnerLists>>,
}

/// The partner lists' margin m, metres: a vertex's list holds the allowed vertices within
/// min(nearest + 2 m, cut-off + m) of it, and serves while it and the parts near it have
/// moved less than m, and the parts farther away less than their gap allows (see
/// [`ContactSearch::weights`]).
const PARTNER_MARGIN: f64 = 0.015;

/// At most this many poses at which lists were built are kept; beyond it, the lists of the
/// oldest are rebuilt at the current pose with the stale ones.
const MAX_EPOCHS: usize = 8;

/// Every vertex's possible partners, built at earlier poses ("epochs").
struct PartnerLists {
    /// The posed vertices at each epoch, metres.
    epochs: Vec<Vec<Vector3<f64>>>,
    /// The epoch each vertex's list was built at.
    epoch_of: Vec<u8>,
    /// Entry `v * parts + b`: how far vertex v and part b may move between them (the sum
    /// of their largest motions) before v's list stops serving, metres; infinite for parts
    /// v does not search.
    allowance: Vec<f32>,
    lists: Vec<Vec<u32>>,
}

/// The posed parts' k-d trees and bounding boxes, for building lists at one pose.
struct PosedParts {
    trees: Vec<NearestTree>,
    boxes: Vec<(Vector3<f64>, Vector3<f64>)>,
}

/// Distance from `q` to the box `(lo, hi)` (0 inside), metres.
fn box_gap(q: &Vector3<f64>, (lo, hi): &(Vector3<f64>, Vector3<f64>)) -> f64 {
    (lo - q).sup(&(q - hi)).sup(&Vector3::zeros()).norm()
}

/// The squared distance (as the trees measure it, m^2) and index of the nearest of the
/// `listed` vertices to vertex v; (infinity, `usize::MAX`) for none. Lists are in index
/// order, so among equally near vertices the lowest index wins, whatever order the lists
/// were found in.
fn nearest_listed(listed: &[u32], keys: &[[f32; 3]], v: usize) -> (f64, usize) {
    // Compared in f32, before `key_distance2` widens them (which orders the same).
    let q = &keys[v];
    let (mut best2, mut best) = (f32::INFINITY, u32::MAX);
    for &w in listed {
        let d2 = key_distance2_f32(q, &keys[w as usize]);
        // Selects, not a branch: which listed vertex is nearest so far is unpredictable.
        let nearer = d2 < best2;
        best = if nearer { w } else { best };
        best2 = if nearer { d2 } else { best2 };
    }
    if best == u32::MAX {
        (f64::INFINITY, usize::MAX)
    } else {
        (best2 as f64, best as usize)
    }
}

impl ContactSearch {
    pub fn new(model: &BodyModel, params: ContactParams) -> ContactSearch {
        let nb = model.skeleton.bones.len();
        let mut parts = vec![Vec::new(); nb];
        for (i, &l) in model.labels.iter().enumerate() {
            parts[l].push(i as u32);
        }
        let searched = (0..nb)
            .map(|a| {
                let near = joint_neighbours(&model.skeleton, a);
                (0..nb)
                    .map(|b| {
                        b != a
                            && !parts[b].is_empty()
                            && (params.rule == ContactRule::RestDistance || !near.contains(&b))
                    })
                    .collect()
            })
            .collect();
        ContactSearch {
            rest: model.mesh.vertices.clone(),
            labels: model.labels.clone(),
            params,
            parts,
            searched,
            cutoff: params.tau_c + (1e4f64).ln() / params.alpha_c,
            partners: Mutex::new(None),
        }
    }

    /// rho_c of every vertex of the model posed at `posed` with vertex `normals`.
    ///
    /// Exact, with partner lists kept from earlier rounds. Let vertex v's list be built when
    /// its nearest allowed vertex lay at d0, holding every allowed vertex then within
    /// r = min(d0 + 2 m, cut-off + m), and part b's bounding box at a gap G_b from v.
    /// Since then v moved dv and each part b's vertices at most D_b; a pair's distance
    /// changed by at most s_b = dv + D_b. The list still holds v's nearest allowed vertex w
    /// whenever that lies within the cut-off, provided s_b <= m for the parts with
    /// G_b <= cut-off + m and s_b < G_b - cut-off for the others: w's part is one of the
    /// former (the others' vertices all still lie beyond G_b - s_b > cut-off), and w then
    /// lay within d1(w) + m <= d1(old nearest) + m <= d0 + 2 m, and within cut-off + m (the
    /// old nearest, at d0 <= r, is in such a part too). Vertices whose lists fail this get
    /// new lists at the current pose.
    /// Also returns where the call's time went.
    pub fn weights(
        &self,
        posed: &[Vector3<f64>],
        normals: &[Vector3<f64>],
    ) -> (Vec<f64>, ContactTimes) {
        let mut cache = self
            .partners
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        let started = std::time::Instant::now();
        let mut stale: Vec<u32> = match cache.as_ref() {
            Some(c) if c.epoch_of.len() == posed.len() => self.stale_lists(c, posed),
            _ => (0..posed.len() as u32).collect(),
        };
        let keys: Vec<[f32; 3]> = posed.par_iter().map(key).collect();
        let checked = std::time::Instant::now();
        if !stale.is_empty() {
            let c = match cache.as_mut() {
                Some(c) if c.epoch_of.len() == posed.len() => c,
                _ => cache.insert(PartnerLists {
                    epochs: Vec::new(),
                    epoch_of: vec![0; posed.len()],
                    allowance: vec![0.0; posed.len() * self.parts.len()],
                    lists: vec![Vec::new(); posed.len()],
                }),
            };
            if c.epochs.len() >= MAX_EPOCHS {
                // Epoch 0 is the oldest: its lists join the stale ones, and it is dropped.
                let mut renewed: Vec<bool> = c.epoch_of.iter().map(|&e| e == 0).collect();
                for &v in &stale {
                    renewed[v as usize] = true;
                }
                stale = (0..posed.len() as u32)
                    .filter(|&v| renewed[v as usize])
                    .collect();
            }
            self.renew(c, &stale, posed, &keys);
        }
        let lists = cache.as_ref().expect("partner lists were just built");
        let cutoff2 = self.cutoff * self.cutoff;
        let rebuilt = std::time::Instant::now();
        let weights = (0..posed.len())
            .into_par_iter()
            .map(|v| {
                let (d2, w) = nearest_listed(&lists.lists[v], &keys, v);
                if d2 > cutoff2 {
                    return 1.0;
                }
                let d = d2.sqrt();
                let signed = if (posed[v] - posed[w]).dot(&normals[w]) >= 0.0 {
                    d
                } else {
                    -d
                };
                rho_c(signed, &self.params)
            })
            .collect();
        let times = ContactTimes {
            staleness: (checked - started).as_secs_f64(),
            rebuilding: (rebuilt - checked).as_secs_f64(),
            scanning: rebuilt.elapsed().as_secs_f64(),
            rebuilt: stale.len(),
        };
        (weights, times)
    }

    /// The vertices whose lists no longer serve at `posed` (see [`Self::weights`]).
    fn stale_lists(&self, c: &PartnerLists, posed: &[Vector3<f64>]) -> Vec<u32> {
        let nb = self.parts.len();
        // moved[e][b]: the farthest any vertex of part b moved since epoch e.
        let moved: Vec<Vec<f64>> = c
            .epochs
            .iter()
            .map(|then| {
                self.parts
                    .par_iter()
                    .map(|ids| {
                        ids.iter()
                            .map(|&i| (posed[i as usize] - then[i as usize]).norm_squared())
                            .fold(0.0, f64::max)
                            .sqrt()
                    })
                    .collect()
            })
            .collect();
        (0..posed.len() as u32)
            .into_par_iter()
            .filter(|&v| {
                let v = v as usize;
                let e = c.epoch_of[v] as usize;
                let dv = (posed[v] - c.epochs[e][v]).norm();
                let allowed = &c.allowance[v * nb..(v + 1) * nb];
                (0..nb).any(|b| dv + moved[e][b] > allowed[b] as f64)
            })
            .collect()
    }

    /// Builds new lists for the vertices `ids` at `posed`, as a new epoch, and drops the
    /// epochs no list refers to any more.
    /// `keys`: `posed` as the trees store it.
    fn renew(&self, c: &mut PartnerLists, ids: &[u32], posed: &[Vector3<f64>], keys: &[[f32; 3]]) {
        let parts = self.posed_parts(posed);
        let nb = self.parts.len();
        // Each new list's allowances in one block (one row per vertex of `ids`), and one
        // scratch buffer per worker for the candidates.
        let mut allowances = vec![0f32; ids.len() * nb];
        let built: Vec<Vec<u32>> = allowances
            .par_chunks_mut(nb.max(1))
            .zip(ids.par_iter())
            .map_init(Vec::new, |found, (allowance, &v)| {
                let v = v as usize;
                // The old list's nearest partner now bounds how far the nearest one lies.
                let bound = nearest_listed(&c.lists[v], keys, v).0.sqrt();
                self.partner_list(&parts, posed, v, bound, allowance, found)
            })
            .collect();
        let epoch = c.epochs.len() as u8;
        c.epochs.push(posed.to_vec());
        for ((&v, list), allowance) in ids.iter().zip(built).zip(allowances.chunks(nb.max(1))) {
            let v = v as usize;
            c.epoch_of[v] = epoch;
            c.allowance[v * nb..(v + 1) * nb].copy_from_slice(allowance);
            c.lists[v] = list;
        }
        // Drop the epochs no list refers to and renumber the rest.
        let mut used = vec![false; c.epochs.len()];
        for &e in &c.epoch_of {
            used[e as usize] = true;
        }
        let renumber: Vec<u8> = used
            .iter()
            .scan(0u8, |kept, &u| {
                let at = *kept;
                *kept += u as u8;
                Some(at)
            })
            .collect();
        let mut in_use = used.iter();
        c.epochs
            .retain(|_| *in_use.next().expect("one flag per epoch"));
        for x in &mut c.epoch_of {
            *x = renumber[*x as usize];
        }
    }

    fn posed_parts(&self, posed: &[Vector3<f64>]) -> PosedParts {
        let points: Vec<Vec<Vector3<f64>>> = self
            .parts
            .iter()
            .map(|ids| ids.iter().map(|&i| posed[i as usize]).collect())
            .collect();
        let trees = points.par_iter().map(|p| NearestTree::new(p)).collect();
        // An empty part is never searched: its box is never read.
        let boxes = points
            .iter()
            .map(|p| point_bounds(p).unwrap_or((Vector3::zeros(), Vector3::zeros())))
            .collect();
        PosedParts { trees, boxes }
    }

    /// Vertex v's list at `posed`: the allowed vertices within min(nearest + 2 m, cut-off +
    /// m); its allowances (one per part, see [`PartnerLists::allowance`]) are written into
    /// `allowance`. `bound`: a distance the nearest allowed vertex is known to lie within,
    /// metres (infinity when none is known). `found`: scratch space for the candidates.
    fn partner_list(
        &self,
        parts: &PosedParts,
        posed: &[Vector3<f64>],
        v: usize,
        bound: f64,
        allowance: &mut [f32],
        found: &mut Vec<(u32, f64)>,
    ) -> Vec<u32> {
        let m = PARTNER_MARGIN;
        let q = &posed[v];
        let rest_d2 = self.params.rest_distance.powi(2);
        let reach = self.cutoff + m;
        // The trees hold f32 coordinates: a little slack keeps every point within reach.
        let slack = |r: f64| r * (1.0 + 1e-5) + 1e-6;
        // Only vertices within the nearest's distance + 2 m are listed: with an upper bound
        // on that distance, nothing farther needs visiting.
        let search = slack((bound + 2.0 * m).min(reach));
        allowance.fill(f32::INFINITY);
        found.clear();
        for (b, tree) in parts.trees.iter().enumerate() {
            if !self.searched[self.labels[v]][b] {
                continue;
            }
            let gap = box_gap(q, &parts.boxes[b]);
            // Rounded down to f32, and a little less: the stored allowance never exceeds
            // the true one.
            allowance[b] = if gap <= reach {
                m as f32
            } else {
                ((gap - self.cutoff) * (1.0 - 1e-5)) as f32
            };
            if gap > search {
                continue;
            }
            tree.within(q, search, |k, d2| {
                let w = self.parts[b][k];
                if self.params.rule == ContactRule::Adjacent
                    || (self.rest[w as usize] - self.rest[v]).norm_squared() > rest_d2
                {
                    found.push((w, d2));
                }
            });
        }
        let nearest = found
            .iter()
            .map(|x| x.1)
            .fold(f64::INFINITY, f64::min)
            .sqrt();
        let r = slack((nearest + 2.0 * m).min(reach));
        let mut list: Vec<u32> = found
            .iter()
            .filter(|&&(_, d2)| d2 <= r * r)
            .map(|&(w, _)| w)
            .collect();
        // In memory order, for the scans.
        list.sort_unstable();
        list
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::mesh::TriMesh;
    use crate::skeleton::{Bone, Skeleton};

    /// A U of three bones in a chain (the first and last are not adjacent, 20 cm apart),
    /// their flesh as scattered points within 4 cm of each bone.
    fn model() -> BodyModel {
        let corners = [
            Vector3::new(0.0, 0.0, 1.0),
            Vector3::new(0.3, 0.0, 1.0),
            Vector3::new(0.3, 0.2, 1.0),
            Vector3::new(0.0, 0.2, 1.0),
        ];
        let bones: Vec<Bone> = (0..3usize)
            .map(|k| Bone {
                name: format!("b{k}"),
                parent: k.checked_sub(1),
                head: corners[k],
                tail: corners[k + 1],
            })
            .collect();
        let mut rnd = crate::rng::chained_uniform(11);
        let (mut vertices, mut labels) = (Vec::new(), Vec::new());
        for (k, b) in bones.iter().enumerate() {
            for _ in 0..1500 {
                let along = b.head + rnd() * (b.tail - b.head);
                let dir = Vector3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5).normalize();
                vertices.push(along + 0.04 * dir);
                labels.push(k);
            }
        }
        BodyModel {
            skeleton: Skeleton {
                reference_frame: 0,
                bones,
            },
            weights: vec![Default::default(); vertices.len()],
            mesh: TriMesh {
                vertices,
                triangles: Vec::new(),
            },
            labels,
        }
    }

    /// rho_c by brute force over every allowed partner.
    fn brute(
        model: &BodyModel,
        p: &ContactParams,
        posed: &[Vector3<f64>],
        normals: &[Vector3<f64>],
    ) -> Vec<f64> {
        let near: Vec<Vec<usize>> = (0..model.skeleton.bones.len())
            .map(|a| joint_neighbours(&model.skeleton, a))
            .collect();
        let rest = &model.mesh.vertices;
        (0..posed.len())
            .map(|v| {
                let (la, q) = (model.labels[v], posed[v]);
                let best = (0..posed.len())
                    .filter(|&w| {
                        let lb = model.labels[w];
                        lb != la
                            && match p.rule {
                                ContactRule::Adjacent => !near[la].contains(&lb),
                                ContactRule::RestDistance => {
                                    (rest[w] - rest[v]).norm() > p.rest_distance
                                }
                            }
                    })
                    .min_by(|&a, &b| {
                        (posed[a] - q)
                            .norm_squared()
                            .total_cmp(&(posed[b] - q).norm_squared())
                    });
                match best {
                    Some(w) => {
                        let d = (posed[w] - q).norm();
                        let signed = if (q - posed[w]).dot(&normals[w]) >= 0.0 {
                            d
                        } else {
                            -d
                        };
                        // Beyond the cut-off (rho_c > 1 - 1e-4 when outside) it is 1.
                        if d > p.tau_c + (1e4f64).ln() / p.alpha_c {
                            1.0
                        } else {
                            rho_c(signed, p)
                        }
                    }
                    None => 1.0,
                }
            })
            .collect()
    }

    /// The lists built at one pose serve nearby poses exactly, and are rebuilt for far ones:
    /// every weight equals the brute-force one, with both rules, as the arms close in.
    #[test]
    fn kept_partner_lists_agree_with_brute_force() {
        let model = model();
        let normals: Vec<Vector3<f64>> = model
            .mesh
            .vertices
            .iter()
            .zip(&model.labels)
            .map(|(x, &l)| {
                let b = &model.skeleton.bones[l];
                let axis = (b.tail - b.head).normalize();
                let off = x - b.head;
                (off - off.dot(&axis) * axis).normalize()
            })
            .collect();
        for rule in [ContactRule::Adjacent, ContactRule::RestDistance] {
            let p = ContactParams {
                alpha_c: 200.0,
                tau_c: 0.025,
                rule,
                rest_distance: 0.075,
            };
            let search = ContactSearch::new(&model, p);
            // The last bone moves rigidly towards the first by growing steps (0.5 mm up to
            // 6 cm, 12.8 cm in all: they touch, then press into each other), while the first
            // sways along x by 0-8 mm: lists go stale in some places and not others.
            let mut shift = 0.0;
            for step in 0..12 {
                shift += 0.0005 * 1.5f64.powi(step);
                let posed: Vec<Vector3<f64>> = model
                    .mesh
                    .vertices
                    .iter()
                    .zip(&model.labels)
                    .map(|(x, &l)| match l {
                        0 => x + 0.004 * (step % 3) as f64 * Vector3::x(),
                        2 => x - shift * Vector3::y(),
                        _ => *x,
                    })
                    .collect();
                let got = search.weights(&posed, &normals).0;
                let want = brute(&model, &p, &posed, &normals);
                let worst = got
                    .iter()
                    .zip(&want)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max);
                let low = got.iter().filter(|&&r| r < 0.5).count();
                // The search measures distances in f32 like the k-d trees (about 1e-7 m here).
                assert!(worst < 1e-5, "{rule:?} step {step}: differs by {worst}");
                if step == 11 {
                    assert!(low > 50, "{rule:?}: the bones should touch ({low} low)");
                }
            }
        }
    }
}
