//! A frame rate the fit cannot be misled by: the bundled sample (7 frames, up to 46 cm of
//! motion between frames, key frames at 8.33 per second) tracked with `export.frame_rate`
//! right (8.33), too high (25, 50: the motion prior's weight grows with f^4) and absent
//! (the default: the rate is unknown) stays within 1 cm of the truth on every frame.

use crate::common;

use common::*;

#[test]
fn the_sample_tracks_within_a_centimetre_at_any_declared_frame_rate() {
    // One capture and one cache: the stages before the fit do not read the frame rate and
    // are computed once; each rate's fit is computed afresh (its key holds the rate).
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path();
    copy_sample(run);
    let path = run.join("pipeline.yaml");
    let text = std::fs::read_to_string(&path).unwrap();
    for rate in ["8.33", "25", "50", "absent"] {
        let line = text
            .lines()
            .find(|l| l.trim_start().starts_with("frame_rate:"))
            .unwrap()
            .to_string();
        let changed = match rate {
            "absent" => text.replace(&format!("{line}\n"), ""),
            r => text.replace(&line, &format!("  frame_rate: {r}")),
        };
        assert_ne!(changed, text, "{rate}");
        std::fs::write(&path, changed).unwrap();
        let (ok, out, err) = run_cli(&["run", "pipeline.yaml"], run);
        assert!(ok, "{rate}: {err}");
        if rate != "8.33" {
            assert!(out.contains("reliability: 0 computed"), "{rate}: {out}");
            assert!(!out.contains("fit: 0 computed"), "{rate}: {out}");
        }
        let errors = output_joint_errors_cm(run, "tripod");
        eprintln!("frame rate {rate}: mean joint error per frame (cm) {errors:.2?}");
        assert_eq!(errors.len(), 7);
        assert!(errors.iter().all(|&e| e <= 1.0), "{rate}: {errors:.2?}");
        if rate == "absent" {
            // An unknown rate judges no joint speed: a good track is neither flagged nor
            // recovered (at a guessed 25 per second, 4 of 7 frames were).
            let rows = hullpose::eval::health_table::read(&run.join("output")).unwrap();
            assert!(
                rows.iter()
                    .all(|r| r.flags.is_empty() && r.recovery.is_empty()),
                "{rows:?}"
            );
        }
    }
}
