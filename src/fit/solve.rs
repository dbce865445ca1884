//! Levenberg-Marquardt on the pose increments with the correspondences held (method.md
//! "Stage 6", step b).
//!
//! With correspondences and weights fixed, paper eq. 4 is a sum over model vertices of
//! `W_v |v(p) - c_v|^2` plus a constant: every pair that involves model vertex v (its own
//! nearest observed vertex, and every observed vertex whose nearest model vertex is v)
//! pulls v towards a point, and a weighted sum of squared distances to points is the total
//! weight W_v times the squared distance to their weighted mean c_v. So each model vertex
//! contributes one 3-row residual, with the analytic Jacobian of linear blend skinning.

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
    /// Every weighted pair as a plane (for the point-to-plane energy,
    /// [`HeldProblem::with_planes`]); empty when only the point-to-point energy is used.
    pub planes: Vec<Plane>,
}

/// One pair seen from its model vertex: the vertex is pulled towards the plane through
/// `point` with unit normal `normal`, with `weight` (the pair's weight in eq. 4).
#[derive(Debug, Clone, Copy)]
pub struct Plane {
    pub vertex: u32,
    pub weight: f64,
    /// Metres.
    pub point: Vector3<f64>,
    pub normal: Vector3<f64>,
}

/// The held problem: model, targets.
pub struct HeldProblem<'a> {
    skeleton: &'a Skeleton,
    /// Reference (t0) vertices, metres.
    rest: &'a [Vector3<f64>],
    weights: &'a [Influences],
    targets: &'a Targets,
    /// The pulls of vertices that move with one bone, summed per bone ([`RigidMoments`]).
    rigid: Vec<RigidMoments>,
    /// Indices (into `targets.pulls`) of the blended vertices, summed one by one.
    blended: Vec<u32>,
    /// The held energy's share of the point-to-point terms (see
    /// [`HeldProblem::with_planes`]); 1: eq. 4's point-to-point energy.
    tangential: f64,
    /// With `tangential` below 1, the planes of rigidly attached vertices, per bone.
    plane_rigid: Vec<PlaneMoments>,
    /// With `tangential` below 1, indices (into `targets.planes`) of the blended vertices'
    /// planes, summed one by one.
    plane_blended: Vec<u32>,
}

