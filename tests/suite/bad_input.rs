//! Broken captures give one clear error naming the file and the problem, a non-zero exit,
//! and no panic.

use crate::common;

use common::*;
use hullpose::synth::{SceneKind, SynthOptions};
use std::path::Path;
use std::sync::OnceLock;

/// A small valid capture (3 cameras, 2 frames, 80x60) every case copies and breaks.
fn pristine() -> &'static Path {
    static CELL: OnceLock<tempfile::TempDir> = OnceLock::new();
    CELL.get_or_init(|| {
        let dir = process_tempdir();
        let mut o = SynthOptions::new(SceneKind::Tripod, dir.path());
        (o.cameras, o.width, o.height, o.frames) = (3, 80, 60, Some(2));
        o.mesh_spacing = 0.03;
        hullpose::synth::generate(&o).unwrap();
        dir
    })
    .path()
}

/// Copies the pristine capture, breaks it with `damage`, runs `pipeline check`, and
/// returns stderr after checking the failure is clean.
fn check_fails(damage: impl FnOnce(&Path)) -> String {
    let dir = tempfile::tempdir().unwrap();
    copy_tree(pristine(), dir.path());
    damage(dir.path());
    let (ok, _out, err) = run_cli(&["check", "pipeline.yaml"], dir.path());
    assert!(!ok, "the check must fail");
    assert!(!err.contains("panicked"), "no panic: {err}");
    eprintln!("{err}");
    assert_eq!(err.trim().lines().count(), 1, "one clear error line: {err}");
    err
}

#[test]
fn the_pristine_capture_passes_the_check() {
    let dir = tempfile::tempdir().unwrap();
    copy_tree(pristine(), dir.path());
    let (ok, out, err) = run_cli(&["check", "pipeline.yaml"], dir.path());
    assert!(ok, "{err}");
    assert!(out.contains("3 cameras, 2 frames"), "{out}");
    // Three cameras are a sparse rig, said so; nothing else is warned about.
    assert!(
        err.lines()
            .all(|l| l.starts_with("warning: only") && l.contains("seen by two or more cameras")),
        "no other warning: {err}"
    );
}

#[test]
fn missing_camera_folder() {
    let err = check_fails(|d| std::fs::remove_dir_all(d.join("data/tripod/frames/cam01")).unwrap());
    assert!(
        err.contains("frames/cam01") && err.contains("missing frame folder for camera 'cam01'"),
        "{err}"
    );
}

#[test]
fn frame_missing_in_one_camera() {
    let err = check_fails(|d| {
        std::fs::remove_file(d.join("data/tripod/frames/cam02/000001.png")).unwrap()
    });
    assert!(
        err.contains("cam02/000001.png") && err.contains("lacks frame 1"),
        "{err}"
    );
}

#[test]
fn calibration_whose_r_is_not_a_rotation() {
    let err = check_fails(|d| {
        let path = d.join("calib/cameras.yaml");
        let mut cams = hullpose::camera::read_cameras(&path).unwrap().cameras;
        cams[1].r *= 1.01; // a scaled rotation: not orthonormal
        std::fs::write(&path, hullpose::camera::cameras_to_yaml(&cams)).unwrap();
    });
    assert!(
        err.contains("cameras.yaml")
            && err.contains("camera 'cam01'")
            && err.contains("R is not a rotation"),
        "{err}"
    );
}

#[test]
fn image_size_differs_from_calibration() {
    let err = check_fails(|d| {
        let img = image::RgbImage::new(40, 30);
        img.save(d.join("data/tripod/frames/cam00/000001.png"))
            .unwrap();
    });
    assert!(
        err.contains("cam00/000001.png") && err.contains("40x30") && err.contains("80x60"),
        "{err}"
    );
}

#[test]
fn unreadable_png() {
    let err = check_fails(|d| {
        std::fs::write(
            d.join("data/tripod/frames/cam01/000000.png"),
            b"\x89PNG\r\n\x1a\nnot really",
        )
        .unwrap()
    });
    assert!(
        err.contains("cam01/000000.png") && err.contains("cannot read the image"),
        "{err}"
    );
}

