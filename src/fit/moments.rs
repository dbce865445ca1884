//! The held energy's terms of the vertices that move with one bone only, summed in closed
//! form (method.md "Stage 6", step b).
//!
//! Skinning weights are exactly one bone's away from the joints, so most model vertices
//! move rigidly: y = G (x - h0) + h for their bone's global rotation G, rest head h0 and
//! posed head h. For such vertices the held energy sum W |y - c|^2, its gradient and its
//! Gauss-Newton matrix depend on the pose only through G and h, and on the vertices only
//! through a few weighted moments, gathered once per round. An LM step then costs O(bones)
//! for them instead of O(vertices); only the blended vertices near joints are summed one
//! by one.
//!
//! The moments are centred (x~ = x - x_mean, c~ = c - c_mean), so that the energy is a sum
//! of small terms: with z = G x~ (sum W z = 0), y_mean = G (x_mean - h0) + h and
//! rho = y_mean - c_mean,
//! `sum W |y - c|^2 = S |rho|^2 + tr(M) + sum W |c~|^2 - 2 tr(G P)`,
//! where S = sum W, M = sum W x~ x~^T and P = sum W x~ c~^T.

use crate::skeleton::PosedBones;
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

/// The total weight S of `pulls` (rest position x, weight W, target c) and their weighted
/// mean rest position and target (metres); `None` when S is zero.
fn weighted_means(
    pulls: impl Iterator<Item = (Vector3<f64>, f64, Vector3<f64>)>,
) -> Option<(f64, Vector3<f64>, Vector3<f64>)> {
    let (mut weight, mut xs, mut cs) = (0.0, Vector3::zeros(), Vector3::zeros());
    for (x, w, c) in pulls {
        weight += w;
        xs += w * x;
        cs += w * c;
    }
    (weight > 0.0).then(|| (weight, xs / weight, cs / weight))
}

/// The rotation parameters that move a point rigidly attached to `bone` at `at` (metres):
/// (parameter index, increment axis u, arm at - head_a) for each axis of every bone a on the
/// chain, in the order of [`PosedBones::add_point_jacobian`].
fn rotation_columns(
    bones: &PosedBones,
    bone: usize,
    at: Vector3<f64>,
) -> impl Iterator<Item = (usize, Vector3<f64>, Vector3<f64>)> + '_ {
    bones.chains[bone].iter().flat_map(move |&b| {
        let arm = at - bones.heads[b];
        let axes = bones.increment_axes[b];
        (0..3).map(move |k| (3 + 3 * b + k, axes.column(k).into_owned(), arm))
    })
}

/// The centred moments of one bone's rigidly attached pulls (see the module's text).
#[derive(Debug, Clone)]
pub struct RigidMoments {
    pub bone: usize,
    /// S = sum W.
    weight: f64,
    /// Weighted mean rest position x_mean, metres.
    rest_mean: Vector3<f64>,
    /// Weighted mean target c_mean, metres.
    target_mean: Vector3<f64>,
    /// M = sum W x~ x~^T, m^2.
    rest_spread: Matrix3<f64>,
    /// P = sum W x~ c~^T, m^2.
    rest_target: Matrix3<f64>,
    /// sum W |c~|^2, m^2.
    target_spread: f64,
}

impl RigidMoments {
    /// The moments of `pulls` (rest position x, total weight W, target c), all attached to
    /// `bone`; `None` when their weight is zero.
    pub fn new(
        bone: usize,
        pulls: impl Iterator<Item = (Vector3<f64>, f64, Vector3<f64>)> + Clone,
    ) -> Option<RigidMoments> {
        let (weight, rest_mean, target_mean) = weighted_means(pulls.clone())?;
        let (mut rest_spread, mut rest_target, mut target_spread) =
            (Matrix3::zeros(), Matrix3::zeros(), 0.0);
        for (x, w, c) in pulls {
            let (dx, dc) = (x - rest_mean, c - target_mean);
            rest_spread += w * dx * dx.transpose();
            rest_target += w * dx * dc.transpose();
            target_spread += w * dc.norm_squared();
        }
        Some(RigidMoments {
            bone,
            weight,
            rest_mean,
            target_mean,
            rest_spread,
            rest_target,
            target_spread,
        })
    }

