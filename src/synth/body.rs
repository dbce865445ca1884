//! Articulated synthetic bodies: bones with tapered round-cone flesh, a watertight rest
//! surface (the smooth union of the cones, meshed as an iso-surface), linear-blend skinning
//! weights, and posing.
//!
//! The rest pose is the reference frame t0, so `skeleton.yaml` describes the rest skeleton.
//! A pose gives every bone's rotation relative to the rest pose in the world frame (its
//! "global" rotation); every bone turns about its head, which its parent carries along.

use crate::geometry::isosurface::{self, ScalarGrid};
use crate::geometry::TriMesh;
pub use crate::skeleton::skinning::{segment_distance, segment_segment};
use crate::skeleton::Skeleton;
use nalgebra::{Rotation3, Vector3};

/// A body: skeleton at rest plus the flesh around every bone.
#[derive(Debug, Clone)]
pub struct Body {
    /// The rest (t0) skeleton.
    pub skeleton: Skeleton,
    /// Flesh radius at each bone's head and tail, metres.
    pub radii: Vec<(f64, f64)>,
    /// Whether a bone's flesh wears the plain (nearly uniform) material.
    pub plain: Vec<bool>,
    /// Smooth-union blend distance between neighbouring cones, metres.
    pub blend: f64,
    /// A skirt around the thighs, if the body wears one.
    pub skirt: Option<Skirt>,
}

/// A skirt at rest: a truncated cone about the vertical, from the waist down, which fuses
/// the thighs into one volume (it is skinned like the flesh, so it swings with the legs).
#[derive(Debug, Clone)]
pub struct Skirt {
    /// The centre of its top (the waist), metres.
    pub top: Vector3<f64>,
    /// Its length down from the top, metres.
    pub length: f64,
    /// Its radius at the top and at the hem, metres.
    pub radii: (f64, f64),
}

impl Skirt {
    /// Signed distance (approximate, negative inside) at rest.
    fn distance(&self, p: &Vector3<f64>) -> f64 {
        let below = self.top.z - p.z;
        let t = (below / self.length).clamp(0.0, 1.0);
        let radius = self.radii.0 + t * (self.radii.1 - self.radii.0);
        let radial = (p.xy() - self.top.xy()).norm() - radius;
        radial.max(-below).max(below - self.length)
    }
}

/// A pose: per bone, its rotation relative to the rest pose (world frame), and the root's
/// translation (metres).
#[derive(Debug, Clone)]
pub struct Pose {
    pub rotations: Vec<Rotation3<f64>>,
    pub root_translation: Vector3<f64>,
}

impl Pose {
    /// The same pose in the project's parameters (`crate::skeleton::pose`): each bone's
    /// rotation relative to its parent's, `L_b = G_parent^T G_b`.
    pub fn to_local(&self, skeleton: &Skeleton) -> crate::skeleton::Pose {
        crate::skeleton::Pose {
            translation: self.root_translation,
            rotations: skeleton
                .bones
                .iter()
                .enumerate()
                .map(|(b, bone)| match bone.parent {
                    None => self.rotations[b],
                    Some(p) => self.rotations[p].inverse() * self.rotations[b],
                })
                .collect(),
        }
    }

    /// The rest pose of a body with `n` bones.
    pub fn rest(n: usize) -> Pose {
        Pose {
            rotations: vec![Rotation3::identity(); n],
            root_translation: Vector3::zeros(),
        }
    }
}

/// Polynomial smooth minimum (blend width `k`).
fn smooth_min(a: f64, b: f64, k: f64) -> f64 {
    let h = (0.5 + 0.5 * (b - a) / k).clamp(0.0, 1.0);
    b + (a - b) * h - k * h * (1.0 - h)
}

/// Rigid transform of one bone: `x -> rotation * (x - rest_head) + head`.
#[derive(Debug, Clone, Copy)]
pub struct BoneTransform {
    pub rotation: Rotation3<f64>,
    pub rest_head: Vector3<f64>,
    pub head: Vector3<f64>,
}

impl BoneTransform {
    pub fn apply(&self, x: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * (x - self.rest_head) + self.head
    }
}

impl Body {
    /// Signed distance (approximate, negative inside) of the flesh around bone `b` at
    /// rest.
    fn cone_distance(&self, b: usize, p: &Vector3<f64>) -> f64 {
        let bone = &self.skeleton.bones[b];
        let (h, d) = segment_distance(p, &bone.head, &bone.tail);
        let (r0, r1) = self.radii[b];
        d - (r0 + h * (r1 - r0))
    }

    /// Signed distance to the rest surface (negative inside).
    pub fn rest_distance(&self, p: &Vector3<f64>) -> f64 {
        let flesh = (0..self.skeleton.bones.len())
            .map(|b| self.cone_distance(b, p))
            .fold(f64::INFINITY, |acc, d| {
                if acc.is_infinite() {
                    d
                } else {
                    smooth_min(acc, d, self.blend)
                }
            });
        match &self.skirt {
            Some(skirt) => flesh.min(skirt.distance(p)),
            None => flesh,
        }
    }

    /// How far down the skirt a rest point lies where the skirt, not the flesh, is the
    /// surface: 0 at the waist to 1 at the hem; 0 on the flesh and without a skirt.
    pub fn skirt_depth(&self, p: &Vector3<f64>) -> f64 {
        let Some(skirt) = &self.skirt else {
            return 0.0;
        };
        let flesh = (0..self.skeleton.bones.len())
            .map(|b| self.cone_distance(b, p))
            .fold(f64::INFINITY, f64::min);
        if skirt.distance(p) >= flesh - 1e-3 {
            return 0.0;
        }
        ((skirt.top.z - p.z) / skirt.length).clamp(0.0, 1.0)
    }

