//! The real dancer (`../shared/realdata/dancer`: a dress, 8 cameras, real masks, frames
//! 0..99, no skeleton): `pipeline skeleton` without `--frame` chooses a frame and embeds
//! the humanoid template in it. Measured against what the capture has: the silhouettes
//! (every joint inside the mask, dilated by 5 px, in at least 7 of 8 cameras) and the
//! body's symmetry (left and right limbs within 10% of each other).

use crate::common;

use common::*;
use hullpose::skeleton::Skeleton;
use std::path::{Path, PathBuf};

fn dancer() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/realdata/dancer")
}

/// A copy of the dancer's calibration and masks (skeleton.yaml is written beside them)
/// with a masks-only pipeline.yaml; `None` (a note) when the capture is not present,
/// a failure under `CI=true`, where it always is.
fn dancer_copy(to: &Path) -> bool {
    let from = dancer();
    if !from.exists() {
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "{} is missing, and CI always has it",
            from.display()
        );
        eprintln!("skipped: {} is not present", from.display());
        return false;
    }
    copy_tree(&from.join("calib"), &to.join("calib"));
    copy_tree(&from.join("data"), &to.join("data"));
    std::fs::write(
        to.join("pipeline.yaml"),
        "calibration: calib/cameras.yaml\nsequence: data/dancer\nframes: 0..99\n\
         cache: cache\noutput: output\nsilhouette:\n  clean_given: true\n",
    )
    .unwrap();
    true
}

#[test]
fn the_dancer_gets_a_skeleton_the_silhouettes_and_her_symmetry_agree_with() {
    let dir = process_tempdir();
    let d = dir.path();
    if !dancer_copy(d) {
        return;
    }
    // No up is given: the tool finds it from the cameras (her world's +z within a degree).
    let (ok, out, err) = run_cli(&["skeleton", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    eprintln!("{out}{err}");
    let up = out
        .lines()
        .find(|l| l.starts_with("up (found, no up given): ("))
        .unwrap_or_else(|| panic!("no up line: {out}"));
    let start = "up (found, no up given): (".len();
    let v: Vec<f64> = up[start..start + up[start..].find(')').unwrap()]
        .split(", ")
        .map(|x| x.parse().unwrap())
        .collect();
    assert!(v[2] > 1f64.to_radians().cos(), "{up}");
    let skeleton = Skeleton::read(&d.join("data/dancer/skeleton.yaml")).unwrap();
    assert_eq!(skeleton.bones.len(), 17);
    let frame = skeleton.reference_frame;

    let config = hullpose::config::Config::load(&d.join("pipeline.yaml")).unwrap();
    let job = hullpose::runner::Job::load(config, None).unwrap();
    let cams = &job.sequence.cameras;
    let masks: Vec<image::GrayImage> = (0..cams.len())
        .map(|c| {
            image::open(job.sequence.mask_path(c, frame))
                .unwrap()
                .to_luma8()
        })
        .collect();
    for (joint, seen) in hullpose::autoskeleton::joint_views(cams, &masks, &skeleton) {
        assert!(
            seen + 1 >= cams.len(),
            "{joint}: in {seen} of 8 masks\n{out}"
        );
    }
    for (limb, left, right) in hullpose::autoskeleton::limb_lengths(&skeleton) {
        assert!(
            (left - right).abs() <= 0.1 * left.max(right),
            "{limb}: {left:.3} / {right:.3} m"
        );
    }
    // The dancer is 1.6-1.75 m tall (README of the capture); the template's joints span
    // 93% of a body's height.
    let z: Vec<f64> = skeleton
        .bones
        .iter()
        .flat_map(|b| [b.head.z, b.tail.z])
        .collect();
    let height =
        z.iter().cloned().fold(f64::MIN, f64::max) - z.iter().cloned().fold(f64::MAX, f64::min);
    assert!((1.4..1.7).contains(&height), "joints span {height:.2} m");
}
