//! Levenberg-Marquardt on the pose increments with the correspondences held (method.md
//! "Stage 6", step b).
//!
//! With correspondences and weights fixed, paper eq. 4 is a sum over model vertices of
//! `W_v |v(p) - c_v|^2` plus a constant: every pair that involves model vertex v (its own
//! nearest observed vertex, and every observed vertex whose nearest model vertex is v)
//! pulls v towards a point, and a weighted sum of squared distances to points is the total
//! weight W_v times the squared distance to their weighted mean c_v. So each model vertex
//! contributes one 3-row residual, with the analytic Jacobian of linear blend skinning.

use super::hold::HiddenHold;
use super::moments::{PlaneMoments, RigidMoments};
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
    skeleton: &'a Skeleton,
    /// Reference (t0) vertices, metres.
    rest: &'a [Vector3<f64>],
    weights: &'a [Influences],
    targets: &'a Targets,
    /// Indices (into `targets.pulls`) of the pulls of vertices that move with one bone,
    /// per bone.
    rigid_pulls: Vec<Vec<u32>>,
    /// Those pulls summed per bone ([`RigidMoments`]).
    rigid: Vec<RigidMoments>,
    /// Indices (into `targets.pulls`) of the blended vertices, summed one by one.
    blended: Vec<u32>,
    /// The held energy's weight of a residual's part along the surface (see
    /// [`HeldProblem::with_tangential`]); 1: eq. 4's point-to-point energy.
    tangential: f64,
    /// With `tangential` below 1, the rigid pulls' parts along their normals, per bone.
    plane: Vec<PlaneMoments>,
    /// The holds on hidden parts, added to the energy ([`HeldProblem::with_hold`]).
    hold: Option<&'a HiddenHold>,
}

