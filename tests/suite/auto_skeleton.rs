//! `pipeline skeleton`: the built-in humanoid template embedded in the reference frame's
//! surface, on synthetic humanoids of four different bodies (height within 15%, limbs
//! within 7% more; body 4 the smallest, its arms the longest for its height) at 12 and 8
//! cameras, against the generator's true skeleton; tracking from the automatic skeleton;
//! and the refusals.

use crate::common;

use common::*;
use hullpose::skeleton::Skeleton;
use hullpose::synth::humanoid::Proportions;
use hullpose::synth::{SceneKind, SynthOptions};
use std::path::Path;

/// Generates the humanoid `body` seen by `cameras` at 640x480 (`frames` frames of its
/// motion; `None`: all), moves its skeleton.yaml away and returns the true skeleton.
fn capture(d: &Path, body: u64, cameras: usize, frames: Option<usize>) -> Skeleton {
    let mut options = SynthOptions::new(SceneKind::Humanoid, d);
    (options.cameras, options.width, options.height) = (cameras, 640, 480);
    options.frames = frames;
    options.seed = body;
    options.proportions = Proportions::from_seed(body);
    hullpose::synth::generate(&options).unwrap();
    let path = d.join("data/humanoid/skeleton.yaml");
    let truth = Skeleton::read(&path).unwrap();
    std::fs::remove_file(&path).unwrap();
    truth
}

/// Mean and worst joint distance (heads and tails), centimetres.
fn joint_errors(a: &Skeleton, b: &Skeleton) -> (f64, f64) {
    let d: Vec<f64> = a
        .bones
        .iter()
        .zip(&b.bones)
        .flat_map(|(x, y)| [(x.head - y.head).norm(), (x.tail - y.tail).norm()])
        .map(|e| 100.0 * e)
        .collect();
    (
        d.iter().sum::<f64>() / d.len() as f64,
        d.iter().fold(0.0, |m, &e| m.max(e)),
    )
}

#[test]
fn four_bodies_at_twelve_and_eight_cameras_are_embedded_within_three_centimetres() {
    for cameras in [12, 8] {
        for body in 1..=4 {
            let dir = process_tempdir();
            let d = dir.path();
            let truth = capture(d, body, cameras, Some(1));
            let (ok, out, err) = run_cli(&["skeleton", "pipeline.yaml"], d);
            assert!(ok, "body {body}, {cameras} cameras: {err}");
            assert!(out.contains("embedded 17 bones in frame 0"), "{out}");
            // The command's own checks of the result: every joint inside all but at most
            // one camera's silhouette, left and right limbs within 10%.
            let seen: usize = out
                .split("of at least ")
                .nth(1)
                .and_then(|t| t.split(' ').next())
                .and_then(|n| n.parse().ok())
                .unwrap_or_else(|| panic!("{out}"));
            assert!(seen + 1 >= cameras, "{out}");
            for line in out.lines().filter(|l| l.contains("limb from")) {
                let pct: f64 = line
                    .rsplit('(')
                    .next()
                    .and_then(|t| t.trim_end_matches("%)").parse().ok())
                    .unwrap_or_else(|| panic!("{line}"));
                assert!(pct.abs() <= 10.0, "{line}");
            }
            let made = Skeleton::read(&d.join("data/humanoid/skeleton.yaml")).unwrap();
            let (mean, worst) = joint_errors(&made, &truth);
            eprintln!("body {body}, {cameras} cameras: mean {mean:.2} cm, worst {worst:.2} cm");
            assert!(
                mean <= 3.0 && worst <= 5.0,
                "body {body}, {cameras} cameras: {mean:.2} / {worst:.2}"
            );
            assert!(d.join("output/skeleton/bones.ply").is_file());
            assert!(d.join("output/skeleton/overlay.png").is_file());
        }
    }
}

