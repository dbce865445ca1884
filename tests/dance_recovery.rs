//! Tracking that repairs itself: the humanoid's dance (8 cameras, 640x480, 25 frames per
//! second; the arms cross in front of the chest with hand steps up to 16 cm per frame).
//! As the arms cross, the first fit folds the right hand back onto its forearm, where
//! rho_c hides it; the surface it should cover is left unexplained, and recovery fits the
//! frame again from the straightened hypothesis. Without recovery the hand stays lost.

mod common;

use common::*;
use hullpose::synth::{Motion, SceneKind, SynthOptions};

#[test]
fn the_dance_s_lost_hand_is_recovered() {
    let dir = process_tempdir();
    let d = dir.path();
    let mut options = SynthOptions::new(SceneKind::Humanoid, d);
    (options.cameras, options.width, options.height) = (8, 640, 480);
    options.motion = Motion::Dance;
    hullpose::synth::generate(&options).unwrap();
    // The first 17 frames: the arms cross and open again.
    let yaml = std::fs::read_to_string(d.join("pipeline.yaml")).unwrap();
    let yaml = yaml.replace("frames: all", "frames: 0..16");
    std::fs::write(d.join("pipeline.yaml"), &yaml).unwrap();
    let without = yaml.replace("output: output", "output: output_without")
        + "fit:\n  restart:\n    enabled: false\n";
    std::fs::write(d.join("without.yaml"), without).unwrap();

    let (ok, out, err) = run_cli(&["run", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    eprintln!("{out}{err}");
    assert!(err.contains("needed recovery"), "{err}");
    let health = hullpose::eval::health::read(&d.join("output")).unwrap();
    assert!(
        health.iter().any(|r| r.recovery == "straightened"),
        "{health:?}"
    );
    let worst = output_worst_joint_errors_cm(d, "humanoid");
    let mean = output_joint_errors_cm(d, "humanoid");
    eprintln!("dance with recovery, worst joint per frame (cm): {worst:.2?}");
    assert_eq!(worst.len(), 17);
    // Mean joint error within 2 cm on every frame (issue bound).
    assert!(mean.iter().all(|&e| e <= 2.0), "{mean:.2?}");
    // Every joint within 4 cm on every frame but one: the frame where the arms first
    // cross, which the observation explains better with the hand folded (a fit from the
    // true pose scores higher there; BENCHMARKS.md). That one stays within 10 cm.
    let far: Vec<_> = worst.iter().filter(|w| w.1 > 4.0).collect();
    assert!(far.len() <= 1 && far.iter().all(|w| w.1 <= 10.0), "{far:?}");
    assert_fit_health(d);

    // Without restarts and recovery, the hand stays lost to the end.
    let (ok, _, err) = run_cli(&["run", "without.yaml", "--only", "fit"], d);
    assert!(ok, "{err}");
    let rows = hullpose::joints::read(&d.join("output_without/joints.csv")).unwrap();
    let truth = hullpose::joints::read(&d.join("data/humanoid/ground_truth/joints.csv")).unwrap();
    let hand_error = |frame: u32| {
        let find = |rows: &[hullpose::joints::JointRow]| {
            rows.iter()
                .find(|r| r.frame == frame && r.bone == "hand_r")
                .unwrap()
                .tail
        };
        100.0 * (find(&rows) - find(&truth)).norm()
    };
    let lost: Vec<f64> = (12..=16).map(hand_error).collect();
    assert!(lost.iter().all(|&e| e > 15.0), "{lost:.1?}");
}
