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
//! part (parts whose bounding box lies farther are not searched) at a slightly wider radius,
//! and the lists serve the following rounds until the pose has moved enough to need new
//! ones.

use crate::geometry::nearest::{tree_distance2, NearestTree};
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

/// rho_c's parameters (metric units).
#[derive(Debug, Clone, Copy)]
pub struct ContactParams {
    /// Sigmoid slope, per metre (paper: 2.0 per cm).
    pub alpha_c: f64,
    /// Distance at which rho_c = 0.5, metres (paper: 2.5 cm).
    pub tau_c: f64,
    pub rule: ContactRule,
    /// For [`ContactRule::RestDistance`]: reference-pose distance above which two vertices
    /// of different parts may be in contact, metres.
    pub rest_distance: f64,
}

/// Paper eq. 2.
pub fn rho_c(d: f64, p: &ContactParams) -> f64 {
    1.0 / (1.0 + (-p.alpha_c * (d - p.tau_c)).exp())
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
    /// Every vertex's possible partners, kept from round to round while the pose changes
    /// little (`None` before the first call).
    partners: Mutex<Option<PartnerLists>>,
}

/// How much farther than the cut-off partner lists reach, metres: the lists stay valid
/// until some vertex has moved half of it.
const PARTNER_MARGIN: f64 = 0.02;

/// Partner lists in compressed rows: vertex v's are `partners[start[v]..start[v + 1]]`.
struct PartnerLists {
    /// The posed vertices the lists were built at, metres.
    posed: Vec<Vector3<f64>>,
    start: Vec<u32>,
    partners: Vec<u32>,
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
    /// The partners a vertex may have within the cut-off are taken from a list built at an
    /// earlier pose with the cut-off widened by [`PARTNER_MARGIN`]; the list is rebuilt when
    /// some vertex has since moved more than half the margin. Exact: two vertices now within
    /// the cut-off were within cut-off + margin then, as each moved at most margin / 2.
    pub fn weights(&self, posed: &[Vector3<f64>], normals: &[Vector3<f64>]) -> Vec<f64> {
        let mut cache = self
            .partners
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        let fresh = cache.as_ref().is_some_and(|c| {
            c.posed.len() == posed.len()
                && c.posed
                    .par_iter()
                    .zip(posed)
                    .all(|(a, b)| (a - b).norm_squared() <= (0.5 * PARTNER_MARGIN).powi(2))
        });
        if !fresh {
            *cache = Some(self.partner_lists(posed, self.cutoff + PARTNER_MARGIN));
        }
        let lists = cache.as_ref().expect("partner lists were just built");
        let cutoff2 = self.cutoff * self.cutoff;
        (0..posed.len())
            .into_par_iter()
            .map(|v| {
                let q = &posed[v];
                let partners =
                    &lists.partners[lists.start[v] as usize..lists.start[v + 1] as usize];
                let best = partners
                    .iter()
                    .map(|&w| (w as usize, tree_distance2(q, &posed[w as usize])))
                    .fold(None, |best: Option<(usize, f64)>, (w, d2)| match best {
                        Some((_, b2)) if b2 <= d2 => best,
                        _ => Some((w, d2)),
                    });
                match best {
                    Some((w, d2)) if d2 <= cutoff2 => {
                        let d = d2.sqrt();
                        let signed = if (q - posed[w]).dot(&normals[w]) >= 0.0 {
                            d
                        } else {
                            -d
                        };
                        rho_c(signed, &self.params)
                    }
                    _ => 1.0,
                }
            })
            .collect()
    }

    /// For every vertex, the vertices the rule allows as its partner that lie within
    /// `radius` metres of it at `posed`.
    fn partner_lists(&self, posed: &[Vector3<f64>], radius: f64) -> PartnerLists {
        let points: Vec<Vec<Vector3<f64>>> = self
            .parts
            .iter()
            .map(|ids| ids.iter().map(|&i| posed[i as usize]).collect())
            .collect();
        let trees: Vec<NearestTree> = points.par_iter().map(|p| NearestTree::new(p)).collect();
        let boxes: Vec<(Vector3<f64>, Vector3<f64>)> = points
            .iter()
            .map(|p| {
                p.iter().fold(
                    (
                        Vector3::repeat(f64::INFINITY),
                        Vector3::repeat(f64::NEG_INFINITY),
                    ),
                    |(lo, hi), x| (lo.inf(x), hi.sup(x)),
                )
            })
            .collect();
        let rest_d2 = self.params.rest_distance.powi(2);
        // The trees hold f32 coordinates: a little slack keeps every point within `radius`.
        let search = radius * (1.0 + 1e-5) + 1e-6;
        let per_vertex: Vec<Vec<u32>> = (0..posed.len())
            .into_par_iter()
            .map(|v| {
                let q = &posed[v];
                let mut found = Vec::new();
                for (b, tree) in trees.iter().enumerate() {
                    if !self.searched[self.labels[v]][b] {
                        continue;
                    }
                    let (lo, hi) = &boxes[b];
                    let gap = (lo - q).sup(&(q - hi)).sup(&Vector3::zeros()).norm();
                    if gap > search {
                        continue;
                    }
                    tree.within(q, search, |k, _| {
                        let w = self.parts[b][k];
                        if self.params.rule == ContactRule::Adjacent
                            || (self.rest[w as usize] - self.rest[v]).norm_squared() > rest_d2
                        {
                            found.push(w);
                        }
                    });
                }
                found
            })
            .collect();
        let mut start = Vec::with_capacity(posed.len() + 1);
        start.push(0u32);
        let mut partners = Vec::new();
        for list in per_vertex {
            partners.extend(list);
            start.push(partners.len() as u32);
        }
        PartnerLists {
            posed: posed.to_vec(),
            start,
            partners,
        }
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
        let mut s = 11u64;
        let mut rnd = move || {
            s = crate::synth::rng::mix64(s);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
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
            // 6 cm, 12.8 cm in all: they touch, then press into each other).
            let mut shift = 0.0;
            for step in 0..12 {
                shift += 0.0005 * 1.5f64.powi(step);
                let posed: Vec<Vector3<f64>> = model
                    .mesh
                    .vertices
                    .iter()
                    .zip(&model.labels)
                    .map(|(x, &l)| if l == 2 { x - shift * Vector3::y() } else { *x })
                    .collect();
                let got = search.weights(&posed, &normals);
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