#[test]
fn pipeline_yaml_with_unknown_key_names_key_and_line() {
    let err = check_fails(|d| {
        let p = d.join("pipeline.yaml");
        let text = std::fs::read_to_string(&p).unwrap();
        std::fs::write(&p, format!("{text}voxle_size: 0.01\n")).unwrap();
    });
    assert!(
        err.contains("pipeline.yaml") && err.contains("voxle_size") && err.contains("line"),
        "{err}"
    );
}

#[test]
fn fit_solver_setting_out_of_range_names_the_key() {
    for (setting, key) in [
        ("  stop:\n    tolerance: 0\n", "tolerance"),
        ("  stop:\n    max_rounds: 0\n", "max_rounds"),
        ("  contact:\n    tau_c: -1\n", "tau_c"),
        ("  restart:\n    turn_deg: 200\n", "turn_deg"),
        ("  hidden_hold: 1\n", "hidden_hold"),
        ("  solver: direct\n", "solver"),
        ("  model_spacing: -0.01\n", "model_spacing"),
        ("  sample_spacing: -1\n", "sample_spacing"),
    ] {
        let err = check_fails(|d| {
            let p = d.join("pipeline.yaml");
            let text = std::fs::read_to_string(&p).unwrap();
            std::fs::write(&p, format!("{text}fit:\n{setting}")).unwrap();
        });
        assert!(err.contains("pipeline.yaml") && err.contains(key), "{err}");
    }
}

#[test]
fn bench_track_output_in_a_missing_folder_fails_before_tracking() {
    let dir = tempfile::tempdir().unwrap();
    copy_tree(pristine(), dir.path());
    // Nothing is cached: the error must come before the tracking looks for the model.
    let (ok, _out, err) = run_cli(
        &[
            "bench",
            "track",
            "pipeline.yaml",
            "--rounds",
            "no/such/rounds.csv",
        ],
        dir.path(),
    );
    assert!(!ok && !err.contains("panicked"), "{err}");
    assert!(
        err.contains("--rounds no/such/rounds.csv") && err.contains("does not exist"),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "one clear error line: {err}");
}

/// `pipeline check` tests skeleton.yaml against the reference frame's cached surface before
/// any long run: not tested before the hull exists, passed by the true skeleton, and a bone
/// moved out of the body is refused by name.
#[test]
fn check_tests_the_skeleton_against_the_cached_reference_surface() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    copy_sample(d);
    let (ok, out, err) = run_cli(&["check", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    assert!(out.contains("skeleton: not tested yet"), "{out}");
    let (ok, _, err) = run_cli(
        &[
            "run",
            "pipeline.yaml",
            "--until",
            "visual_hull",
            "--frames",
            "0..0",
        ],
        d,
    );
    assert!(ok, "{err}");
    let (ok, out, err) = run_cli(&["check", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    assert!(out.contains("every bone lies inside"), "{out}");
    assert!(out.contains("visual_hull/000000.ply"), "{out}");
    // Lift the whole skeleton 0.8 m, out of the body.
    let path = d.join("data/tripod/skeleton.yaml");
    let text = std::fs::read_to_string(&path).unwrap();
    let mut skeleton = hullpose::skeleton::Skeleton::parse(&path, &text).unwrap();
    let away = nalgebra::Vector3::new(0.0, 0.0, 0.8);
    for bone in &mut skeleton.bones {
        (bone.head, bone.tail) = (bone.head + away, bone.tail + away);
    }
    let name = skeleton.bones[0].name.clone();
    skeleton.write(&path).unwrap();
    let (ok, _, err) = run_cli(&["check", "pipeline.yaml"], d);
    assert!(!ok && !err.contains("panicked"), "{err}");
    assert!(
        err.contains(&format!("bone '{name}' lies outside")),
        "{err}"
    );
    assert!(err.contains("skeleton.yaml"), "{err}");
}
