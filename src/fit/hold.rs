//! The hold on hidden parts (`fit.hidden_hold`, README "Robust articulated fitting").
//!
//! rho_c (method.md "Stage 6") silences every pair of a vertex in contact. A part that lies
//! wholly within tau_c of the body it touches, such as a hand resting on a thigh, then has
//! no pair left that holds its turn about its joint, and the rounds may turn it anywhere.
//! The hold gives the share of each vertex that rho_c hides, 1 - rho_c(v), a weak pull
//! towards where the anchor pose (the previous frame's) puts it relative to its parent:
//! per non-root bone b, the energy `phi_b^T A_b phi_b`, where
//! - `phi_b = log(L_b L_anchor,b^-1)` is the rotation vector from the anchor's local rotation
//!   to the current one, in the coordinates of b's pose increments (its parent's frame);
//! - `A_b = s f_b^k sum_v (1 - rho_c(v)) w_vb Ax^T [a_v]x^T [a_v]x Ax`, where the sum is
//!   the bone's inertia about its head over its hidden vertices (`a_v` the vertex's arm
//!   from the head, Ax the increment axes, both at the round's pose), so that
//!   `delta^T A_b delta` is s times the hidden vertices' squared displacement under a small
//!   turn delta;
//! - `f_b` is the bone's hidden share of its whole inertia's trace and k =
//!   [`HIDDEN_SHARE_POWER`]: a bone partly hidden is held by its observed part, and only a
//!   bone hidden nearly whole is held much;
//! - `s` is `fit.hidden_hold` times the weight a fully observed vertex's pairs carry
//!   (eq. 4's weights without rho_c, summed over the round's pairs, per model vertex).
//!
//! The anchor is the previous frame's pose, not the predicted start: the prediction runs
//! past a pose where the motion stops (the humanoid's t12-t13), and the hold then pulls the
//! hidden part past it too. A hold keeps a wrong turn as firmly as a right one: a part that
//! was folded into the body in the previous frame is hidden by its own fold and held there.
//!
//! A bone whose vertices are all observed (rho_c 1) has no hold, so the methods without
//! rho_c (`icp`, `normals`, `rho_p`) are unchanged by it.

use crate::skeleton::skinning::Influences;
use crate::skeleton::{Pose, PosedBones, Skeleton};
use nalgebra::{DMatrix, DVector, Matrix3, Rotation3, Vector3};

/// Vertices whose hidden share 1 - rho_c is below this add nothing to a hold (they would
/// add less than a thousandth of a hidden vertex's).
const LEAST_HIDDEN: f64 = 1e-3;

/// The power k of a bone's hidden share f_b in its hold (module docs). Under the
/// `rest_distance` rule the far side of every bent joint counts as contact, so a hold on
/// every hidden vertex (k = 0) held the tripod's bent limbs back (1.74 cm off at t8 with
/// `hidden_hold` 0.1, against 0.71 without); with k = 4 a bone a fifth hidden is held at
/// 1/625 of the strength and only a bone hidden nearly whole is held much (BENCHMARKS.md,
/// 2026-11-26, night).
const HIDDEN_SHARE_POWER: f64 = 4.0;

/// The holds of one round: per held bone its stiffness, and the anchor they hold to.
#[derive(Debug, Clone, Default)]
pub struct HiddenHold {
    /// (bone, A_b): the stiffness in b's increment coordinates (unnormalized eq. 4 units,
    /// m^2 per radian^2).
    stiffness: Vec<(usize, Matrix3<f64>)>,
    /// The anchor's local rotation of every bone.
    anchor: Vec<Rotation3<f64>>,
}