#[test]
fn tracking_from_the_automatic_skeleton_stays_within_two_and_a_half_centimetres() {
    let dir = process_tempdir();
    let d = dir.path();
    capture(d, 2, 8, None);
    let yaml = std::fs::read_to_string(d.join("pipeline.yaml")).unwrap();
    std::fs::write(
        d.join("pipeline.yaml"),
        yaml.replace("frames: all", "frames: 0..8"),
    )
    .unwrap();
    // Without --frame every frame of 0..8 is examined (at most 12 are) and scored; the
    // best is written, wherever it lies: tracking then runs backwards and forwards from it.
    let (ok, out, err) = run_cli(&["skeleton", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    assert!(out.contains("frames examined"), "{out}");
    let examined = out
        .lines()
        .filter(|l| l.trim_start().starts_with("frame "))
        .count();
    assert_eq!(examined, 9, "{out}");
    let made = std::fs::read(d.join("data/humanoid/skeleton.yaml")).unwrap();
    let chosen = Skeleton::read(&d.join("data/humanoid/skeleton.yaml")).unwrap();
    eprintln!("reference frame chosen: {}", chosen.reference_frame);

    // The frame with the hands on the hips is not chosen; asked for, it is refused with
    // the reason (a loop the template cannot follow) or embedded with a warning that a
    // limb was not followed. An existing skeleton.yaml is replaced only with --force.
    assert_ne!(chosen.reference_frame, 4);
    let (ok, _, err) = run_cli(&["skeleton", "pipeline.yaml", "--frame", "4"], d);
    assert!(!ok && err.contains("--force"), "{err}");
    assert_eq!(
        std::fs::read(d.join("data/humanoid/skeleton.yaml")).unwrap(),
        made
    );
    let (ok, _, err) = run_cli(&["skeleton", "pipeline.yaml", "--frame", "4", "--force"], d);
    if ok {
        assert!(err.contains("lies far from every bone"), "{err}");
        std::fs::write(d.join("data/humanoid/skeleton.yaml"), &made).unwrap();
    } else {
        assert!(
            err.contains("holds no bone") || err.contains("runs through the torso"),
            "{err}"
        );
        assert_eq!(
            std::fs::read(d.join("data/humanoid/skeleton.yaml")).unwrap(),
            made
        );
    }

    let (ok, _, err) = run_cli(&["run", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    let errors = output_joint_errors_cm(d, "humanoid");
    eprintln!("from the automatic skeleton, mean joint error per frame (cm): {errors:.2?}");
    // The exports' floor, found as the posed model's lowest point, lies within 2 cm of the
    // true floor (z = 0) and is put at Y = 0.
    let path = d.join("output/export/world.yaml");
    let placed: hullpose::geometry::axes::ExportFrame =
        hullpose::yaml::from_str(&path, &std::fs::read_to_string(&path).unwrap()).unwrap();
    assert!(placed.floor.abs() <= 0.02, "floor {:.3} m", placed.floor);
    assert_eq!(errors.len(), 9);
    assert!(errors.iter().all(|&e| e <= 2.5), "{errors:.2?}");
}

/// The humanoid in a dress (`--dress`: a skirt that fuses the thighs to above the knees
/// and swings with the legs) stands with its arms hanging against its hips for the first
/// ten frames (`--motion arms-down`; no open pose before the tenth frame): `pipeline
/// skeleton` still embeds the template within 3 cm on average and 5 cm at worst of the
/// truth at the frame it picks (the bounds for a dress: 4 and 8), and tracking
/// from it covers every frame within 2.5 cm (bound 3).
#[test]
fn a_dress_and_no_open_pose_at_the_start_are_embedded_and_tracked() {
    let dir = process_tempdir();
    let d = dir.path();
    let mut options = SynthOptions::new(SceneKind::Humanoid, d);
    (options.cameras, options.width, options.height) = (8, 640, 480);
    options.motion = hullpose::synth::Motion::ArmsDown;
    options.dress = Some(hullpose::synth::Dress::Fitted);
    hullpose::synth::generate(&options).unwrap();
    // Frames 0..15: arms down to frame 9, open at 13, towards the crossed forearms after.
    let yaml = std::fs::read_to_string(d.join("pipeline.yaml")).unwrap();
    std::fs::write(
        d.join("pipeline.yaml"),
        yaml.replace("frames: all", "frames: 0..15"),
    )
    .unwrap();
    let path = d.join("data/humanoid/skeleton.yaml");
    std::fs::remove_file(&path).unwrap();
    let (ok, out, err) = run_cli(&["skeleton", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    let made = Skeleton::read(&path).unwrap();
    let t0 = made.reference_frame;
    // The truth at the chosen frame, from the ground truth's joints.
    let truth_rows =
        hullpose::joints::read(&d.join("data/humanoid/ground_truth/joints.csv")).unwrap();
    let mut truth = made.clone();
    for bone in &mut truth.bones {
        let row = truth_rows
            .iter()
            .find(|r| r.frame == t0 && r.bone == bone.name)
            .unwrap();
        (bone.head, bone.tail) = (row.head, row.tail);
    }
    let (mean, worst) = joint_errors(&made, &truth);
    eprintln!("arms down: frame {t0} chosen, mean {mean:.2} cm, worst {worst:.2} cm\n{out}");
    assert!(mean <= 3.0 && worst <= 5.0, "{mean:.2} / {worst:.2}\n{out}");

    let (ok, _, err) = run_cli(&["run", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    let errors = output_joint_errors_cm(d, "humanoid");
    eprintln!("arms down, tracked: mean joint error per frame (cm): {errors:.2?}");
    assert_eq!(errors.len(), 16);
    assert!(errors.iter().all(|&e| e <= 2.5), "{errors:.2?}");
    // Through the dress: no frame below 0.9 x the reference IoU; the flags follow the truth
    // and recovery ran on at most 10% of the frames (the bounds for flags that mean
    // something). At t15 the right hand folds against the belly (15.8 cm off), which fits
    // the evidence as well as the true hand straight before the skirt: flagged `ambiguous`.
    let rows = assert_silhouettes_held(d);
    assert_flags_follow_truth(d, "humanoid");
    let recovered = rows.iter().filter(|r| !r.recovery.is_empty()).count();
    assert!(
        10 * recovered <= rows.len(),
        "recovery on {recovered} of {} frames",
        rows.len()
    );
}
