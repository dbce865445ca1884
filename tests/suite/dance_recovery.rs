//! Tracking through fast motion: the humanoid's dance (8 cameras, 640x480, 25 frames per
//! second; the arms cross in front of the chest with hand steps up to 16 cm per frame).
//!
//! With the default motion prior every joint stays within 3 cm of the truth. Without it,
//! as the arms cross the fit folds the right hand back onto its forearm, where rho_c hides
//! it; the health checks send the frame to recovery, which fits it again from the
//! straightened hypothesis. Without the prior and without recovery the hand stays lost.

use crate::common;

use common::*;
use hullpose::synth::{Motion, SceneKind, SynthOptions};

#[test]
fn the_dance_is_tracked_and_a_lost_hand_is_recovered() {
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
    let variant = |name: &str, fit: &str| {
        let text = yaml.replace("output: output", &format!("output: output_{name}"))
            + &format!("fit:\n  motion_prior_acceleration: 0\n{fit}");
        std::fs::write(d.join(format!("{name}.yaml")), text).unwrap();
    };
    variant("no_prior", "");
    variant("no_prior_no_recovery", "  restart:\n    enabled: false\n");

    // Default: the bound, every joint within 3 cm on every frame.
    let (ok, out, err) = run_cli(&["run", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    eprintln!("{out}{err}");
    let worst = output_worst_joint_errors_cm(d, "humanoid");
    let mean = output_joint_errors_cm(d, "humanoid");
    eprintln!("dance, worst joint per frame (cm): {worst:.2?}");
    assert_eq!(worst.len(), 17);
    assert!(worst.iter().all(|w| w.1 <= 3.0), "{worst:.2?}");
    assert!(mean.iter().all(|&e| e <= 2.0), "{mean:.2?}");
    assert_fit_health(d);

    // Without the prior the hand is lost as the arms cross, and recovered.
    let (ok, _, err) = run_cli(&["run", "no_prior.yaml", "--only", "fit"], d);
    assert!(ok, "{err}");
    assert!(err.contains("needed recovery"), "{err}");
    let out = d.join("output_no_prior");
    let health = hullpose::eval::health_table::read(&out).unwrap();
    let recovered: Vec<u32> = health
        .iter()
        .filter(|r| r.recovery == "straightened")
        .map(|r| r.frame)
        .collect();
    assert!(!recovered.is_empty(), "{health:?}");
    let hand = |dir: &str, frame: u32| hand_error_cm(d, dir, frame);
    let after = recovered[0] + 1..=16;
    assert!(
        after.clone().all(|f| hand("output_no_prior", f) < 4.0),
        "{:.1?}",
        after
            .map(|f| hand("output_no_prior", f))
            .collect::<Vec<_>>()
    );

    // Without the prior and without recovery, the hand stays lost to the end.
    let (ok, _, err) = run_cli(&["run", "no_prior_no_recovery.yaml", "--only", "fit"], d);
    assert!(ok, "{err}");
    let lost: Vec<f64> = (12..=16)
        .map(|f| hand("output_no_prior_no_recovery", f))
        .collect();
    assert!(lost.iter().all(|&e| e > 15.0), "{lost:.1?}");
    // The hand folded back onto the forearm is flagged on every frame where it lies over 20
    // cm off (`bent_joint`); at 10-20 cm it may still bend like a wrist.
    let health =
        hullpose::eval::health_table::read(&d.join("output_no_prior_no_recovery")).unwrap();
    for r in &health {
        let off = hand("output_no_prior_no_recovery", r.frame);
        assert!(
            off <= 20.0 || r.flags.contains("bent_joint"),
            "frame {}: hand {off:.1} cm off, flags '{}'",
            r.frame,
            r.flags
        );
    }
}

/// The right hand's tip's distance to the truth at `frame` in `output/joints.csv`, cm.
fn hand_error_cm(d: &std::path::Path, output: &str, frame: u32) -> f64 {
    let rows = hullpose::joints::read(&d.join(output).join("joints.csv")).unwrap();
    let truth = hullpose::joints::read(&d.join("data/humanoid/ground_truth/joints.csv")).unwrap();
    let find = |rows: &[hullpose::joints::JointRow]| {
        rows.iter()
            .find(|r| r.frame == frame && r.bone == "hand_r")
            .unwrap()
            .tail
    };
    100.0 * (find(&rows) - find(&truth)).norm()
}
