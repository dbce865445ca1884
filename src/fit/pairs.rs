//! The pairs of a round (method.md "Stage 6"): each posed model vertex's nearest observed
//! vertex and each observed vertex's nearest model vertex, found both ways; and the frame's
//! observation prepared for those searches (thinned, in a k-d tree and in cells).

use super::kept_nearest::{MovingPoints, MovingQueries};
use super::probe::Probe;
use super::{FitParams, Method, Observation};
use crate::geometry::cell_grid::CellGrid;
use crate::geometry::nearest::{key, NearestTree};
use crate::geometry::oriented_nearest::OrientedTree;
use nalgebra::Vector3;
use rayon::prelude::*;

/// The cell edge of the grids that answer the short nearest searches between rounds
/// (`kept_nearest`), in units of the surface's spacing (`sample_spacing` for the
/// observed surface, `model_spacing` for the model): a search within a spacing or two
/// visits a few cells of a few points each (tripod, 1 cm: 2 cm cells 1.15x faster than
/// 1 cm ones).
const SEARCH_CELLS_PER_SPACING: f64 = 2.0;

/// The grids' cell edge for a surface thinned to `spacing` metres (0: not thinned, taken as
/// the paper's 1 cm), metres.
pub(super) fn search_cell(spacing: f64) -> f64 {
    SEARCH_CELLS_PER_SPACING * if spacing > 0.0 { spacing } else { 0.01 }
}

/// How far the `normals` baseline's search looks for a vertex whose normal agrees, metres.
pub const COMPATIBLE_SEARCH_LIMIT: f64 = 0.2;

/// A partner: its index on the other surface and the squared distance to it, m^2
/// (`(0, inf)` for none).
pub(super) type Partner = (usize, f64);

/// A frame's observation prepared for the rounds ([`prepare`]).
pub(super) struct Prepared {
    /// Finite observed vertices thinned to `sample_spacing`.
    pub obs: Observation,
    pub tree: NearestTree,
    /// The same points with their normals, for the `normals` baseline's search (`None` for
    /// the other methods).
    pub oriented: Option<OrientedTree>,
    /// The same points in cells ([`search_cell`]), for the short searches.
    pub grid: CellGrid,
    /// Nearest answers kept between this frame's rounds, both ways (every start's rounds
    /// may share them: they hold for any pose).
    pub kept: std::sync::Mutex<(MovingQueries, MovingPoints)>,
    /// Observed vertices before thinning (for the diagnostics).
    pub observed: usize,
    /// Where the motion prior pulls each thinned model vertex, and its weight.
    pub prior: Option<(Vec<Vector3<f64>>, f64)>,
}

/// The frame's observation as the rounds use it: finite vertices only, thinned to
/// `sample_spacing`, with its k-d tree; `None` when too little of it is left (fewer than
/// `min_observed_share` of the model's `model_vertices`).
pub(super) fn prepare(obs: &Observation, p: &FitParams, model_vertices: usize) -> Option<Prepared> {
    if obs.vertices.is_empty()
        || (obs.vertices.len() as f64) < p.min_observed_share * model_vertices as f64
    {
        return None;
    }
    // Non-finite observations (a damaged cache, a hostile file) are dropped, never
    // fitted: NaN must not reach a pose.
    let finite: Vec<usize> = (0..obs.vertices.len())
        .filter(|&i| {
            obs.vertices[i]
                .iter()
                .chain(obs.normals[i].iter())
                .all(|v| v.is_finite())
                && obs.rho_p[i].is_finite()
        })
        .collect();
    let points: Vec<Vector3<f64>> = finite.iter().map(|&i| obs.vertices[i]).collect();
    let keep: Vec<usize> = thin(&points, p.sample_spacing)
        .into_iter()
        .map(|k| finite[k])
        .collect();
    if keep.is_empty() {
        return None;
    }
    let input_count = obs.vertices.len();
    let obs = Observation {
        vertices: keep.iter().map(|&i| obs.vertices[i]).collect(),
        normals: keep.iter().map(|&i| obs.normals[i]).collect(),
        rho_p: keep.iter().map(|&i| obs.rho_p[i]).collect(),
    };
    let tree = NearestTree::new(&obs.vertices);
    let grid = CellGrid::new(tree.keys(), search_cell(p.sample_spacing));
    let oriented =
        (p.method == Method::Normals).then(|| OrientedTree::new(&obs.vertices, &obs.normals));
    Some(Prepared {
        grid,
        oriented,
        observed: input_count,
        obs,
        tree,
        kept: Default::default(),
        prior: None,
    })
}

/// Indices of `points` thinned to one per cube of side `spacing` (the point nearest the
/// cube's centre; ties to the lower index), in increasing order; all of them for spacing 0.
pub fn thin(points: &[Vector3<f64>], spacing: f64) -> Vec<usize> {
    if spacing <= 0.0 {
        return (0..points.len()).collect();
    }
    let mut best: std::collections::HashMap<[i64; 3], (usize, f64)> =
        std::collections::HashMap::new();
    for (i, p) in points.iter().enumerate() {
        let c = p / spacing;
        let cell = [c.x.floor() as i64, c.y.floor() as i64, c.z.floor() as i64];
        let centre = Vector3::new(cell[0] as f64, cell[1] as f64, cell[2] as f64).add_scalar(0.5);
        let d = (c - centre).norm_squared();
        let e = best.entry(cell).or_insert((i, d));
        if d < e.1 {
            *e = (i, d);
        }
    }
    let mut keep: Vec<usize> = best.into_values().map(|x| x.0).collect();
    keep.sort_unstable();
    keep
}

