//! What `pipeline check` says about a rig before any work: how much of the first frame's
//! hull surface two or more cameras see (a sparse rig is warned about by name), and every
//! camera whose images are not the size its calibration states, named at once.

use crate::common;

use common::*;
use std::path::Path;

/// Keeps the sample's cameras at 1-based positions `keep` in its calibration.
fn keep_cameras(d: &Path, keep: &[usize]) {
    let calib = d.join("calib/cameras.yaml");
    let text = std::fs::read_to_string(&calib).unwrap();
    let parts: Vec<&str> = text.split("  - name:").collect();
    let mut kept = vec![parts[0]];
    kept.extend(keep.iter().map(|&i| parts[i]));
    std::fs::write(&calib, kept.join("  - name:")).unwrap();
}

/// The percentage `check` prints on its coverage line.
fn coverage(out: &str) -> f64 {
    let line = out
        .lines()
        .find(|l| l.starts_with("coverage: "))
        .unwrap_or_else(|| panic!("no coverage line: {out}"));
    line["coverage: ".len()..line.find('%').unwrap()]
        .parse()
        .unwrap()
}

#[test]
fn a_sparse_rig_is_named_by_the_share_two_cameras_see() {
    let dir = process_tempdir();
    let d = dir.path();
    copy_sample(d);
    let (ok, out, err) = run_cli(&["check", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    let all = coverage(&out);
    assert!(all >= 80.0, "15 cameras: {all}%");
    assert!(!err.contains("seen by two or more"), "{err}");

    // Four cameras about 90 degrees apart: most of the surface has one view.
    keep_cameras(d, &[1, 5, 9, 13]);
    let (ok, out, err) = run_cli(&["check", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    let four = coverage(&out);
    assert!(four < 20.0, "4 cameras: {four}%");
    assert!(
        err.contains("warning: only") && err.contains("seen by two or more cameras"),
        "{err}"
    );
}

#[test]
fn every_camera_whose_images_differ_from_its_calibration_is_named() {
    let dir = process_tempdir();
    let d = dir.path();
    copy_sample(d);
    let calib = d.join("calib/cameras.yaml");
    let text = std::fs::read_to_string(&calib).unwrap();
    std::fs::write(&calib, text.replace("width: 256", "width: 264")).unwrap();
    let (ok, _, err) = run_cli(&["check", "pipeline.yaml"], d);
    assert!(!ok);
    assert!(
        err.contains("15 cameras' images") && err.contains("'cam00'") && err.contains("'cam14'"),
        "{err}"
    );
    assert!(err.contains("256x192, calibrated 264x192"), "{err}");
}

#[test]
fn masks_that_take_the_room_for_the_subject_are_named_by_camera() {
    let dir = process_tempdir();
    let d = dir.path();
    copy_sample(d);
    // Every camera's mask of frame 0 marks all but a thin border: the room as the subject.
    let masks = d.join("data/tripod/masks");
    for cam in std::fs::read_dir(&masks).unwrap() {
        let path = cam.unwrap().path().join("000000.png");
        let (w, h) = image::image_dimensions(&path).unwrap();
        let border = 6;
        let img = image::GrayImage::from_fn(w, h, |x, y| {
            let inside = x >= border && y >= border && x + border < w && y + border < h;
            image::Luma([if inside { 255 } else { 0 }])
        });
        img.save(&path).unwrap();
    }
    let yaml = d.join("pipeline.yaml");
    let text = std::fs::read_to_string(&yaml).unwrap();
    std::fs::write(&yaml, text.replace("frames: all", "frames: 0..0")).unwrap();
    let (ok, _, err) = run_cli(&["check", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    assert!(
        err.contains("far larger than a person")
            && err.contains("'cam00' (")
            && err.contains("cover most of their image"),
        "{err}"
    );
}