impl HiddenHold {
    /// The holds at the round's pose `bones`, with the posed vertices `posed`, their
    /// influences and rho_c; `scale` is `s` of the module docs. Empty when `scale` is 0.
    pub fn new(
        skeleton: &Skeleton,
        bones: &PosedBones,
        posed: &[Vector3<f64>],
        weights: &[Influences],
        rho_c: &[f64],
        scale: f64,
        anchor: &Pose,
    ) -> HiddenHold {
        if scale <= 0.0 || !scale.is_finite() {
            return HiddenHold::default();
        }
        let n = skeleton.bones.len();
        let mut inertia = vec![Matrix3::zeros(); n];
        // Per bone, sum w |a|^2 over its vertices, and the same weighed by 1 - rho_c: the
        // traces of its inertia, whole and hidden, up to a factor 2.
        let (mut whole, mut hidden_part) = (vec![0.0; n], vec![0.0; n]);
        let mut any = vec![false; n];
        for ((y, influences), &rho) in posed.iter().zip(weights).zip(rho_c) {
            let hidden = 1.0 - rho;
            for &(b, w) in influences {
                let a = y - bones.heads[b];
                let a2 = a.norm_squared();
                whole[b] += w * a2;
                hidden_part[b] += hidden * w * a2;
                if hidden < LEAST_HIDDEN || skeleton.bones[b].parent.is_none() {
                    continue;
                }
                // [a]x^T [a]x = |a|^2 I - a a^T.
                inertia[b] += hidden * w * (Matrix3::identity() * a2 - a * a.transpose());
                any[b] = true;
            }
        }
        let stiffness = (0..n)
            .filter(|&b| any[b])
            .map(|b| {
                let axes = &bones.increment_axes[b];
                let share = (hidden_part[b] / whole[b].max(1e-300)).powf(HIDDEN_SHARE_POWER);
                (b, share * scale * axes.transpose() * inertia[b] * axes)
            })
            .collect();
        HiddenHold {
            stiffness,
            anchor: anchor.rotations.clone(),
        }
    }

    /// Whether no bone is held.
    pub fn is_empty(&self) -> bool {
        self.stiffness.is_empty()
    }

    /// phi_b at `pose` (radians, b's increment coordinates).
    fn turn(&self, pose: &Pose, b: usize) -> Vector3<f64> {
        (pose.rotations[b] * self.anchor[b].inverse()).scaled_axis()
    }

    /// The holds' energy at `pose` (unnormalized eq. 4 units, m^2).
    pub fn energy(&self, pose: &Pose) -> f64 {
        self.stiffness
            .iter()
            .map(|(b, a)| {
                let phi = self.turn(pose, *b);
                phi.dot(&(a * phi))
            })
            .sum()
    }

    /// Adds the holds' Gauss-Newton terms at `pose` to H and g (the convention of
    /// [`super::solve`]: energy `sum r^T A r`, g = J^T A r, H = J^T A J) and returns their
    /// energy. J is the derivative of phi_b with respect to b's increment, the inverse of
    /// the left Jacobian of SO(3) at phi_b.
    pub fn add_normal_equations(
        &self,
        pose: &Pose,
        h: &mut DMatrix<f64>,
        g: &mut DVector<f64>,
    ) -> f64 {
        let mut energy = 0.0;
        for (b, a) in &self.stiffness {
            let phi = self.turn(pose, *b);
            let j = inverse_left_jacobian(&phi);
            let ap = a * phi;
            energy += phi.dot(&ap);
            let (gb, hb) = (j.transpose() * ap, j.transpose() * a * j);
            let at = 3 + 3 * b;
            for r in 0..3 {
                g[at + r] += gb[r];
                for c in 0..3 {
                    h[(at + r, at + c)] += hb[(r, c)];
                }
            }
        }
        energy
    }
}

