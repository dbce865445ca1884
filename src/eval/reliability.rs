//! How well ZNCC tells true surface from false (method.md "Stage 4"), against the true
//! meshes: every reconstructed vertex within one voxel of the true surface is *true*, every
//! vertex more than two voxels away (phantom volume, bridges between touching parts) is
//! *false*; vertices in between are left out.
//!
//! Two AUCs: over all labelled vertices, and over those seen by two or more cameras, where
//! ZNCC is defined. A vertex fewer than two cameras see scores -1 whatever it is, so the first
//! also measures how much of the true surface the cameras miss (tripod t0: 16% of the true
//! vertices, AUC 0.86 over all, 0.997 over the seen ones).

use crate::error::Result;
use crate::runner::Job;
use rayon::prelude::*;
use std::fmt::Write as _;

/// One frame's separation figures.
#[derive(Debug, Clone)]
pub struct ReliabilityRow {
    pub frame: u32,
    /// Vertices labelled true and false.
    pub true_vertices: usize,
    pub false_vertices: usize,
    /// ROC AUC of ZNCC as a classifier of true vs false vertices (1 perfect, 0.5 chance);
    /// NaN when one class is empty.
    pub auc: f64,
    /// The same over the vertices seen by two or more cameras.
    pub auc_seen: f64,
    /// Mean rho_p of the false vertices.
    pub rho_p_false: f64,
    /// Mean rho_p of the true vertices seen by three or more cameras.
    pub rho_p_true_seen3: f64,
}

/// ROC AUC of `scores` for `positives` against `negatives` (ties count half): the
/// probability that a random positive scores above a random negative.
pub fn roc_auc(positives: &[f32], negatives: &[f32]) -> f64 {
    if positives.is_empty() || negatives.is_empty() {
        return f64::NAN;
    }
    let mut all: Vec<(f32, bool)> = positives
        .iter()
        .map(|&s| (s, true))
        .chain(negatives.iter().map(|&s| (s, false)))
        .collect();
    all.sort_by(|a, b| a.0.total_cmp(&b.0));
    // Mann-Whitney U with average ranks over ties.
    let mut rank_sum = 0.0;
    let mut i = 0;
    while i < all.len() {
        let mut j = i;
        while j < all.len() && all[j].0 == all[i].0 {
            j += 1;
        }
        let rank = (i + j + 1) as f64 / 2.0; // mean of ranks i+1 ..= j
        rank_sum += rank * all[i..j].iter().filter(|x| x.1).count() as f64;
        i = j;
    }
    let (np, nn) = (positives.len() as f64, negatives.len() as f64);
    (rank_sum - np * (np + 1.0) / 2.0) / (np * nn)
}

fn mean(v: impl Iterator<Item = f32>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x as f64, n + 1));
    if n == 0 {
        f64::NAN
    } else {
        s / n as f64
    }
}

/// Separation figures for every selected frame with a true mesh and a cached reliability.
pub fn evaluate(job: &Job) -> Result<Vec<ReliabilityRow>> {
    let mut rows = Vec::new();
    for &frame in &job.frames {
        if job.cache.manifest("reliability", frame).is_none() {
            continue;
        }
        let Some(truth) = job.sequence.ground_truth_mesh(frame)? else {
            continue;
        };
        use crate::artifacts::reconstruction::{self, Surface};
        let obs = crate::artifacts::observation::read(&job.cache, frame)?;
        let grid = reconstruction::read_grid_spec(&job.cache, Surface::Refined, frame)?;
        let h = grid.voxel;
        let truth = super::TruthSamples::new(&truth);
        let distance: Vec<f64> = obs
            .vertices
            .par_iter()
            .map(|v| truth.signed_distance(&v.cast()).abs())
            .collect();
        let is_true = |i: usize| distance[i] <= h;
        let is_false = |i: usize| distance[i] > 2.0 * h;
        let n = obs.vertices.len();
        let pos: Vec<f32> = (0..n)
            .filter(|&i| is_true(i))
            .map(|i| obs.zncc[i])
            .collect();
        let neg: Vec<f32> = (0..n)
            .filter(|&i| is_false(i))
            .map(|i| obs.zncc[i])
            .collect();
        let seen = |i: &usize| obs.cameras[*i] >= 2;
        let pos_seen: Vec<f32> = (0..n)
            .filter(|&i| is_true(i))
            .filter(seen)
            .map(|i| obs.zncc[i])
            .collect();
        let neg_seen: Vec<f32> = (0..n)
            .filter(|&i| is_false(i))
            .filter(seen)
            .map(|i| obs.zncc[i])
            .collect();
        rows.push(ReliabilityRow {
            frame,
            true_vertices: pos.len(),
            false_vertices: neg.len(),
            auc: roc_auc(&pos, &neg),
            auc_seen: roc_auc(&pos_seen, &neg_seen),
            rho_p_false: mean((0..n).filter(|&i| is_false(i)).map(|i| obs.rho_p[i])),
            rho_p_true_seen3: mean(
                (0..n)
                    .filter(|&i| is_true(i) && obs.cameras[i] >= 3)
                    .map(|i| obs.rho_p[i]),
            ),
        });
    }
    Ok(rows)
}

/// The CSV text of reliability rows.
pub fn to_csv(rows: &[ReliabilityRow]) -> String {
    let mut s = String::from(
        "frame,true_vertices,false_vertices,roc_auc,rho_p_false,rho_p_true_seen3,roc_auc_seen\n",
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{},{},{},{:.4},{:.4},{:.4},{:.4}",
            r.frame,
            r.true_vertices,
            r.false_vertices,
            r.auc,
            r.rho_p_false,
            r.rho_p_true_seen3,
            r.auc_seen
        );
    }
    s
}

/// A printed table of reliability rows.
pub fn table(rows: &[ReliabilityRow]) -> String {
    let mut s = format!(
        "{:>6}  {:>6}  {:>6}  {:>7}  {:>11}  {:>11}  {:>15}\n",
        "frame", "true", "false", "ROC AUC", "AUC seen 2+", "rho_p false", "rho_p true (3+)"
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{:>6}  {:>6}  {:>6}  {:>7.3}  {:>11.3}  {:>11.3}  {:>15.3}",
            r.frame,
            r.true_vertices,
            r.false_vertices,
            r.auc,
            r.auc_seen,
            r.rho_p_false,
            r.rho_p_true_seen3
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::roc_auc;

    #[test]
    fn auc_of_separated_tied_and_reversed_scores() {
        assert_eq!(roc_auc(&[0.9, 0.8], &[0.1, 0.2, 0.3]), 1.0);
        assert_eq!(roc_auc(&[0.1], &[0.9]), 0.0);
        assert_eq!(roc_auc(&[0.5, 0.5], &[0.5]), 0.5);
        assert!((roc_auc(&[0.2, 0.6], &[0.4]) - 0.5).abs() < 1e-12);
    }
}
