//! The README's quick start: `pipeline run pipeline.yaml` on the bundled sample (the tripod
//! at 256x192, 7 frames, up to 46 cm of motion between frames) tracks every frame within
//! 1 cm of the truth.

use crate::common;

use common::*;

#[test]
fn quick_start_tracks_the_bundled_sample_within_a_centimetre() {
    let dir = process_tempdir();
    let d = dir.path();
    copy_sample(d);
    let (ok, out, err) = run_cli(&["run", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    eprintln!("{out}");
    let errors = output_joint_errors_cm(d, "tripod");
    eprintln!("mean joint error per frame, cm: {errors:.2?}");
    assert_eq!(errors.len(), 7);
    let worst = errors.iter().copied().fold(0.0, f64::max);
    assert!(worst <= 1.0, "worst frame {worst:.2} cm: {errors:.2?}");
    assert_fit_health(d);
}