/// d log(exp(delta) exp(phi)) / d delta at delta = 0: the inverse of SO(3)'s left
/// Jacobian, `I - Phi/2 + (1/t^2 - (1 + cos t) / (2 t sin t)) Phi^2` with `Phi = [phi]x`
/// and `t = |phi|` (its series `1/12` below a microradian).
fn inverse_left_jacobian(phi: &Vector3<f64>) -> Matrix3<f64> {
    let t = phi.norm();
    let cross = phi.cross_matrix();
    let c = if t < 1e-6 {
        1.0 / 12.0
    } else {
        1.0 / (t * t) - (1.0 + t.cos()) / (2.0 * t * t.sin())
    };
    Matrix3::identity() - 0.5 * cross + c * cross * cross
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::skeleton::skinning::tests::{chain, signed_uniform};
    use crate::skeleton::skinning::{pose_vertex, skin_weights};

    /// The holds' gradient is the derivative of their energy along the pose increments
    /// (central differences), at turns of up to about a radian from the anchor; a bone
    /// whose vertices are all observed is not held.
    #[test]
    fn hold_gradient_matches_its_energy() {
        let skeleton = chain();
        let n = skeleton.bones.len();
        let mut rnd = signed_uniform(31);
        let p = |x: f64, y: f64, z: f64| Vector3::new(x, y, z);
        let rest: Vec<Vector3<f64>> = (0..600)
            .map(|_| p(0.7 * rnd(), 0.1 * rnd(), 1.0 + 0.4 * rnd().abs()))
            .collect();
        let weights = skin_weights(&skeleton, &rest, 0.05);
        // Every vertex of bone "b" (the end of the chain root-a-b) hidden, the rest observed.
        let last = 2;
        let rho_c: Vec<f64> = weights
            .iter()
            .map(|w| {
                if w.iter().any(|x| x.0 == last) {
                    0.2
                } else {
                    1.0
                }
            })
            .collect();
        let mut anchor = Pose::rest(n);
        let mut pose = Pose::rest(n);
        for b in 0..n {
            anchor.rotations[b] = Rotation3::new(p(rnd(), rnd(), rnd()) * 0.5);
            pose.rotations[b] = Rotation3::new(p(rnd(), rnd(), rnd()) * 0.5);
        }
        let bones = PosedBones::new(&skeleton, &pose);
        let posed: Vec<Vector3<f64>> = rest
            .iter()
            .zip(&weights)
            .map(|(x, w)| pose_vertex(&bones, x, w))
            .collect();
        let hold = HiddenHold::new(&skeleton, &bones, &posed, &weights, &rho_c, 2.0, &anchor);
        // Held: exactly the non-root bones that move a hidden vertex.
        let mut expected: Vec<usize> = (1..n)
            .filter(|&b| {
                (0..rest.len()).any(|v| rho_c[v] < 1.0 && weights[v].iter().any(|x| x.0 == b))
            })
            .collect();
        expected.sort();
        let held: Vec<usize> = hold.stiffness.iter().map(|(b, _)| *b).collect();
        assert_eq!(held, expected);
        assert!(held.contains(&last), "{held:?}");
        let m = pose.parameter_count();
        let (mut h, mut g) = (DMatrix::zeros(m, m), DVector::zeros(m));
        let e = hold.add_normal_equations(&pose, &mut h, &mut g);
        assert!((e - hold.energy(&pose)).abs() <= 1e-12 * e.abs());
        assert!(e > 0.0);
        for i in 0..m {
            let step = 1e-6;
            let mut d = vec![0.0; m];
            d[i] = step;
            let up = hold.energy(&pose.apply_increment(&d));
            d[i] = -step;
            let down = hold.energy(&pose.apply_increment(&d));
            // e = sum r^T A r, so its derivative is 2 g.
            let numeric = (up - down) / (2.0 * step);
            assert!(
                (numeric - 2.0 * g[i]).abs() <= 1e-6 * (1.0 + g.abs().max()),
                "parameter {i}: {numeric} against {}",
                2.0 * g[i]
            );
        }
        // Held at the anchor: no energy, no pull.
        let (mut h0, mut g0) = (DMatrix::zeros(m, m), DVector::zeros(m));
        assert!(hold.add_normal_equations(&anchor, &mut h0, &mut g0) < 1e-24);
        assert!(g0.abs().max() < 1e-12);
    }
}
