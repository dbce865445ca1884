//! Levenberg-Marquardt on the pose increments with the correspondences held (method.md
//! "Stage 6", step b).
//!
//! With correspondences and weights fixed, paper eq. 4 is a sum over model vertices of
//! `W_v |v(p) - c_v|^2` plus a constant: every pair that involves model vertex v (its own
//! nearest observed vertex, and every observed vertex whose nearest model vertex is v)
//! pulls v towards a point, and a weighted sum of squared distances to points is the total
//! weight W_v times the squared distance to their weighted mean c_v. So each model vertex
//! contributes one 3-row residual, with the analytic Jacobian of linear blend skinning.

use crate::skeleton::skinning::{pose_vertex, sparse_vertex_jacobian, Influences};
use crate::skeleton::{Pose, PosedBones, Skeleton};
use nalgebra::{DMatrix, DVector, Vector3};
use rayon::prelude::*;

/// Vertices per parallel work item.
const CHUNK: usize = 2048;

/// What the held correspondences ask of the model: per model vertex, the total weight W_v
/// and the weighted mean target c_v (metres). Vertices with W_v = 0 are left out.
pub struct Targets {
    /// (model vertex, W_v, c_v).
    pub pulls: Vec<(u32, f64, Vector3<f64>)>,
    /// The posed model's unit normal at each pull's vertex (same order as `pulls`).
    pub normals: Vec<Vector3<f64>>,
}

/// The held problem: model, targets.
pub struct HeldProblem<'a> {
    pub skeleton: &'a Skeleton,
    /// Reference (t0) vertices, metres.
    pub rest: &'a [Vector3<f64>],
    pub weights: &'a [Influences],
    pub targets: &'a Targets,
}

impl HeldProblem<'_> {
    /// sum_v W_v |v(p) - c_v|^2 (m^2).
    pub fn energy(&self, pose: &Pose) -> f64 {
        let bones = PosedBones::new(self.skeleton, pose);
        // Fixed chunks summed in order: the same bits on every run and thread count.
        let partial: Vec<f64> = self
            .targets
            .pulls
            .par_chunks(CHUNK)
            .map(|chunk| {
                chunk
                    .iter()
                    .map(|&(v, w, c)| {
                        let v = v as usize;
                        w * (pose_vertex(&bones, &self.rest[v], &self.weights[v]) - c)
                            .norm_squared()
                    })
                    .sum::<f64>()
            })
            .collect();
        partial.iter().sum()
    }

    /// The Gauss-Newton system at `pose`: H = sum W J^T M J, g = sum W J^T r, and the
    /// energy, where M = n n^T + `tangential` (I - n n^T) weighs a residual's part along the
    /// vertex normal n fully and its part along the surface by `tangential` (1: the
    /// point-to-point H of the held energy; below 1 it approaches the curvature of the
    /// distance to the observed surface, along which nearest neighbours slide).
    pub fn normal_equations(
        &self,
        pose: &Pose,
        tangential: f64,
    ) -> (DMatrix<f64>, DVector<f64>, f64) {
        let bones = PosedBones::new(self.skeleton, pose);
        let n = pose.parameter_count();
        let zero = || Accumulator {
            h: vec![0.0; n * n],
            g: vec![0.0; n],
            e: 0.0,
            blocks: Vec::new(),
            cols: Vec::new(),
            along: Vec::new(),
        };
        // Per fixed chunk, then summed in order (deterministic, see `energy`).
        let partials: Vec<Accumulator> = self
            .targets
            .pulls
            .par_chunks(CHUNK)
            .enumerate()
            .map(|(chunk_index, chunk)| {
                chunk
                    .iter()
                    .enumerate()
                    .fold(zero(), |mut acc, (offset, &(v, w, c))| {
                        let v = v as usize;
                        let y = pose_vertex(&bones, &self.rest[v], &self.weights[v]);
                        let r = y - c;
                        acc.e += w * r.norm_squared();
                        sparse_vertex_jacobian(
                            &bones,
                            &self.rest[v],
                            &self.weights[v],
                            &mut acc.blocks,
                        );
                        // Columns: the translation's identity, then each block's three.
                        acc.cols.clear();
                        for k in 0..3 {
                            acc.cols.push((k, Vector3::ith(k, 1.0)));
                        }
                        for (b, c3) in &acc.blocks {
                            for (k, col) in c3.iter().enumerate() {
                                acc.cols.push((3 + 3 * b + k, *col));
                            }
                        }
                        // Below 1, ci^T M cj = t ci.cj + (1 - t)(n.ci)(n.cj); at 1, M = I.
                        let t = tangential;
                        acc.along.clear();
                        if t < 1.0 {
                            let normal = self.targets.normals[chunk_index * CHUNK + offset];
                            acc.along
                                .extend(acc.cols.iter().map(|(_, col)| normal.dot(col)));
                        }
                        for (i, (pi, ci)) in acc.cols.iter().enumerate() {
                            acc.g[*pi] += w * ci.dot(&r);
                            for (j, (pj, cj)) in acc.cols.iter().enumerate().skip(i) {
                                let mut m = ci.dot(cj);
                                if t < 1.0 {
                                    m = t * m + (1.0 - t) * acc.along[i] * acc.along[j];
                                }
                                acc.h[pi * n + pj] += w * m;
                            }
                        }
                        acc
                    })
            })
            .collect();
        let Accumulator { h, g, e, .. } = partials.into_iter().fold(zero(), |mut a, b| {
            a.h.iter_mut().zip(&b.h).for_each(|(x, y)| *x += y);
            a.g.iter_mut().zip(&b.g).for_each(|(x, y)| *x += y);
            a.e += b.e;
            a
        });
        // Only one triangle of each pair (i, j) was summed, in the order the columns came;
        // fold both triangles into a symmetric matrix.
        let mut hm = DMatrix::from_row_slice(n, n, &h);
        for i in 0..n {
            for j in (i + 1)..n {
                let s = hm[(i, j)] + hm[(j, i)];
                hm[(i, j)] = s;
                hm[(j, i)] = s;
            }
        }
        (hm, DVector::from_vec(g), e)
    }
}