/// Whether a vertex with these influences moves with one bone only (and which).
fn rigid_bone(influences: &Influences) -> Option<usize> {
    match influences.as_slice() {
        [(b, w)] if *w == 1.0 => Some(*b),
        _ => None,
    }
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
            match rigid_bone(&weights[v as usize]) {
                Some(b) => per_bone[b].push(i as u32),
                None => blended.push(i as u32),
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
            rigid,
            blended,
            tangential: 1.0,
            plane_rigid: Vec::new(),
            plane_blended: Vec::new(),
        }
    }

    /// The held problem whose energy is `tangential` times the point-to-point energy plus
    /// `1 - tangential` times the point-to-plane energy of `targets.planes`,
    /// sum w (n . (y - point))^2: each pair measured along its plane's normal, so that the
    /// model slides along the other surface within one step (point-to-plane ICP), where
    /// point-to-point rounds slide one partner change at a time.
    pub fn with_planes(mut self, tangential: f64) -> HeldProblem<'a> {
        self.tangential = tangential;
        if tangential < 1.0 {
            let planes = &self.targets.planes;
            let mut per_bone: Vec<Vec<u32>> = vec![Vec::new(); self.skeleton.bones.len()];
            self.plane_blended.clear();
            for (i, plane) in planes.iter().enumerate() {
                match rigid_bone(&self.weights[plane.vertex as usize]) {
                    Some(b) => per_bone[b].push(i as u32),
                    None => self.plane_blended.push(i as u32),
                }
            }
            let rest = self.rest;
            self.plane_rigid = per_bone
                .par_iter()
                .enumerate()
                .filter_map(|(b, mine)| {
                    let planes = mine.iter().map(|&i| {
                        let q = planes[i as usize];
                        (rest[q.vertex as usize], q.weight, q.point, q.normal)
                    });
                    PlaneMoments::new(b, planes)
                })
                .collect();
        }
        self
    }

    /// sum_v W_v |v(p) - c_v|^2 (m^2), blended with the point-to-plane energy as
    /// [`HeldProblem::with_planes`] says.
    pub fn energy(&self, pose: &Pose) -> f64 {
        let bones = PosedBones::new(self.skeleton, pose);
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
                        w * r.norm_squared()
                    })
                    .sum::<f64>()
            })
            .collect();
        let rigid = self.rigid.iter().map(|m| m.energy(&bones)).sum::<f64>();
        let mut held = partial.iter().sum::<f64>() + rigid;
        let t = self.tangential;
        if t < 1.0 {
            held = t * held + (1.0 - t) * self.plane_energy(&bones);
        }
        held
    }

    /// sum w (n . (y - point))^2 over the planes, m^2.
    fn plane_energy(&self, bones: &PosedBones) -> f64 {
        // Fixed chunks summed in order, as in `energy`.
        let partial: Vec<f64> = self
            .plane_blended
            .par_chunks(CHUNK)
            .map(|chunk| {
                chunk
                    .iter()
                    .map(|&i| {
                        let q = self.targets.planes[i as usize];
                        let v = q.vertex as usize;
                        let y = pose_vertex(bones, &self.rest[v], &self.weights[v]);
                        q.weight * q.normal.dot(&(y - q.point)).powi(2)
                    })
                    .sum::<f64>()
            })
            .collect();
        partial.iter().sum::<f64>()
            + self
                .plane_rigid
                .iter()
                .map(|m| m.energy(bones))
                .sum::<f64>()
    }

    /// The Gauss-Newton system of the held energy at `pose`: H, g and the energy.
    pub fn held_equations(&self, pose: &Pose) -> (DMatrix<f64>, DVector<f64>, f64) {
        let bones = PosedBones::new(self.skeleton, pose);
        let (mut h, mut g, mut e) = self.point_equations(&bones, pose.parameter_count());
        let t = self.tangential;
        if t < 1.0 {
            h *= t;
            g *= t;
            e *= t;
            let n = g.len();
            let (mut hp, mut gp) = (vec![0.0; n * n], vec![0.0; n]);
            let ep = self.add_plane_equations(&bones, &mut hp, &mut gp);
            h += (1.0 - t) * DMatrix::from_row_slice(n, n, &hp);
            g += (1.0 - t) * DVector::from_vec(gp);
            e += (1.0 - t) * ep;
        }
        (h, g, e)
    }

    /// Adds the planes' Gauss-Newton terms to `h` (n x n, row-major, both triangles) and
    /// `g`; returns their energy.
    fn add_plane_equations(&self, bones: &PosedBones, h: &mut [f64], g: &mut [f64]) -> f64 {
        let n = g.len();
        let zero = || Accumulator::new(n);
        // Per fixed chunk, then summed in order (deterministic, see `energy`); each pair
        // of columns once, as in `point_equations`.
        let partials: Vec<Accumulator> = self
            .plane_blended
            .par_chunks(CHUNK)
            .map(|chunk| {
                chunk.iter().fold(zero(), |mut acc, &i| {
                    let q = self.targets.planes[i as usize];
                    let v = q.vertex as usize;
                    let y = sparse_vertex_jacobian(
                        bones,
                        &self.rest[v],
                        &self.weights[v],
                        &mut acc.blocks,
                    );
                    let r = q.normal.dot(&(y - q.point));
                    acc.e += q.weight * r * r;
                    // The residual's derivative along each column: n . column.
                    acc.scalar_cols.clear();
                    acc.scalar_cols.extend((0..3).map(|k| (k, q.normal[k])));
                    for (b, c3) in &acc.blocks {
                        for (k, col) in c3.iter().enumerate() {
                            acc.scalar_cols.push((3 + 3 * b + k, q.normal.dot(col)));
                        }
                    }
                    for (a, &(pi, ai)) in acc.scalar_cols.iter().enumerate() {
                        acc.g[pi] += q.weight * ai * r;
                        let wa = q.weight * ai;
                        for &(pj, aj) in &acc.scalar_cols[a..] {
                            acc.h[pi * n + pj] += wa * aj;
                        }
                    }
                    acc
                })
            })
            .collect();
        let mut total = partials.into_iter().fold(zero(), Accumulator::add);
        let mut e = total.e;
        g.iter_mut().zip(&total.g).for_each(|(x, y)| *x += y);
        fold_triangles(&mut total.h, n);
        h.iter_mut().zip(&total.h).for_each(|(x, y)| *x += y);
        for m in &self.plane_rigid {
            m.add_normal_equations(bones, 1.0, h, g);
            e += m.energy(bones);
        }
        e
    }

    /// The point-to-point Gauss-Newton system at `bones`: H = sum W J^T J, g = sum W J^T r,
    /// and the energy; blended vertices summed one by one, the rigid ones in closed form.
    fn point_equations(&self, bones: &PosedBones, n: usize) -> (DMatrix<f64>, DVector<f64>, f64) {
        let zero = || Accumulator::new(n);
        // Per fixed chunk, then summed in order (deterministic, see `energy`).
        let partials: Vec<Accumulator> = self
            .blended
            .par_chunks(CHUNK)
            .map(|chunk| {
                chunk.iter().fold(zero(), |mut acc, &pull| {
                    let (v, w, c) = self.targets.pulls[pull as usize];
                    let v = v as usize;
                    let y = sparse_vertex_jacobian(
                        bones,
                        &self.rest[v],
                        &self.weights[v],
                        &mut acc.blocks,
                    );
                    let r = y - c;
                    acc.e += w * r.norm_squared();
                    acc.cols.clear();
                    for (b, c3) in &acc.blocks {
                        for (k, col) in c3.iter().enumerate() {
                            acc.cols.push((3 + 3 * b + k, *col));
                        }
                    }
                    // A translation column's dot product with a column is that column's
                    // entry (the other two products are zeros, exactly), so its row is
                    // filled without them.
                    for k in 0..3 {
                        acc.g[k] += w * r[k];
                        acc.h[k * n + k] += w;
                        for (pj, cj) in &acc.cols {
                            acc.h[k * n + pj] += w * cj[k];
                        }
                    }
                    for (i, (pi, ci)) in acc.cols.iter().enumerate() {
                        acc.g[*pi] += w * ci.dot(&r);
                        for (pj, cj) in &acc.cols[i..] {
                            acc.h[pi * n + pj] += w * ci.dot(cj);
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
        } = partials.into_iter().fold(zero(), Accumulator::add);
        fold_triangles(&mut h, n);
        let mut hm = DMatrix::from_row_slice(n, n, &h);
        // The closed-form terms, both triangles.
        h.fill(0.0);
        for m in &self.rigid {
            m.add_normal_equations(bones, 1.0, &mut h, &mut g);
            e += m.energy(bones);
        }
        hm += DMatrix::from_row_slice(n, n, &h);
        (hm, DVector::from_vec(g), e)
    }
}

/// Makes `h` (n x n, row-major) symmetric where only one triangle of each pair (i, j) was
/// summed, in whichever order the columns came: both entries become their sum.
fn fold_triangles(h: &mut [f64], n: usize) {
    for i in 0..n {
        for j in (i + 1)..n {
            let s = h[i * n + j] + h[j * n + i];
            h[i * n + j] = s;
            h[j * n + i] = s;
        }
    }
}

/// One chunk's share of the normal equations, with scratch space reused vertex to vertex.
struct Accumulator {
    /// H, row-major, one triangle summed (see `point_equations`).
    h: Vec<f64>,
    g: Vec<f64>,
    e: f64,
    blocks: Vec<(usize, [Vector3<f64>; 3])>,
    /// A pull's Jacobian columns (3-vectors), by parameter.
    cols: Vec<(usize, Vector3<f64>)>,
    /// A plane's Jacobian row (scalars), by parameter.
    scalar_cols: Vec<(usize, f64)>,
}

impl Accumulator {
    fn new(n: usize) -> Accumulator {
        Accumulator {
            h: vec![0.0; n * n],
            g: vec![0.0; n],
            e: 0.0,
            blocks: Vec::new(),
            cols: Vec::new(),
            scalar_cols: Vec::new(),
        }
    }

    /// `self` plus `other`'s sums (in this order: the same bits on every run).
    fn add(mut self, other: Accumulator) -> Accumulator {
        self.h.iter_mut().zip(&other.h).for_each(|(x, y)| *x += y);
        self.g.iter_mut().zip(&other.g).for_each(|(x, y)| *x += y);
        self.e += other.e;
        self
    }
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

    /// The held energy, its gradient and its Gauss-Newton matrix (rigid vertices in closed
    /// form, blended ones one by one) equal a plain sum over every pull and plane with the
    /// full Jacobian: for eq. 4's point-to-point held energy (1) and for point-to-plane
    /// blends (0.3, 0.05).
    #[test]
    fn held_equations_match_the_sum_over_pairs() {
        let p = |x: f64, y: f64, z: f64| Vector3::new(x, y, z);
        let skeleton = chain();
        let mut rnd = signed_uniform(777);
        let rest: Vec<Vector3<f64>> = (0..3000)
            .map(|_| p(0.7 * rnd(), 0.1 * rnd(), 1.0 + 0.4 * rnd().abs()))
            .collect();
        let weights = skin_weights(&skeleton, &rest, 0.05);
        let rigid = weights.iter().filter(|w| w.len() == 1).count();
        assert!(rigid > 1000 && rigid < rest.len(), "{rigid} rigid vertices");
        // Every other vertex pulled towards a point near it; two planes per pulled vertex.
        let pulls: Vec<(u32, f64, Vector3<f64>)> = (0..rest.len())
            .step_by(2)
            .map(|v| {
                let c = rest[v] + p(rnd(), rnd(), rnd()) * 0.05;
                (v as u32, 0.1 + rnd().abs(), c)
            })
            .collect();
        let planes: Vec<Plane> = pulls
            .iter()
            .flat_map(|&(v, w, c)| [(v, w, c), (v, 0.5 * w, c + p(0.0, 0.01, 0.0))])
            .map(|(vertex, weight, point)| Plane {
                vertex,
                weight,
                point,
                normal: (p(rnd(), rnd(), rnd()) + p(0.0, 0.0, 0.3)).normalize(),
            })
            .collect();
        let targets = Targets { pulls, planes };
        let n = 3 + 3 * skeleton.bones.len();
        for tangential in [1.0, 0.3, 0.05] {
            let problem =
                HeldProblem::new(&skeleton, &rest, &weights, &targets).with_planes(tangential);
            for _ in 0..5 {
                let mut pose = Pose::rest(skeleton.bones.len());
                pose.translation = p(rnd(), rnd(), rnd()) * 0.1;
                for r in &mut pose.rotations {
                    *r = Rotation3::new(p(rnd(), rnd(), rnd()) * 0.4);
                }
                let bones = PosedBones::new(&skeleton, &pose);
                // The reference: every residual row with its full Jacobian row.
                let (mut h1, mut g1, mut e1) = (DMatrix::zeros(n, n), DVector::zeros(n), 0.0);
                let mut add = |w: f64, y: Vector3<f64>, v: usize, dir: Vector3<f64>, c| {
                    let mut cols = vec![Vector3::zeros(); n];
                    crate::skeleton::skinning::vertex_jacobian(
                        &bones,
                        &rest[v],
                        &weights[v],
                        &mut cols,
                    );
                    let r = dir.dot(&(y - c));
                    let row = DVector::from_iterator(n, cols.iter().map(|col| dir.dot(col)));
                    h1 += w * &row * row.transpose();
                    g1 += w * r * row;
                    e1 += w * r * r;
                };
                for &(v, w, c) in &targets.pulls {
                    let y = pose_vertex(&bones, &rest[v as usize], &weights[v as usize]);
                    for k in 0..3 {
                        add(tangential * w, y, v as usize, Vector3::ith(k, 1.0), c);
                    }
                }
                if tangential < 1.0 {
                    for q in &targets.planes {
                        let v = q.vertex as usize;
                        let y = pose_vertex(&bones, &rest[v], &weights[v]);
                        add((1.0 - tangential) * q.weight, y, v, q.normal, q.point);
                    }
                }
                let (h, g, e) = problem.held_equations(&pose);
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