    /// The rest surface: the zero level of [`Body::rest_distance`] meshed at `spacing`.
    pub fn rest_mesh(&self, spacing: f64) -> TriMesh {
        let mut lo = Vector3::repeat(f64::INFINITY);
        let mut hi = Vector3::repeat(f64::NEG_INFINITY);
        for (b, bone) in self.skeleton.bones.iter().enumerate() {
            let r = self.radii[b].0.max(self.radii[b].1) + self.blend;
            for p in [bone.head, bone.tail] {
                lo = lo.inf(&(p - Vector3::repeat(r)));
                hi = hi.sup(&(p + Vector3::repeat(r)));
            }
        }
        if let Some(skirt) = &self.skirt {
            let r = Vector3::new(skirt.radii.1, skirt.radii.1, 0.0);
            let hem = skirt.top - Vector3::z() * skirt.length;
            lo = lo.inf(&(hem - r));
            hi = hi.sup(&(skirt.top + r));
        }
        let margin = Vector3::repeat(2.0 * spacing);
        let grid = ScalarGrid::sample(lo - margin, hi + margin, spacing, |p| self.rest_distance(p));
        isosurface::extract(&grid)
    }

    /// Bones whose flesh may blend with bone `b`'s at a joint: parent, children, and
    /// siblings sharing `b`'s head.
    fn neighbours(&self, b: usize) -> Vec<usize> {
        let bones = &self.skeleton.bones;
        (0..bones.len())
            .filter(|&o| {
                o != b
                    && (bones[b].parent == Some(o)
                        || bones[o].parent == Some(b)
                        || (bones[o].parent == bones[b].parent
                            && (bones[o].head - bones[b].head).norm() < 1e-9))
            })
            .collect()
    }

    /// Linear-blend skinning weights per rest vertex: the nearest bone, blended with its
    /// joint neighbours where they are almost as near (Gaussian falloff over `falloff`
    /// metres of extra distance). Entries are (bone, weight) with weights summing to 1.
    pub fn skin_weights(&self, rest: &TriMesh, falloff: f64) -> Vec<Vec<(usize, f64)>> {
        let neighbours: Vec<Vec<usize>> = (0..self.skeleton.bones.len())
            .map(|b| self.neighbours(b))
            .collect();
        rest.vertices
            .iter()
            .map(|p| {
                let d: Vec<f64> = (0..self.skeleton.bones.len())
                    .map(|b| self.cone_distance(b, p))
                    .collect();
                let best = (0..d.len()).min_by(|&i, &j| d[i].total_cmp(&d[j])).unwrap();
                let mut w: Vec<(usize, f64)> = std::iter::once(best)
                    .chain(neighbours[best].iter().copied())
                    .map(|b| (b, (-((d[b] - d[best]) / falloff).powi(2)).exp()))
                    .filter(|&(_, w)| w > 0.01)
                    .collect();
                let sum: f64 = w.iter().map(|x| x.1).sum();
                w.iter_mut().for_each(|x| x.1 /= sum);
                w
            })
            .collect()
    }

    /// Each bone's rigid transform under `pose`.
    pub fn transforms(&self, pose: &Pose) -> Vec<BoneTransform> {
        let mut out: Vec<BoneTransform> = Vec::with_capacity(self.skeleton.bones.len());
        for (b, bone) in self.skeleton.bones.iter().enumerate() {
            let head = match bone.parent {
                None => bone.head + pose.root_translation,
                Some(p) => out[p].apply(&bone.head),
            };
            out.push(BoneTransform {
                rotation: pose.rotations[b],
                rest_head: bone.head,
                head,
            });
        }
        out
    }

    /// Posed (head, tail) of every bone.
    pub fn joints(&self, pose: &Pose) -> Vec<(Vector3<f64>, Vector3<f64>)> {
        self.transforms(pose)
            .iter()
            .zip(&self.skeleton.bones)
            .map(|(t, b)| (t.head, t.apply(&b.tail)))
            .collect()
    }

    /// The rest mesh deformed by linear blend skinning.
    pub fn pose_mesh(&self, rest: &TriMesh, weights: &[Vec<(usize, f64)>], pose: &Pose) -> TriMesh {
        let t = self.transforms(pose);
        TriMesh {
            vertices: rest
                .vertices
                .iter()
                .zip(weights)
                .map(|(v, w)| w.iter().map(|&(b, wb)| wb * t[b].apply(v)).sum())
                .collect(),
            triangles: rest.triangles.clone(),
        }
    }

    /// Gap between the flesh of bones `a` and `b` under `pose` (negative when they overlap),
    /// from their cones' axes: metres.
    pub fn flesh_gap(&self, pose: &Pose, a: usize, b: usize) -> f64 {
        let j = self.joints(pose);
        let (s, t, d) = segment_segment(&j[a].0, &j[a].1, &j[b].0, &j[b].1);
        let ra = self.radii[a].0 + s * (self.radii[a].1 - self.radii[a].0);
        let rb = self.radii[b].0 + t * (self.radii[b].1 - self.radii[b].0);
        d - ra - rb
    }
}