/// Whether a model vertex's normal and an observed vertex's agree, for the `normals`
/// baseline: their dot product is at least `min_dot` (the cosine of `normal_angle_deg`).
pub(super) fn normals_agree(model: &Vector3<f64>, observed: &Vector3<f64>, min_dot: f64) -> bool {
    model.dot(observed) >= min_dot
}

/// The nearest partners both ways of the posed model vertices `posed`: each model vertex's
/// observed partner, then each observed vertex's model partner. With `compatible` (the
/// `normals` baseline: Ogawara et al.'s search, as the paper's Fig. 12 describes it: the
/// posed model's normals and the smallest dot product with which they agree) the nearest
/// whose normal agrees ([`normals_agree`]), within [`COMPATIBLE_SEARCH_LIMIT`]; a model vertex
/// may so pair with a phantom surface or, where the touching surfaces are missing, with the
/// far side of the other part. Without it, the nearest, reusing the earlier rounds' answers
/// that still hold (`kept_nearest`: the same answers as fresh searches).
pub(super) fn find_pairs(
    prepared: &Prepared,
    posed: &[Vector3<f64>],
    compatible: Option<(&[Vector3<f64>], f64)>,
    model_cell: f64,
    probe: &Probe,
) -> (Vec<Partner>, Vec<Partner>) {
    match compatible {
        Some((normals, min_dot)) => compatible_pairs(prepared, posed, normals, min_dot, probe),
        None => nearest_pairs(prepared, posed, model_cell, probe),
    }
}

/// [`find_pairs`] with normals that must agree, in trees that bound their points' normals.
fn compatible_pairs(
    prepared: &Prepared,
    posed: &[Vector3<f64>],
    normals: &[Vector3<f64>],
    min_dot: f64,
    probe: &Probe,
) -> (Vec<Partner>, Vec<Partner>) {
    let obs = &prepared.obs;
    let observed_tree = prepared
        .oriented
        .as_ref()
        .expect("`prepare` builds the oriented tree for the `normals` method");
    // Each query's nearest partner in `tree` (whose points have `tree_normals`) with a normal
    // that agrees.
    let partners = |queries: &[Vector3<f64>],
                    query_normals: &[Vector3<f64>],
                    tree: &OrientedTree,
                    tree_normals: &[Vector3<f64>]|
     -> Vec<Partner> {
        queries
            .par_iter()
            .zip(query_normals)
            .map(|(q, n)| {
                let agrees = |j: usize| normals_agree(n, &tree_normals[j], min_dot);
                tree.nearest_agreeing(q, n, min_dot, COMPATIBLE_SEARCH_LIMIT, &agrees)
                    .unwrap_or((0, f64::INFINITY))
            })
            .collect()
    };
    // Model -> observed, while the model's tree for the way back is built.
    let (forward, model_tree) = rayon::join(
        || {
            probe.time("nearest model->observed", || {
                partners(posed, normals, observed_tree, &obs.normals)
            })
        },
        || probe.time("model tree", || OrientedTree::new(posed, normals)),
    );
    let backward = probe.time("nearest observed->model", || {
        partners(&obs.vertices, &obs.normals, &model_tree, normals)
    });
    (forward, backward)
}

/// [`find_pairs`] without normals: the nearest both ways, reusing kept answers.
fn nearest_pairs(
    prepared: &Prepared,
    posed: &[Vector3<f64>],
    model_cell: f64,
    probe: &Probe,
) -> (Vec<Partner>, Vec<Partner>) {
    let obs_tree = &prepared.tree;
    let keys: Vec<[f32; 3]> = posed.iter().map(key).collect();
    let mut guard = prepared.kept.lock().unwrap_or_else(|e| e.into_inner());
    let (to_observed, to_model) = &mut *guard;
    let reused_before = [to_observed.reused, to_model.reused];
    let (forward, backward) = rayon::join(
        || {
            probe.time("nearest model->observed", || {
                to_observed.partners(&keys, obs_tree, &prepared.grid)
            })
        },
        || {
            let answers = probe.time("nearest observed->model", || {
                to_model.kept(obs_tree.keys(), &keys)
            });
            if answers.iter().all(|a| a.is_ok()) {
                answers.into_iter().flatten().collect()
            } else {
                probe.time("model grid", || to_model.grid.rebuild(&keys, model_cell));
                probe.time("nearest observed->model", || {
                    to_model.search(obs_tree.keys(), &keys, answers)
                })
            }
        },
    );
    probe.add_nearest([
        to_observed.reused - reused_before[0],
        forward.len(),
        to_model.reused - reused_before[1],
        backward.len(),
    ]);
    (forward, backward)
}
