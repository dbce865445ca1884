//! Deep interpenetration of two parts that do not meet at a joint (a health check, README
//! "Reading the fit's health"): each bone's flesh as a tapered capsule (its radius at the
//! head and at the tail from the reference model's vertices), and for every pair of bones
//! that do not meet, how far their capsules overlap at a pose beyond how far they overlap
//! at the reference pose.

use crate::skeleton::model::BodyModel;
use crate::skeleton::skinning::{joint_neighbours, segment_distance, segment_segment};
use crate::skeleton::Pose;

/// A capsule's radius is this quantile of its vertices' distances to the bone (low, so
/// that only a deep overlap counts).
const RADIUS_QUANTILE: f64 = 0.25;

/// The body's parts as capsules, and the pairs checked.
pub struct Capsules {
    /// (head radius, tail radius) per bone, metres.
    radii: Vec<(f64, f64)>,
    /// (bone a, bone b, their overlap at the reference pose, metres; 0 when apart).
    pairs: Vec<(usize, usize, f64)>,
}

impl Capsules {
    pub fn new(model: &BodyModel) -> Capsules {
        let skeleton = &model.skeleton;
        let n = skeleton.bones.len();
        // Per bone, the distances of its vertices in the head half and the tail half.
        let mut halves: Vec<[Vec<f64>; 2]> = vec![[Vec::new(), Vec::new()]; n];
        for (v, &b) in model.mesh.vertices.iter().zip(&model.labels) {
            let bone = &skeleton.bones[b];
            let (t, d) = segment_distance(v, &bone.head, &bone.tail);
            halves[b][usize::from(t >= 0.5)].push(d);
        }
        let quantile = |mut d: Vec<f64>| -> f64 {
            if d.is_empty() {
                return 0.0;
            }
            d.sort_by(f64::total_cmp);
            d[((d.len() - 1) as f64 * RADIUS_QUANTILE) as usize]
        };
        let radii: Vec<(f64, f64)> = halves
            .into_iter()
            .map(|[head, tail]| (quantile(head), quantile(tail)))
            .collect();
        let mut capsules = Capsules {
            radii,
            pairs: Vec::new(),
        };
        let rest = crate::skeleton::pose::joints(skeleton, &Pose::rest(n));
        for a in 0..n {
            let meets = joint_neighbours(skeleton, a);
            for b in a + 1..n {
                if !meets.contains(&b) {
                    let overlap = capsules.overlap(&rest, a, b).max(0.0);
                    capsules.pairs.push((a, b, overlap));
                }
            }
        }
        capsules
    }

    /// How far the capsules of bones `a` and `b` overlap with joints `joints` ((head,
    /// tail) per bone), metres (negative: apart).
    fn overlap(
        &self,
        joints: &[(nalgebra::Vector3<f64>, nalgebra::Vector3<f64>)],
        a: usize,
        b: usize,
    ) -> f64 {
        let (ja, jb) = (joints[a], joints[b]);
        let (s, t, d) = segment_segment(&ja.0, &ja.1, &jb.0, &jb.1);
        let ra = self.radii[a].0 + s * (self.radii[a].1 - self.radii[a].0);
        let rb = self.radii[b].0 + t * (self.radii[b].1 - self.radii[b].0);
        ra + rb - d
    }

    /// The deepest overlap at `pose` of two parts that do not meet, beyond their overlap at
    /// the reference pose, metres, with the two bones; `None` when no pair overlaps more.
    pub fn deepest(&self, model: &BodyModel, pose: &Pose) -> Option<(usize, usize, f64)> {
        let joints = crate::skeleton::pose::joints(&model.skeleton, pose);
        self.pairs
            .iter()
            .map(|&(a, b, rest)| (a, b, self.overlap(&joints, a, b) - rest))
            .filter(|x| x.2 > 0.0)
            .max_by(|x, y| x.2.total_cmp(&y.2))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Vector3};

    /// The synthetic humanoid's right forearm turned into its chest overlaps deeply; its
    /// reference pose does not count.
    #[test]
    fn a_forearm_pushed_into_the_chest_overlaps() {
        let body = crate::synth::humanoid::standard_body();
        let mesh = body.rest_mesh(0.02);
        let model = crate::skeleton::model::build(
            &body.skeleton,
            &mesh,
            &crate::skeleton::model::ModelParams::default(),
        )
        .unwrap();
        let capsules = Capsules::new(&model);
        let n = model.skeleton.bones.len();
        assert!(capsules.deepest(&model, &Pose::rest(n)).is_none());
        let mut pose = Pose::rest(n);
        let upper = model.skeleton.bone_index("upper_arm_r").unwrap();
        // The arm turned to point through the chest, across the body.
        let bone = &model.skeleton.bones[upper];
        pose.rotations[upper] = Rotation3::rotation_between(
            &(bone.tail - bone.head),
            &(Vector3::new(0.1, 0.0, 1.2) - bone.head),
        )
        .unwrap();
        let (a, b, depth) = capsules.deepest(&model, &pose).unwrap();
        let names = [&model.skeleton.bones[a].name, &model.skeleton.bones[b].name];
        assert!(depth > 0.03, "{names:?} {depth}");
    }
}
