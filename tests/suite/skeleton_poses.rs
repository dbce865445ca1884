//! `pipeline skeleton` on the poses people stand in (`pipeline synth --pose`), at 8 and 12
//! cameras, in worlds tilted by 25 degrees with no up given: the skeleton found against the
//! generator's true one (every joint within 5.5 cm, mean within 2.5 cm; each hand and foot
//! within 8 cm), for the arms out with the elbows bent and fists down, and the arms down;
//! hands on the hips right or refused by name; and the tilted world itself (same images, up
//! only in the truth, found from the cameras, the floor found by `check` within 2 cm).

use crate::common::*;
use hullpose::skeleton::Skeleton;
use hullpose::synth::humanoid::{HeldPose, Proportions};
use hullpose::synth::{SceneKind, SynthOptions};
use nalgebra::Vector3;
use std::path::Path;

/// Generates body `body` holding `pose` before `cameras` cameras at 640x480, its world
/// tilted by `tilt` degrees; moves its skeleton.yaml away and returns the true skeleton.
fn capture(d: &Path, pose: HeldPose, body: u64, cameras: usize, tilt: f64) -> Skeleton {
    let mut options = SynthOptions::new(SceneKind::Humanoid, d);
    (options.cameras, options.width, options.height) = (cameras, 640, 480);
    options.seed = body;
    options.proportions = Proportions::from_seed(body);
    options.pose = Some(pose);
    options.world_tilt_deg = tilt;
    hullpose::synth::generate(&options).unwrap();
    let path = d.join("data/humanoid/skeleton.yaml");
    let truth = Skeleton::read(&path).unwrap();
    std::fs::remove_file(&path).unwrap();
    truth
}

/// Every joint's distance to the truth (heads and tails), centimetres, with its name.
fn joint_errors(made: &Skeleton, truth: &Skeleton) -> Vec<(f64, String)> {
    made.bones
        .iter()
        .zip(&truth.bones)
        .flat_map(|(m, t)| {
            [
                (100.0 * (m.head - t.head).norm(), format!("{} head", m.name)),
                (100.0 * (m.tail - t.tail).norm(), format!("{} tail", m.name)),
            ]
        })
        .collect()
}

/// Runs `pipeline skeleton` on the capture; the skeleton written, or the error.
fn skeleton(d: &Path) -> Result<Skeleton, String> {
    let (ok, out, err) = run_cli(&["skeleton", "pipeline.yaml"], d);
    if !ok {
        return Err(err);
    }
    assert!(out.contains("embedded 17 bones"), "{out}");
    Ok(Skeleton::read(&d.join("data/humanoid/skeleton.yaml")).unwrap())
}

/// The hands' and feet's tails within 8 cm of the truth: no limb outside its limb.
fn assert_limbs_in_limbs(made: &Skeleton, truth: &Skeleton, case: &str) {
    for (m, t) in made.bones.iter().zip(&truth.bones) {
        if m.name.starts_with("hand") || m.name.starts_with("foot") {
            let e = 100.0 * (m.tail - t.tail).norm();
            assert!(
                e <= 8.0,
                "{case}: {} ends {e:.1} cm from its limb's end",
                m.name
            );
        }
    }
}

#[test]
fn ordinary_poses_and_tilted_worlds_get_their_limbs_in_their_limbs() {
    use HeldPose::{ArmsDown, ArmsOutBent, HandsOnHips};
    // (pose, body, cameras, tilt, held to the 5 cm / 2.5 cm bound). Hands on the hips close
    // loops the template cannot follow: right, or refused by name (body 4 was once written
    // with both arms laid through the torso).
    let cases = [
        (ArmsOutBent, 4, 12, 25.0, true),
        (ArmsDown, 3, 8, 25.0, true),
        (HandsOnHips, 4, 8, 25.0, false),
    ];
    for (pose, body, cameras, tilt, bound) in cases {
        let case = format!("{pose:?}, body {body}, {cameras} cameras, tilt {tilt}");
        let dir = process_tempdir();
        let d = dir.path();
        let truth = capture(d, pose, body, cameras, tilt);
        match skeleton(d) {
            Ok(made) => {
                let errors = joint_errors(&made, &truth);
                let mean = errors.iter().map(|e| e.0).sum::<f64>() / errors.len() as f64;
                let worst =
                    errors.iter().fold(
                        (0.0, String::new()),
                        |a, e| {
                            if e.0 > a.0 {
                                e.clone()
                            } else {
                                a
                            }
                        },
                    );
                eprintln!(
                    "{case}: mean {mean:.2} cm, worst {:.2} cm ({})",
                    worst.0, worst.1
                );
                assert_limbs_in_limbs(&made, &truth, &case);
                if bound {
                    assert!(
                        mean <= 2.5 && worst.0 <= 5.5,
                        "{case}: {mean:.2} / {worst:?}"
                    );
                }
            }
            // Only the poses not yet held to the bound may be refused, by name.
            Err(e) => {
                eprintln!("{case}: refused: {e}");
                assert!(!bound, "{case}: {e}");
                assert!(
                    e.contains("holds no bone") || e.contains("runs through the torso"),
                    "{case}: {e}"
                );
            }
        }
    }
}

#[test]
fn a_tilted_world_keeps_its_images_and_states_its_up_only_in_the_truth() {
    let dir = process_tempdir();
    let (flat, tilted) = (dir.path().join("flat"), dir.path().join("tilted"));
    capture(&flat, HeldPose::APose, 0, 8, 0.0);
    capture(&tilted, HeldPose::APose, 0, 8, 25.0);
    let frame = "data/humanoid/frames/cam02/000000.png";
    assert_eq!(
        std::fs::read(flat.join(frame)).unwrap(),
        std::fs::read(tilted.join(frame)).unwrap()
    );
    let yaml = std::fs::read_to_string(tilted.join("pipeline.yaml")).unwrap();
    assert!(
        !yaml.contains("up_axis") && !yaml.contains("world:"),
        "{yaml}"
    );
    let truth: hullpose::synth::world::WorldTruth =
        hullpose::yaml::read(&tilted.join("data/humanoid/ground_truth/world.yaml")).unwrap();
    let up = Vector3::from(truth.up);
    assert!((up.z.acos().to_degrees() - 25.0).abs() < 1e-6, "{up}");
    // The cameras show the same up.
    let cams = hullpose::camera::read_cameras(&tilted.join("calib/cameras.yaml"))
        .unwrap()
        .cameras;
    let found = hullpose::geometry::up::estimate(&cams, None).unwrap();
    assert!(
        hullpose::geometry::up::angle_deg(&found.up, &up) < 3.0,
        "{:?}",
        found.up
    );
    // `check` finds the floor from the reconstruction, along the up it found.
    let (ok, out, err) = run_cli(&["check", "pipeline.yaml"], &tilted);
    assert!(ok, "{err}");
    let floor: f64 = out
        .lines()
        .find_map(|l| l.strip_prefix("floor: "))
        .and_then(|l| l.split(' ').next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no floor in: {out}"));
    assert!(
        (floor - truth.floor_height).abs() <= 0.02,
        "floor {floor} m against {} m",
        truth.floor_height
    );
}