impl<'a> HeldProblem<'a> {
    pub fn new(
        skeleton: &'a Skeleton,
        rest: &'a [Vector3<f64>],
        weights: &'a [Influences],
        targets: &'a Targets,
    ) -> HeldProblem<'a> {
        // Pulls of vertices with one influence, by bone; the others one by one.
        let pulls = &targets.pulls;
        let mut per_bone: Vec<Vec<u32>> = vec![Vec::new(); skeleton.bones.len()];
        let mut blended = Vec::new();
        for (i, &(v, _, _)) in pulls.iter().enumerate() {
            match weights[v as usize].as_slice() {
                [(b, w)] if *w == 1.0 => per_bone[*b].push(i as u32),
                _ => blended.push(i as u32),
            }
        }
        // Bone by bone in parallel; each bone's sums run in order (the same bits).
        let rigid = per_bone
            .par_iter()
            .enumerate()
            .filter_map(|(b, mine)| {
                let pulls = mine.iter().map(|&i| {
                    let (v, w, c) = pulls[i as usize];
                    (rest[v as usize], w, c)
                });
                RigidMoments::new(b, pulls)
            })
            .collect();
        HeldProblem {
            skeleton,
            rest,
            weights,
            targets,
            rigid_pulls: per_bone,
            rigid,
            blended,
            tangential: 1.0,
            plane: Vec::new(),
            hold: None,
        }
    }

    /// The held problem with the round's holds on hidden parts added to its energy
    /// (`fit.hidden_hold`, [`HiddenHold`]).
    pub fn with_hold(mut self, hold: &'a HiddenHold) -> HeldProblem<'a> {
        self.hold = (!hold.is_empty()).then_some(hold);
        self
    }

    /// The holds' energy at `pose` (0 without holds).
    fn hold_energy(&self, pose: &Pose) -> f64 {
        self.hold.map_or(0.0, |h| h.energy(pose))
    }

    /// The held problem whose energy weighs each pull's residual r by
    /// M = n n^T + `tangential` (I - n n^T) (n the pull's normal, held at the round's pose):
    /// the part along the surface by `tangential` in (0, 1], the part along the normal
    /// fully. Below 1 the held minimum lets the model slide along the observed surface
    /// within one round, which the point-to-point rounds do one partner change at a time
    /// (`fit.held_tangential_weight`).
    pub fn with_tangential(mut self, tangential: f64) -> HeldProblem<'a> {
        self.tangential = tangential;
        if tangential < 1.0 {
            let (pulls, normals, rest) = (&self.targets.pulls, &self.targets.normals, self.rest);
            self.plane = self
                .rigid_pulls
                .par_iter()
                .enumerate()
                .filter_map(|(b, mine)| {
                    let pulls = mine.iter().map(|&i| {
                        let (v, w, c) = pulls[i as usize];
                        (rest[v as usize], w, c, normals[i as usize])
                    });
                    PlaneMoments::new(b, pulls)
                })
                .collect();
        }
        self
    }

    /// The Gauss-Newton system of the held energy itself (see
    /// [`HeldProblem::with_tangential`]): H, g and the energy all weigh residuals by M.
    pub fn held_equations(&self, pose: &Pose) -> (DMatrix<f64>, DVector<f64>, f64) {
        if self.tangential < 1.0 {
            self.summed(pose, self.tangential, &self.blended, &self.rigid, true)
        } else {
            self.normal_equations(pose, 1.0)
        }
    }

    /// sum_v W_v |v(p) - c_v|^2 (m^2); with [`HeldProblem::with_tangential`] below 1,
    /// sum_v W_v r^T M r for r = v(p) - c_v.
    pub fn energy(&self, pose: &Pose) -> f64 {
        let bones = PosedBones::new(self.skeleton, pose);
        let t = self.tangential;
        // Fixed chunks summed in order: the same bits on every run and thread count.
        let partial: Vec<f64> = self
            .blended
            .par_chunks(CHUNK)
            .map(|chunk| {
                chunk
                    .iter()
                    .map(|&i| {
                        let (v, w, c) = self.targets.pulls[i as usize];
                        let v = v as usize;
                        let r = pose_vertex(&bones, &self.rest[v], &self.weights[v]) - c;
                        if t < 1.0 {
                            let along = self.targets.normals[i as usize].dot(&r);
                            w * (t * r.norm_squared() + (1.0 - t) * along * along)
                        } else {
                            w * r.norm_squared()
                        }
                    })
                    .sum::<f64>()
            })
            .collect();
        let rigid = self.rigid.iter().map(|m| m.energy(&bones)).sum::<f64>();
        let held = if t < 1.0 {
            let plane = self.plane.iter().map(|m| m.energy(&bones)).sum::<f64>();
            partial.iter().sum::<f64>() + t * rigid + (1.0 - t) * plane
        } else {
            partial.iter().sum::<f64>() + rigid
        };
        held + self.hold_energy(pose)
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
        if tangential < 1.0 {
            // The tangential H needs each vertex's normal: every pull one by one.
            return self.summed(pose, tangential, &self.every_pull(), &[], false);
        }
        self.summed(pose, 1.0, &self.blended, &self.rigid, false)
    }

    /// Indices of every pull.
    fn every_pull(&self) -> Vec<u32> {
        (0..self.targets.pulls.len() as u32).collect()
    }

    /// The normal equations of the pulls `each` summed vertex by vertex and of `rigid` in
    /// closed form. `weighted`: the residuals, and so g and the energy, are weighed by M
    /// too (the held energy of [`HeldProblem::with_tangential`]; `rigid` then counts
    /// `tangential` times, and [`HeldProblem::plane`] the rest); otherwise only H is.
    fn summed(
        &self,
        pose: &Pose,
        tangential: f64,
        each: &[u32],
        rigid: &[RigidMoments],
        weighted: bool,
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
        let partials: Vec<Accumulator> = each
            .par_chunks(CHUNK)
            .map(|chunk| {
                chunk.iter().fold(zero(), |mut acc, &pull| {
                    let (v, w, c) = self.targets.pulls[pull as usize];
                    let v = v as usize;
                    let y = sparse_vertex_jacobian(
                        &bones,
                        &self.rest[v],
                        &self.weights[v],
                        &mut acc.blocks,
                    );
                    let mut r = y - c;
                    if weighted {
                        // r^T M r, and M r in place of r in g.
                        let normal = self.targets.normals[pull as usize];
                        let along = normal.dot(&r);
                        let t = tangential;
                        acc.e += w * (t * r.norm_squared() + (1.0 - t) * along * along);
                        r = t * r + (1.0 - t) * along * normal;
                    } else {
                        acc.e += w * r.norm_squared();
                    }
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
                    let mut first = 0;
                    if t < 1.0 {
                        let normal = self.targets.normals[pull as usize];
                        acc.along
                            .extend(acc.cols.iter().map(|(_, col)| normal.dot(col)));
                    } else {
                        // At 1 a translation column's dot product with a column is that
                        // column's entry (the other two products are zeros, exactly), so
                        // its row is filled without them: the same sums, bit for bit.
                        for k in 0..3 {
                            acc.g[k] += w * r[k];
                            acc.h[k * n + k] += w;
                            for (pj, cj) in &acc.cols[3..] {
                                acc.h[k * n + pj] += w * cj[k];
                            }
                        }
                        first = 3;
                    }
                    for (i, (pi, ci)) in acc.cols.iter().enumerate().skip(first) {
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
        let Accumulator {
            mut h,
            mut g,
            mut e,
            ..
        } = partials.into_iter().fold(zero(), |mut a, b| {
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
        if !rigid.is_empty() {
            // The closed-form terms, both triangles.
            let share = if weighted { tangential } else { 1.0 };
            h.fill(0.0);
            for m in rigid {
                m.add_normal_equations(&bones, share, &mut h, &mut g);
                e += share * m.energy(&bones);
            }
            if weighted {
                for m in &self.plane {
                    m.add_normal_equations(&bones, 1.0 - tangential, &mut h, &mut g);
                    e += (1.0 - tangential) * m.energy(&bones);
                }
            }
            hm += DMatrix::from_row_slice(n, n, &h);
        }
        let mut g = DVector::from_vec(g);
        if let Some(hold) = self.hold {
            e += hold.add_normal_equations(pose, &mut hm, &mut g);
        }
        (hm, g, e)
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
        let (h, g, e0) = problem.held_equations(&pose);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::skeleton::skinning::skin_weights;
    use crate::skeleton::skinning::tests::{chain, signed_uniform};
    use nalgebra::Rotation3;

    /// The closed-form sums of the rigidly attached vertices give the same energy, gradient
    /// and Gauss-Newton matrix as summing every vertex one by one: for eq. 4's
    /// point-to-point held energy, and for the energy whose residuals are weighed along the
    /// surface by 0.3 and 0.05 ([`HeldProblem::with_tangential`]).
    #[test]
    fn rigid_moments_match_the_sum_over_vertices() {
        let p = |x: f64, y: f64, z: f64| Vector3::new(x, y, z);
        let skeleton = chain();
        let mut rnd = signed_uniform(777);
        let rest: Vec<Vector3<f64>> = (0..3000)
            .map(|_| p(0.7 * rnd(), 0.1 * rnd(), 1.0 + 0.4 * rnd().abs()))
            .collect();
        let weights = skin_weights(&skeleton, &rest, 0.05);
        let rigid = weights.iter().filter(|w| w.len() == 1).count();
        assert!(rigid > 1000 && rigid < rest.len(), "{rigid} rigid vertices");
        // Every other vertex pulled towards a point near it, along a normal of its own.
        let pulls: Vec<(u32, f64, Vector3<f64>)> = (0..rest.len())
            .step_by(2)
            .map(|v| {
                let c = rest[v] + p(rnd(), rnd(), rnd()) * 0.05;
                (v as u32, 0.1 + rnd().abs(), c)
            })
            .collect();
        let normals = (0..pulls.len())
            .map(|_| (p(rnd(), rnd(), rnd()) + p(0.0, 0.0, 0.3)).normalize())
            .collect();
        let targets = Targets { pulls, normals };
        for tangential in [1.0, 0.3, 0.05] {
            let problem =
                HeldProblem::new(&skeleton, &rest, &weights, &targets).with_tangential(tangential);
            for _ in 0..5 {
                let mut pose = Pose::rest(skeleton.bones.len());
                pose.translation = p(rnd(), rnd(), rnd()) * 0.1;
                for r in &mut pose.rotations {
                    *r = Rotation3::new(p(rnd(), rnd(), rnd()) * 0.4);
                }
                let (h, g, e) = problem.held_equations(&pose);
                let every = problem.every_pull();
                let (h1, g1, e1) = problem.summed(&pose, tangential, &every, &[], true);
                let close = |a: f64, b: f64, scale: f64| (a - b).abs() <= 1e-9 * scale;
                assert!(close(e, e1, e1), "{tangential}: {e} {e1}");
                assert!(close(problem.energy(&pose), e1, e1), "{tangential}");
                let hs = h1.abs().max();
                assert!(
                    h.iter().zip(h1.iter()).all(|(a, b)| close(*a, *b, hs)),
                    "{tangential}"
                );
                let gs = g1.abs().max();
                assert!(
                    g.iter().zip(g1.iter()).all(|(a, b)| close(*a, *b, gs)),
                    "{tangential}: {g} {g1}"
                );
            }
        }
    }
}