/// One chunk's share of the normal equations, with scratch space reused vertex to vertex.
struct Accumulator {
    /// H, row-major, one triangle summed (see `normal_equations`).
    h: Vec<f64>,
    g: Vec<f64>,
    e: f64,
    blocks: Vec<(usize, [Vector3<f64>; 3])>,
    cols: Vec<(usize, Vector3<f64>)>,
    /// n . column, per column.
    along: Vec<f64>,
}

/// How a run of LM steps went.
pub struct StepReport {
    /// Accepted steps.
    pub steps: usize,
    /// Energy before and after (m^2, unnormalized).
    pub energy_before: f64,
    pub energy_after: f64,
}

/// Up to `max_steps` Levenberg-Marquardt steps from `pose` (Marquardt's scaling of the
/// damping by diag(H)); `lambda` carries the damping from call to call. Returns the best
/// pose found (never a worse or non-finite one).
pub fn levenberg_marquardt(
    problem: &HeldProblem,
    pose: &Pose,
    max_steps: usize,
    lambda: &mut f64,
) -> (Pose, StepReport) {
    let mut pose = pose.clone();
    let mut report = StepReport {
        steps: 0,
        energy_before: f64::NAN,
        energy_after: f64::NAN,
    };
    for _ in 0..max_steps {
        let (h, g, e0) = problem.normal_equations(&pose, 1.0);
        if report.steps == 0 {
            report.energy_before = e0;
            report.energy_after = e0;
        }
        if e0.is_nan() || e0 <= 0.0 || !e0.is_finite() {
            break;
        }
        let mut improved = false;
        for _ in 0..12 {
            let Some(delta) = damped_step(&h, &g, *lambda) else {
                *lambda *= 4.0;
                continue;
            };
            let candidate = pose.apply_increment(delta.as_slice());
            let e1 = problem.energy(&candidate);
            if e1 < e0 && candidate.is_finite() {
                pose = candidate;
                report.steps += 1;
                report.energy_after = e1;
                *lambda = (*lambda / 3.0).max(1e-9);
                improved = true;
                break;
            }
            *lambda *= 4.0;
        }
        if !improved || report.energy_after > e0 * (1.0 - 1e-9) {
            break;
        }
    }
    (pose, report)
}

/// The increment solving (H + lambda diag(H)) delta = -g (Marquardt's scaling, with a
/// small floor so that parameters no pair moves stay put); `None` when the system cannot be
/// solved at this damping.
pub fn damped_step(h: &DMatrix<f64>, g: &DVector<f64>, lambda: f64) -> Option<DVector<f64>> {
    let n = h.nrows();
    let floor = 1e-12 * (h.trace() / n as f64).max(1e-30);
    let mut a = h.clone();
    for i in 0..n {
        a[(i, i)] += lambda * h[(i, i)].max(floor) + floor;
    }
    let delta = a.cholesky()?.solve(&(-g));
    delta.iter().all(|x| x.is_finite()).then_some(delta)
}
