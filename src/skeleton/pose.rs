//! Pose parameters and forward kinematics (method.md "Stage 5").
//!
//! A pose holds the root's translation (metres) and, per bone, its rotation relative to the
//! reference pose t0 expressed in its parent's posed frame (the root's in the world frame):
//! the bone's global rotation is `G_b = G_parent(b) * L_b`, and a point x attached to bone b
//! at t0 moves to `G_b (x - rest_head_b) + head_b`, where the posed head is carried by the
//! parent (the root's head moves by the translation).
//!
//! As a parameter vector (3 N + 3 numbers for N bones): `[t_x, t_y, t_z, r_0, r_1, ...]`
//! where `r_b` is the rotation vector (axis times angle, radians) of `L_b`.
//!
//! Fitting steps by *increments*: `delta` of the same length moves the translation by
//! `delta[0..3]` and turns `L_b` into `exp(delta_b) L_b`, i.e. rotates bone b (and its
//! subtree) about its head by the rotation vector `G_parent(b) delta_b` in world axes. The
//! Jacobians are with respect to these increments at zero.

use super::Skeleton;
use nalgebra::{Matrix3, Rotation3, Vector3};

/// The pose of a skeleton: root translation and local rotations (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Pose {
    /// Root translation from its reference position, metres.
    pub translation: Vector3<f64>,
    /// Per bone, its rotation relative to t0 in its parent's posed frame.
    pub rotations: Vec<Rotation3<f64>>,
}

impl Pose {
    /// The reference pose t0 of a skeleton of `bones` bones.
    pub fn rest(bones: usize) -> Pose {
        Pose {
            translation: Vector3::zeros(),
            rotations: vec![Rotation3::identity(); bones],
        }
    }

    /// Number of parameters, 3 N + 3.
    pub fn parameter_count(&self) -> usize {
        3 * self.rotations.len() + 3
    }

    /// The parameter vector `[t, r_0, r_1, ...]` (metres, radians).
    pub fn to_vector(&self) -> Vec<f64> {
        let mut v = Vec::with_capacity(self.parameter_count());
        v.extend(self.translation.iter());
        for r in &self.rotations {
            v.extend(r.scaled_axis().iter());
        }
        v
    }

    /// The pose of a parameter vector of length 3 N + 3.
    pub fn from_vector(v: &[f64]) -> Pose {
        assert!(
            v.len() >= 3 && v.len().is_multiple_of(3),
            "3 N + 3 parameters"
        );
        Pose {
            translation: Vector3::new(v[0], v[1], v[2]),
            rotations: v[3..]
                .chunks_exact(3)
                .map(|r| Rotation3::new(Vector3::new(r[0], r[1], r[2])))
                .collect(),
        }
    }

    /// The pose after the increment `delta` (see the module docs).
    pub fn apply_increment(&self, delta: &[f64]) -> Pose {
        assert_eq!(delta.len(), self.parameter_count());
        Pose {
            translation: self.translation + Vector3::new(delta[0], delta[1], delta[2]),
            rotations: self
                .rotations
                .iter()
                .zip(delta[3..].chunks_exact(3))
                .map(|(r, d)| Rotation3::new(Vector3::new(d[0], d[1], d[2])) * r)
                .collect(),
        }
    }

    /// Whether every number of the pose is finite.
    pub fn is_finite(&self) -> bool {
        self.to_vector().iter().all(|v| v.is_finite())
    }
}

/// Every bone's rigid motion under one pose.
#[derive(Debug, Clone)]
pub struct PosedBones {
    /// Global rotation G_b of each bone relative to t0.
    pub rotations: Vec<Rotation3<f64>>,
    /// Reference (t0) head of each bone, metres.
    pub rest_heads: Vec<Vector3<f64>>,
    /// Posed head of each bone, metres.
    pub heads: Vec<Vector3<f64>>,
    /// Posed tail of each bone, metres.
    pub tails: Vec<Vector3<f64>>,
    /// World axes of each bone's rotation increment: the columns of its parent's global
    /// rotation (identity for the root).
    pub increment_axes: Vec<Matrix3<f64>>,
    /// Each bone followed by its ancestors up to the root.
    pub chains: Vec<Vec<usize>>,
}

impl PosedBones {
    /// Forward kinematics of `pose` on `skeleton` (bones listed parents first).
    pub fn new(skeleton: &Skeleton, pose: &Pose) -> PosedBones {
        let n = skeleton.bones.len();
        assert_eq!(pose.rotations.len(), n, "one rotation per bone");
        let mut out = PosedBones {
            rotations: Vec::with_capacity(n),
            rest_heads: Vec::with_capacity(n),
            heads: Vec::with_capacity(n),
            tails: Vec::with_capacity(n),
            increment_axes: Vec::with_capacity(n),
            chains: Vec::with_capacity(n),
        };
        for (b, bone) in skeleton.bones.iter().enumerate() {
            let (parent_rotation, head, mut chain) = match bone.parent {
                None => (
                    Rotation3::identity(),
                    bone.head + pose.translation,
                    Vec::new(),
                ),
                Some(p) => (
                    out.rotations[p],
                    out.transform(p, &bone.head),
                    out.chains[p].clone(),
                ),
            };
            chain.insert(0, b);
            let rotation = parent_rotation * pose.rotations[b];
            out.rotations.push(rotation);
            out.rest_heads.push(bone.head);
            out.heads.push(head);
            out.tails.push(rotation * (bone.tail - bone.head) + head);
            out.increment_axes.push(*parent_rotation.matrix());
            out.chains.push(chain);
        }
        out
    }

    /// Where the t0 point `x` attached rigidly to bone `b` moves.
    pub fn transform(&self, b: usize, x: &Vector3<f64>) -> Vector3<f64> {
        self.rotations[b] * (x - self.rest_heads[b]) + self.heads[b]
    }

    /// Accumulates into `columns` (one 3-vector per parameter) `weight` times the
    /// derivative of `y`, the posed position of a point rigidly attached to bone `b`, with
    /// respect to the pose increments: the identity for the translation, and for every
    /// bone a on b's chain, `axis_k x (y - head_a)` for its three increment axes.
    pub fn add_point_jacobian(
        &self,
        b: usize,
        y: &Vector3<f64>,
        weight: f64,
        columns: &mut [Vector3<f64>],
    ) {
        for (k, column) in columns[..3].iter_mut().enumerate() {
            column[k] += weight;
        }
        for &a in &self.chains[b] {
            let arm = y - self.heads[a];
            let axes = &self.increment_axes[a];
            for k in 0..3 {
                columns[3 + 3 * a + k] += weight * axes.column(k).cross(&arm);
            }
        }
    }
}

/// Posed (head, tail) of every bone.
pub fn joints(skeleton: &Skeleton, pose: &Pose) -> Vec<(Vector3<f64>, Vector3<f64>)> {
    let posed = PosedBones::new(skeleton, pose);
    posed.heads.into_iter().zip(posed.tails).collect()
}
