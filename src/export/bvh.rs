//! BVH (Biovision hierarchy): the skeleton and the fitted motion.
//!
//! Each bone becomes a JOINT at its head; OFFSET is the head's offset from the parent's head
//! at t0 (the rest pose), so the t0 pose is all-zero rotations. The root has six channels
//! (its posed head as `Xposition Yposition Zposition`, then three rotations; its OFFSET is
//! zero so readers that add it and readers that do not agree), every other joint three. A
//! leaf bone's tail is its `End Site`; a bone with children whose tail is not a child's head
//! gets an extra joint `<bone>_tail` at its tail (three channels, always zero) ending in a
//! zero End Site, so every head and tail of joints.csv is a BVH joint position.
//!
//! Rotations are the pose's local rotations L_b (relative to t0, in the parent's frame,
//! [`crate::skeleton::pose`]) as Euler angles in degrees in the declared channel order: for
//! `Zrotation Xrotation Yrotation`, L = Rz(a) Rx(b) Ry(c). Positions x are written as
//! C x - floor Y (offsets as C d) and rotations as C L Cᵀ, so the world's up is +Y and its
//! floor Y = 0 ([`crate::geometry::axes::ExportFrame`]). Units are metres.

use crate::geometry::axes::{ExportFrame, RotationOrder};
use crate::skeleton::{Pose, Skeleton};
use nalgebra::{Rotation3, Vector3};
use std::fmt::Write as _;

/// Distance under which a child's head counts as its parent's tail, metres.
const SAME_POINT: f64 = 1e-6;

/// A bone's name as a joint name (whitespace turned to `_`), in the BVH and the marker
/// files alike.
pub(super) fn joint_name(bone: &str) -> String {
    bone.chars()
        .map(|ch| if ch.is_whitespace() { '_' } else { ch })
        .collect()
}

/// Whether one of bone `b`'s `children` starts at its tail (the tail is then that child's
/// joint, not one of its own).
pub(super) fn tail_is_a_head(skeleton: &Skeleton, children: &[usize], b: usize) -> bool {
    let tail = skeleton.bones[b].tail;
    children
        .iter()
        .any(|&ch| (skeleton.bones[ch].head - tail).norm() <= SAME_POINT)
}

/// Writes the HIERARCHY section, depth first: the order in which MOTION lists channels.
struct Hierarchy<'a> {
    skeleton: &'a Skeleton,
    children: Vec<Vec<usize>>,
    /// World to export axes.
    c: Rotation3<f64>,
    order: RotationOrder,
    text: String,
    /// Per written joint, the bone whose rotation drives it (None: a tail joint, zeros).
    joints: Vec<Option<usize>>,
}

impl Hierarchy<'_> {
    fn name(&self, b: usize) -> String {
        joint_name(&self.skeleton.bones[b].name)
    }

    fn line(&mut self, depth: usize, s: &str) {
        let _ = writeln!(self.text, "{}{s}", "  ".repeat(depth));
    }

    fn end_site(&mut self, depth: usize, offset: &Vector3<f64>) {
        self.line(depth, "End Site");
        self.line(depth, "{");
        self.line(depth + 1, &format!("OFFSET {}", v3(offset)));
        self.line(depth, "}");
    }

    fn joint(&mut self, b: usize, depth: usize) {
        let bone = &self.skeleton.bones[b];
        let rotations = self.order.channels();
        let (keyword, offset, channels) = match bone.parent {
            None => (
                "ROOT",
                Vector3::zeros(),
                format!("6 Xposition Yposition Zposition {rotations}"),
            ),
            Some(p) => (
                "JOINT",
                self.c * (bone.head - self.skeleton.bones[p].head),
                format!("3 {rotations}"),
            ),
        };
        self.line(depth, &format!("{keyword} {}", self.name(b)));
        self.line(depth, "{");
        self.line(depth + 1, &format!("OFFSET {}", v3(&offset)));
        self.line(depth + 1, &format!("CHANNELS {channels}"));
        self.joints.push(Some(b));
        let tail = self.c * (bone.tail - bone.head);
        let children = self.children[b].clone();
        if children.is_empty() {
            self.end_site(depth + 1, &tail);
        } else {
            for &ch in &children {
                self.joint(ch, depth + 1);
            }
            if !tail_is_a_head(self.skeleton, &children, b) {
                self.line(depth + 1, &format!("JOINT {}_tail", self.name(b)));
                self.line(depth + 1, "{");
                self.line(depth + 2, &format!("OFFSET {}", v3(&tail)));
                self.line(depth + 2, &format!("CHANNELS 3 {rotations}"));
                self.joints.push(None);
                self.end_site(depth + 2, &Vector3::zeros());
                self.line(depth + 1, "}");
            }
        }
        self.line(depth, "}");
    }
}

fn v3(v: &Vector3<f64>) -> String {
    format!("{:.6} {:.6} {:.6}", v.x, v.y, v.z)
}

/// The BVH text of `skeleton` animated by `poses` ((frame, pose) in frame order).
pub fn to_bvh(
    skeleton: &Skeleton,
    poses: &[(u32, Pose)],
    frame_rate: f64,
    frame: &ExportFrame,
    order: RotationOrder,
) -> String {
    let c = frame.rotation;
    let mut h = Hierarchy {
        skeleton,
        children: skeleton.children(),
        c,
        order,
        text: String::from("HIERARCHY\n"),
        joints: Vec::new(),
    };
    for root in (0..skeleton.bones.len()).filter(|&b| skeleton.bones[b].parent.is_none()) {
        h.joint(root, 0);
    }
    let (mut text, joints) = (h.text, h.joints);
    let _ = writeln!(text, "MOTION");
    let _ = writeln!(text, "Frames: {}", poses.len());
    let _ = writeln!(text, "Frame Time: {:.8}", 1.0 / frame_rate);
    for (_, pose) in poses {
        let mut line = Vec::with_capacity(3 * joints.len() + 3);
        for j in &joints {
            let Some(b) = *j else {
                line.extend(["0.000000".to_string(), "0.000000".into(), "0.000000".into()]);
                continue;
            };
            let bone = &skeleton.bones[b];
            if bone.parent.is_none() {
                let p = frame.point(&(bone.head + pose.translation));
                line.extend([p.x, p.y, p.z].map(|x| format!("{x:.6}")));
            }
            let local = c * pose.rotations[b] * c.inverse();
            let angles = order.decompose(local.matrix());
            line.extend(angles.map(|a| format!("{:.6}", a.to_degrees())));
        }
        let _ = writeln!(text, "{}", line.join(" "));
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn euler_angles_round_trip_in_every_order() {
        let orders = ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"];
        let mut seed = 7u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        for o in orders {
            let order = RotationOrder::parse(o).unwrap();
            for t in 0..200 {
                let mut angles = [rnd() * 3.1, rnd() * 1.5, rnd() * 3.1];
                if t % 20 == 0 {
                    angles[1] = std::f64::consts::FRAC_PI_2 * if t % 40 == 0 { 1.0 } else { -1.0 };
                }
                let r = order.compose(angles);
                let back = order.compose(order.decompose(r.matrix()));
                let gap = (r.matrix() - back.matrix()).abs().max();
                assert!(gap < 1e-9, "{o} {angles:?}: {gap:e}");
            }
        }
        assert!(RotationOrder::parse("XXY").is_err());
        assert!(RotationOrder::parse("XY").is_err());
        assert_eq!(
            RotationOrder::parse("zxy").unwrap().channels(),
            "Zrotation Xrotation Yrotation"
        );
    }
}
