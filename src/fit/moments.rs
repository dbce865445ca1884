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
use nalgebra::{Matrix3, Vector3};

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
        let (mut weight, mut xs, mut cs) = (0.0, Vector3::zeros(), Vector3::zeros());
        for (x, w, c) in pulls.clone() {
            weight += w;
            xs += w * x;
            cs += w * c;
        }
        if weight <= 0.0 {
            return None;
        }
        let (rest_mean, target_mean) = (xs / weight, cs / weight);
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

    /// Adds the pulls' point-to-point Gauss-Newton terms to `h` (n x n, row-major, both
    /// triangles) and `g` (n), with the parameters of [`PosedBones::add_point_jacobian`]:
    /// the translation's identity, and `u x (y - head_a)` for each increment axis u of every
    /// bone a on the chain. With p_a = y - head_a = d_a + z (d_a = y_mean - head_a):
    /// sum W (u x p_a).(v x p_b) = (u.v) tr(Q) - v^T Q u for Q = S d_a d_b^T + G M G^T, and
    /// sum W p_a x (y - c) = S d_a x rho - sum W z x c~.
    pub fn add_normal_equations(&self, bones: &PosedBones, h: &mut [f64], g: &mut [f64]) {
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
        let chain = &bones.chains[self.bone];
        let columns: Vec<(usize, Vector3<f64>, Vector3<f64>)> = chain
            .iter()
            .flat_map(|&b| {
                let d = mean - bones.heads[b];
                let axes = bones.increment_axes[b];
                (0..3).map(move |k| (3 + 3 * b + k, axes.column(k).into_owned(), d))
            })
            .collect();
        for k in 0..3 {
            h[k * n + k] += s;
            g[k] += s * rho[k];
        }
        for (i, &(pi, u, d)) in columns.iter().enumerate() {
            let t = s * u.cross(&d);
            for k in 0..3 {
                h[k * n + pi] += t[k];
                h[pi * n + k] += t[k];
            }
            g[pi] += u.dot(&(s * d.cross(&rho) - z_cross_c));
            for &(pj, v, e) in &columns[i..] {
                let q = s * d * e.transpose() + z_spread;
                let x = u.dot(&v) * q.trace() - v.dot(&(q * u));
                h[pi * n + pj] += x;
                if pj != pi {
                    h[pj * n + pi] += x;
                }
            }
        }
    }
}