    /// The posed mean y_mean and rho = y_mean - c_mean.
    fn posed_mean(&self, bones: &PosedBones) -> (Vector3<f64>, Vector3<f64>) {
        let mean = bones.transform(self.bone, &self.rest_mean);
        (mean, mean - self.target_mean)
    }

    /// sum W |y - c|^2 over the pulls, m^2.
    pub fn energy(&self, bones: &PosedBones) -> f64 {
        let g = bones.rotations[self.bone].matrix();
        let (_, rho) = self.posed_mean(bones);
        let spread =
            self.rest_spread.trace() + self.target_spread - 2.0 * (g * self.rest_target).trace();
        self.weight * rho.norm_squared() + spread.max(0.0)
    }

    /// Adds `scale` times the pulls' point-to-point Gauss-Newton terms to `h` (n x n,
    /// row-major, both triangles) and `g` (n), with the parameters of
    /// [`PosedBones::add_point_jacobian`]: the translation's identity, and `u x (y - head_a)`
    /// for each increment axis u of every bone a on the chain. With p_a = y - head_a =
    /// d_a + z (d_a = y_mean - head_a):
    /// sum W (u x p_a).(v x p_b) = (u.v) tr(Q) - v^T Q u for Q = S d_a d_b^T + G M G^T, and
    /// sum W p_a x (y - c) = S d_a x rho - sum W z x c~.
    pub fn add_normal_equations(
        &self,
        bones: &PosedBones,
        scale: f64,
        h: &mut [f64],
        g: &mut [f64],
    ) {
        let n = g.len();
        let s = self.weight;
        let rotation = bones.rotations[self.bone].matrix();
        let (mean, rho) = self.posed_mean(bones);
        let z_spread = rotation * self.rest_spread * rotation.transpose();
        // sum W z c~^T and its axial vector sum W z x c~.
        let a = rotation * self.rest_target;
        let z_cross_c = Vector3::new(
            a[(1, 2)] - a[(2, 1)],
            a[(2, 0)] - a[(0, 2)],
            a[(0, 1)] - a[(1, 0)],
        );
        // Columns: (parameter, axis u, arm d) per rotation parameter on the chain.
        let columns: Vec<(usize, Vector3<f64>, Vector3<f64>)> =
            rotation_columns(bones, self.bone, mean).collect();
        for k in 0..3 {
            h[k * n + k] += scale * s;
            g[k] += scale * s * rho[k];
        }
        for (i, &(pi, u, d)) in columns.iter().enumerate() {
            let t = s * u.cross(&d);
            for k in 0..3 {
                h[k * n + pi] += scale * t[k];
                h[pi * n + k] += scale * t[k];
            }
            g[pi] += scale * u.dot(&(s * d.cross(&rho) - z_cross_c));
            for &(pj, v, e) in &columns[i..] {
                let q = s * d * e.transpose() + z_spread;
                let x = u.dot(&v) * q.trace() - v.dot(&(q * u));
                h[pi * n + pj] += scale * x;
                if pj != pi {
                    h[pj * n + pi] += scale * x;
                }
            }
        }
    }
}

/// The held energy's part along the pulls' normals, sum W (n . (y - c))^2, of one bone's
/// rigidly attached planes (each pair with its plane's normal), in closed form (for
/// `proposed`'s point-to-plane rounds).
///
/// With z = G x~ and rho = y_mean - c_mean as in [`RigidMoments`], each pull's residual is
/// linear in theta = (G row by row, rho): n . (y - c) = f . theta - gamma, with
/// f = (n x~^T row by row, n) and gamma = n . c~. So the energy is
/// `theta^T A theta - 2 b . theta + C` (A = sum W f f^T, b = sum W gamma f,
/// C = sum W gamma^2), and its Gauss-Newton terms are J^T A J and J^T (A theta - b) for the
/// derivative J of theta by the pose increments: d G = [u]x G and d rho = u x (y_mean -
/// head_a) for an increment axis u of a bone a on the chain, d rho = I for the translation.
#[derive(Debug, Clone)]
pub struct PlaneMoments {
    pub bone: usize,
    /// Weighted mean rest position x_mean and target c_mean, metres.
    rest_mean: Vector3<f64>,
    target_mean: Vector3<f64>,
    /// A, m^2 in its rotation block.
    a: SMatrix<f64, 12, 12>,
    b: SVector<f64, 12>,
    /// C, m^2.
    c: f64,
}

