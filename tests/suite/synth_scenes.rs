//! The synthetic scenes do what the method needs: phantom volume beneath the tripod's hub on
//! the phantom frames and none at t0, touching arm tips at t9-t10, touching body parts on
//! the humanoid's contact frames.

use crate::common;

use common::*;
use hullpose::dataset::Sequence;
use hullpose::geometry::TriMesh;
use std::path::Path;

fn open(root: &Path, seq: &str) -> Sequence {
    Sequence::open_with_calibration(
        &root.join("calib/cameras.yaml"),
        &root.join("data").join(seq),
    )
    .unwrap()
}

/// Size of the largest phantom region beneath the hub: voxels of the visual hull farther
/// than one voxel from the true object, within 25 cm of the vertical axis through the hub
/// and below the hub's underside (the hub's flesh is 9 cm thick; the crevices between the
/// arms beside the hub are concavities, not the space beneath it). Returns the equivalent diameter (metres) of the region's largest
/// horizontal slice, and the region's height.
fn phantom_beneath_hub(seq: &Sequence, frame: u32, hub: nalgebra::Vector3<f64>) -> (f64, f64) {
    let mesh: TriMesh = seq.ground_truth_mesh(frame).unwrap().unwrap();
    let grid = Grid::around(&mesh, 0.05, 0.01);
    let masks: Vec<_> = (0..seq.cameras.len())
        .map(|c| seq.load_mask(c, frame).unwrap().unwrap())
        .collect();
    let hull = carve(&grid, &seq.cameras, &masks);
    let near_truth = dilate(&grid, &voxelize(&grid, &mesh));
    let phantom: Vec<bool> = (0..grid.len())
        .map(|i| {
            let c = grid.centre(i);
            hull[i] && !near_truth[i] && (c.xy() - hub.xy()).norm() < 0.25 && c.z < hub.z - 0.10
        })
        .collect();
    let mut best = (0.0, 0.0);
    for comp in components(&grid, &phantom) {
        let mut per_slice = std::collections::HashMap::<usize, usize>::new();
        for &i in &comp {
            *per_slice.entry(grid.coords(i)[2]).or_default() += 1;
        }
        let largest = *per_slice.values().max().unwrap() as f64 * grid.size * grid.size;
        let across = 2.0 * (largest / std::f64::consts::PI).sqrt();
        if across > best.0 {
            best = (across, per_slice.len() as f64 * grid.size);
        }
    }
    best
}

#[test]
fn tripod_hull_has_phantom_beneath_hub_on_phantom_frames_only() {
    let made = tripod();
    let seq = open(&made.root, "tripod");
    let skel = seq.skeleton().unwrap().unwrap();
    let hub = skel.bones[0].head;
    let mut report = Vec::new();
    for f in [0u32, 3, 6, 7, 8, 9, 11, 12, 13] {
        let (across, height) = phantom_beneath_hub(&seq, f, hub);
        report.push(format!(
            "t{f}: {:.1} cm across, {:.0} cm tall",
            across * 100.0,
            height * 100.0
        ));
        if f == 0 {
            assert!(
                across < 0.05,
                "t0 must have no phantom region 5 cm across: {report:?}"
            );
        }
        if (6..=8).contains(&f) {
            assert!(
                across >= 0.05,
                "t{f} must have a phantom region >= 5 cm across: {report:?}"
            );
        }
    }
    eprintln!("{}", report.join("\n"));
}

/// Dominant bone of every rest vertex (frame 0's true mesh): the bone whose segment is
/// nearest. Frames share vertex order, so the labels hold for every frame.
fn labels(seq: &Sequence) -> Vec<usize> {
    let skel = seq.skeleton().unwrap().unwrap();
    let rest = seq
        .ground_truth_mesh(skel.reference_frame)
        .unwrap()
        .unwrap();
    rest.vertices
        .iter()
        .map(|v| {
            (0..skel.bones.len())
                .min_by(|&a, &b| {
                    let d = |i: usize| {
                        hullpose::synth::body::segment_distance(
                            v,
                            &skel.bones[i].head,
                            &skel.bones[i].tail,
                        )
                        .1
                    };
                    d(a).total_cmp(&d(b))
                })
                .unwrap()
        })
        .collect()
}

