//! A skeleton placed on a frame's triangulated body keypoints: the first guess of
//! `pipeline skeleton` on captures the person model has seen, so that no A- or T-pose is
//! needed. The template's limbs go from keypoint to keypoint (MediaPipe's left is the
//! subject's left, the template's `_l`):
//!
//! | bone | head | tail |
//! |---|---|---|
//! | `upper_arm_*` | shoulder | elbow |
//! | `forearm_*` | elbow | wrist |
//! | `hand_*` | wrist | towards the index knuckle, the template's hand length |
//! | `thigh_*` | hip | knee |
//! | `shin_*` | knee | ankle |
//! | `foot_*` | ankle | towards the foot's index toe, the template's foot length |
//!
//! The trunk's joints (bones without a side) keep their template place along the line from
//! the hips' midpoint to the shoulders' (its height between the template's hips and
//! shoulders, its share of the way along that line), and their offset from the line,
//! scaled; the rest of a bone keeps the template's length, scaled by the trunk's.

use super::triangulate::Point3;
use crate::skeleton::{Bone, Skeleton};
use nalgebra::Vector3;

/// The keypoint (by MediaPipe name) of a limb bone's head and tail, for side `l`/`r`.
fn limb(bone: &str) -> Option<(&'static str, &'static str, char)> {
    let (base, side) = bone.rsplit_once('_')?;
    let side = match side {
        "l" => 'l',
        "r" => 'r',
        _ => return None,
    };
    let (head, tail) = match base {
        "upper_arm" => ("shoulder", "elbow"),
        "forearm" => ("elbow", "wrist"),
        "hand" => ("wrist", "index"),
        "thigh" => ("hip", "knee"),
        "shin" => ("knee", "ankle"),
        "foot" => ("ankle", "foot_index"),
        _ => return None,
    };
    Some((head, tail, side))
}

/// The template placed on `points` (one frame's keypoints in LANDMARK_NAMES order), or
/// `None` when a keypoint it needs is missing or the template's bones are not the
/// humanoid's (`upper_arm_l` ... `foot_r` and a trunk).
pub fn from_keypoints(template: &Skeleton, points: &[Option<Point3>]) -> Option<Skeleton> {
    let at = |name: &str| -> Option<Vector3<f64>> {
        let i = super::LANDMARK_NAMES.iter().position(|n| *n == name)?;
        points.get(i)?.as_ref().map(|p| p.position)
    };
    let side = |name: &str, s: char| {
        at(&format!(
            "{}_{name}",
            if s == 'l' { "left" } else { "right" }
        ))
    };
    let tpl_bone = |name: &str| template.bones.iter().find(|b| b.name == name);
    // The trunk frame: hips' and shoulders' midpoints, in the template and in the body.
    let tpl_hips = (tpl_bone("thigh_l")?.head + tpl_bone("thigh_r")?.head) / 2.0;
    let tpl_shoulders = (tpl_bone("upper_arm_l")?.head + tpl_bone("upper_arm_r")?.head) / 2.0;
    let hips = (at("left_hip")? + at("right_hip")?) / 2.0;
    let shoulders = (at("left_shoulder")? + at("right_shoulder")?) / 2.0;
    let tpl_axis = tpl_shoulders - tpl_hips;
    let axis = shoulders - hips;
    let scale = axis.norm() / tpl_axis.norm().max(1e-9);
    let trunk = |p: &Vector3<f64>| -> Vector3<f64> {
        let f = (p - tpl_hips).dot(&tpl_axis) / tpl_axis.norm_squared();
        // Trunk joints lie on the template's centre line; what lies off it is kept, scaled.
        let off = (p - tpl_hips) - tpl_axis * f;
        hips + axis * f + off * scale
    };
    let mut bones: Vec<Bone> = Vec::with_capacity(template.bones.len());
    for b in &template.bones {
        let (head, tail) = match limb(&b.name) {
            Some((h, t, s)) => {
                let head = side(h, s)?;
                let toward = side(t, s)?;
                let tail = if matches!(t, "index" | "foot_index") {
                    head + (toward - head).try_normalize(1e-9)? * b.length() * scale
                } else {
                    toward
                };
                (head, tail)
            }
            None => {
                // A trunk bone: its head is its parent's tail where the template joins them.
                let head = match b.parent.map(|p| &bones[p]) {
                    Some(parent) if (template.bones[b.parent?].tail - b.head).norm() < 1e-6 => {
                        parent.tail
                    }
                    _ => trunk(&b.head),
                };
                (head, trunk(&b.tail))
            }
        };
        bones.push(Bone {
            head,
            tail,
            ..b.clone()
        });
    }
    // Shared joints stay shared: a child whose template head is its parent's tail.
    for i in 0..bones.len() {
        if let Some(p) = template.bones[i].parent {
            if (template.bones[p].tail - template.bones[i].head).norm() < 1e-6 {
                bones[i].head = bones[p].tail;
            }
        }
    }
    Some(Skeleton {
        reference_frame: template.reference_frame,
        bones,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_template_on_its_own_keypoints_is_itself() {
        let template = crate::synth::humanoid::skeleton();
        let bone = |n: &str| template.bones.iter().find(|b| b.name == n).unwrap();
        // Keypoints where the template's joints are (hands and feet point along their bones).
        let points: Vec<Option<Point3>> = super::super::LANDMARK_NAMES
            .iter()
            .map(|name| {
                let (s, base) = match name.split_once('_') {
                    Some(("left", b)) => ('l', b),
                    Some(("right", b)) => ('r', b),
                    _ => return None,
                };
                let p = match base {
                    "shoulder" => bone(&format!("upper_arm_{s}")).head,
                    "elbow" => bone(&format!("forearm_{s}")).head,
                    "wrist" => bone(&format!("hand_{s}")).head,
                    "index" => bone(&format!("hand_{s}")).tail,
                    "hip" => bone(&format!("thigh_{s}")).head,
                    "knee" => bone(&format!("shin_{s}")).head,
                    "ankle" => bone(&format!("foot_{s}")).head,
                    "foot_index" => bone(&format!("foot_{s}")).tail,
                    _ => return None,
                };
                Some(Point3 {
                    position: p,
                    views: vec![0, 1],
                    rms_px: 0.0,
                })
            })
            .collect();
        let placed = from_keypoints(&template, &points).unwrap();
        for (a, b) in placed.bones.iter().zip(&template.bones) {
            assert!(
                (a.head - b.head).norm() < 1e-9,
                "{}: head {:?} / {:?}",
                a.name,
                a.head,
                b.head
            );
            assert!((a.tail - b.tail).norm() < 1e-9, "{}: tail", a.name);
        }
        // A missing wrist: no guess.
        let mut missing = points.clone();
        missing[15] = None;
        assert!(from_keypoints(&template, &missing).is_none());
    }
}
