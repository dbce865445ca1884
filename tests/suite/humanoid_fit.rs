//! The humanoid (17 bones, 15 cameras, 640x480, t0..t23) through the whole pipeline: the
//! fit stage within 1.5 cm of the truth on every frame, hands crossing the chest and resting
//! on a knee included.

use crate::common;

use common::*;
use hullpose::synth::{SceneKind, SynthOptions};

#[test]
fn proposed_fit_tracks_the_humanoid_within_one_and_a_half_centimetres() {
    let dir = process_tempdir();
    let d = dir.path();
    let mut options = SynthOptions::new(SceneKind::Humanoid, d);
    (options.width, options.height) = (640, 480);
    hullpose::synth::generate(&options).unwrap();
    let (ok, out, err) = run_cli(&["run", "pipeline.yaml", "--until", "model"], d);
    assert!(ok, "{err}");
    eprintln!("{out}");

    let config = hullpose::config::Config::load(&d.join("pipeline.yaml")).unwrap();
    let job = hullpose::runner::Job::load(config, None).unwrap();
    let ctx = job.context();
    let model = hullpose::artifacts::body_model::read(ctx.cache).unwrap();
    let truth_path = d.join("data/humanoid/ground_truth/joints.csv");
    let truth = hullpose::joints::read(&truth_path).unwrap();
    let errors_cm = |rows: &[hullpose::joints::JointRow]| -> Vec<f64> {
        hullpose::eval::pose::joint_errors(&truth, rows, &truth_path)
            .unwrap()
            .into_iter()
            .map(|x| x.1 * 100.0)
            .collect()
    };
    let (ok, out, err) = run_cli(&["run", "pipeline.yaml", "--only", "fit"], d);
    assert!(ok, "{err}");
    eprintln!("{out}");
    let rows = hullpose::joints::read(&d.join("output/joints.csv")).unwrap();
    assert_eq!(rows.len(), 24 * model.skeleton.bones.len());
    assert!(rows
        .iter()
        .all(|r| r.head.iter().chain(r.tail.iter()).all(|v| v.is_finite())));
    let proposed = errors_cm(&rows);
    eprintln!("proposed: {proposed:.2?}");
    assert_eq!(proposed.len(), 24);
    let worst = proposed.iter().copied().fold(0.0, f64::max);
    assert!(worst <= 1.5, "proposed worst {worst:.2} cm: {proposed:.2?}");
    assert_fit_health(d);
}