impl PlaneMoments {
    /// The moments of `pulls` (rest position x, total weight W, target c, unit normal n),
    /// all attached to `bone`; `None` when their weight is zero.
    pub fn new(
        bone: usize,
        pulls: impl Iterator<Item = (Vector3<f64>, f64, Vector3<f64>, Vector3<f64>)> + Clone,
    ) -> Option<PlaneMoments> {
        let (_, rest_mean, target_mean) =
            weighted_means(pulls.clone().map(|(x, w, c, _)| (x, w, c)))?;
        let (mut a, mut b, mut c_sum) = (SMatrix::zeros(), SVector::zeros(), 0.0);
        for (x, w, c, n) in pulls {
            let dx = x - rest_mean;
            let gamma = n.dot(&(c - target_mean));
            let f = SVector::<f64, 12>::from_fn(|i, _| {
                if i < 9 {
                    n[i / 3] * dx[i % 3]
                } else {
                    n[i - 9]
                }
            });
            a += w * f * f.transpose();
            b += (w * gamma) * f;
            c_sum += w * gamma * gamma;
        }
        Some(PlaneMoments {
            bone,
            rest_mean,
            target_mean,
            a,
            b,
            c: c_sum,
        })
    }

    /// theta at `bones`.
    fn theta(&self, bones: &PosedBones) -> SVector<f64, 12> {
        let g = bones.rotations[self.bone].matrix();
        let rho = bones.transform(self.bone, &self.rest_mean) - self.target_mean;
        SVector::from_fn(|i, _| if i < 9 { g[(i / 3, i % 3)] } else { rho[i - 9] })
    }

    /// sum W (n . (y - c))^2 over the pulls, m^2.
    pub fn energy(&self, bones: &PosedBones) -> f64 {
        let theta = self.theta(bones);
        ((self.a * theta).dot(&theta) - 2.0 * self.b.dot(&theta) + self.c).max(0.0)
    }

    /// Adds `scale` times the pulls' Gauss-Newton terms along the normals to `h` (n x n,
    /// row-major, both triangles) and `g` (n), with the parameters of
    /// [`RigidMoments::add_normal_equations`].
    pub fn add_normal_equations(
        &self,
        bones: &PosedBones,
        scale: f64,
        h: &mut [f64],
        g: &mut [f64],
    ) {
        let n = g.len();
        let rotation = bones.rotations[self.bone].matrix();
        let mean = bones.transform(self.bone, &self.rest_mean);
        let mut columns: Vec<(usize, SVector<f64, 12>)> = (0..3)
            .map(|k| {
                (
                    k,
                    SVector::from_fn(|i, _| if i == 9 + k { 1.0 } else { 0.0 }),
                )
            })
            .collect();
        for (parameter, u, arm) in rotation_columns(bones, self.bone, mean) {
            let turned = u.cross_matrix() * rotation;
            let moved = u.cross(&arm);
            let column = SVector::from_fn(|i, _| {
                if i < 9 {
                    turned[(i / 3, i % 3)]
                } else {
                    moved[i - 9]
                }
            });
            columns.push((parameter, column));
        }
        let theta = self.theta(bones);
        let residual = self.a * theta - self.b;
        for &(pi, ci) in &columns {
            g[pi] += scale * ci.dot(&residual);
            let a_ci = self.a * ci;
            for &(pj, cj) in &columns {
                h[pi * n + pj] += scale * cj.dot(&a_ci);
            }
        }
    }
}