/// Smallest distance between vertices of part `a` and part `b` of frame `frame`, metres.
fn part_distance(seq: &Sequence, labels: &[usize], frame: u32, a: &str, b: &str) -> f64 {
    let skel = seq.skeleton().unwrap().unwrap();
    let (ia, ib) = (skel.bone_index(a).unwrap(), skel.bone_index(b).unwrap());
    let mesh = seq.ground_truth_mesh(frame).unwrap().unwrap();
    let pa: Vec<_> = mesh
        .vertices
        .iter()
        .zip(labels)
        .filter(|(_, &l)| l == ia)
        .map(|(v, _)| *v)
        .collect();
    let pb: Vec<_> = mesh
        .vertices
        .iter()
        .zip(labels)
        .filter(|(_, &l)| l == ib)
        .map(|(v, _)| *v)
        .collect();
    assert!(
        !pa.is_empty() && !pb.is_empty(),
        "parts {a} and {b} have vertices"
    );
    pa.iter()
        .flat_map(|p| pb.iter().map(move |q| (p - q).norm()))
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn tripod_arm_tips_touch_on_t9_and_t10() {
    let seq = open(&tripod().root, "tripod");
    let labels = labels(&seq);
    for (a, b) in [
        ("arm0_lower", "arm1_lower"),
        ("arm1_lower", "arm2_lower"),
        ("arm0_lower", "arm2_lower"),
    ] {
        for f in [9, 10] {
            let d = part_distance(&seq, &labels, f, a, b);
            assert!(d <= 0.01, "t{f}: {a} and {b} are {:.1} cm apart", d * 100.0);
        }
        for f in [0, 6] {
            let d = part_distance(&seq, &labels, f, a, b);
            assert!(
                d > 0.05,
                "t{f}: {a} and {b} must be apart, {:.1} cm",
                d * 100.0
            );
        }
    }
}

#[test]
fn humanoid_parts_touch_on_contact_frames_and_not_at_t0() {
    let seq = open(&humanoid().root, "humanoid");
    let labels = labels(&seq);
    let contacts = [
        (4, "hand_l", "pelvis"),
        (5, "hand_r", "pelvis"),
        (12, "forearm_r", "chest"),
        (13, "forearm_l", "forearm_r"),
        (20, "hand_r", "thigh_l"),
        (21, "hand_r", "thigh_l"),
    ];
    for (f, a, b) in contacts {
        let d = part_distance(&seq, &labels, f, a, b);
        assert!(
            d <= 0.01,
            "t{f}: {a} and {b} should touch but are {:.1} cm apart",
            d * 100.0
        );
        let d0 = part_distance(&seq, &labels, 0, a, b);
        assert!(
            d0 > 0.05,
            "t0: {a} and {b} should be apart but are {:.1} cm apart",
            d0 * 100.0
        );
    }
}

/// `--motion dance`: hand steps of 10-15 cm per frame at their fastest (never over 17), the
/// left foot crossing to the right of the right foot, and a turn of at least 90 degrees.
#[test]
fn the_dance_is_fast_crosses_the_legs_and_turns() {
    use hullpose::synth::{Motion, SceneKind, SynthOptions};
    let mut options = SynthOptions::new(SceneKind::Humanoid, "unused");
    options.motion = Motion::Dance;
    let scene = hullpose::synth::build_scene(&options).unwrap();
    let skeleton = &scene.body.skeleton;
    let bone = |n: &str| skeleton.bone_index(n).unwrap();
    let joints: Vec<_> = scene.poses.iter().map(|p| scene.body.joints(p)).collect();
    assert_eq!(joints.len(), 39);
    let hand_step = |f: usize| {
        ["hand_l", "hand_r"]
            .iter()
            .map(|h| (joints[f][bone(h)].1 - joints[f - 1][bone(h)].1).norm())
            .fold(0.0, f64::max)
    };
    let fastest = (1..joints.len()).map(hand_step).fold(0.0, f64::max);
    assert!(
        (0.10..=0.17).contains(&fastest),
        "fastest hand step {fastest} m"
    );
    // The left foot passes the right one sideways (in the body's turning frame: compare
    // along the line between the hips).
    let crossed = joints.iter().any(|j| {
        let across = j[bone("thigh_l")].0 - j[bone("thigh_r")].0;
        (j[bone("foot_l")].0 - j[bone("foot_r")].0).dot(&across) < 0.0
    });
    assert!(crossed, "the left foot crosses the right");
    let hips = |j: &Vec<(nalgebra::Vector3<f64>, nalgebra::Vector3<f64>)>| {
        let d = j[bone("thigh_l")].0 - j[bone("thigh_r")].0;
        d.y.atan2(d.x)
    };
    let turn = (hips(joints.last().unwrap()) - hips(&joints[0]))
        .to_degrees()
        .abs();
    let turn = turn.min(360.0 - turn);
    assert!(turn >= 90.0, "turned {turn} degrees");
}
