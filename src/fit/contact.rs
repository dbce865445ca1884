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
//! Exact, and fast: one k-d tree per part on the posed vertices; parts whose bounding box
//! lies beyond the cut-off distance (where rho_c > 1 - 1e-4) are not searched and leave
//! rho_c = 1.

use crate::geometry::nearest::NearestTree;
use crate::skeleton::model::BodyModel;
use crate::skeleton::skinning::joint_neighbours;
use nalgebra::Vector3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

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
        }
    }

    /// rho_c of every vertex of the model posed at `posed` with vertex `normals`.
    pub fn weights(&self, posed: &[Vector3<f64>], normals: &[Vector3<f64>]) -> Vec<f64> {
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
        let rest = &self.rest;
        let labels = &self.labels;
        let rest_d2 = self.params.rest_distance.powi(2);
        (0..posed.len())
            .into_par_iter()
            .map(|v| {
                let q = &posed[v];
                let mut best: Option<(usize, f64)> = None;
                for (b, tree) in trees.iter().enumerate() {
                    if !self.searched[labels[v]][b] {
                        continue;
                    }
                    let (lo, hi) = &boxes[b];
                    let gap = (lo - q)
                        .sup(&(q - hi))
                        .sup(&Vector3::zeros())
                        .norm_squared();
                    let limit = best.map_or(self.cutoff * self.cutoff, |x| x.1);
                    if gap > limit {
                        continue;
                    }
                    let allowed = |w: usize| {
                        self.params.rule == ContactRule::Adjacent
                            || (rest[w] - rest[v]).norm_squared() > rest_d2
                    };
                    let mut consider = |k: usize, d2: f64| {
                        let w = self.parts[b][k] as usize;
                        if d2 < best.map_or(f64::INFINITY, |x| x.1) && allowed(w) {
                            best = Some((w, d2));
                        }
                    };
                    let Some((k, d2)) = tree.nearest(q) else {
                        continue;
                    };
                    if allowed(self.parts[b][k] as usize) {
                        consider(k, d2);
                    } else {
                        tree.within(q, limit.sqrt(), &mut consider);
                    }
                }
                match best {
                    Some((w, d2)) if d2 <= self.cutoff * self.cutoff => {
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
}
