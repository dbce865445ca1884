//! `pipeline pose-search` on the bundled sample (frames 0..2): it measures a pose as the
//! fit's health check does (the fitted pose's worst IoU is fit.csv's), finds nothing much
//! better near a good fit, finds a bone knocked 25 degrees off and turns it back, and
//! refuses a frame without a fit by name.

use crate::common;

use common::*;
use hullpose::eval::pose_search::{search, worst};
use nalgebra::{Rotation3, Vector3};

#[test]
fn pose_search_finds_a_knocked_bone_and_leaves_a_good_fit() {
    let dir = process_tempdir();
    let d = dir.path();
    copy_sample(d);
    let path = d.join("pipeline.yaml");
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::write(&path, text.replace("frames: all", "frames: 0..2")).unwrap();
    let (ok, _, err) = run_cli(&["run", "pipeline.yaml"], d);
    assert!(ok, "{err}");

    // The command: the fitted pose measured as fit.csv measured it.
    let (ok, out, err) = run_cli(
        &[
            "pose-search",
            "pipeline.yaml",
            "--frame",
            "2",
            "--tries",
            "200",
        ],
        d,
    );
    assert!(ok, "{err}");
    eprintln!("{out}");
    let fit_csv = std::fs::read_to_string(d.join("output/fit.csv")).unwrap();
    let row = fit_csv.lines().find(|l| l.starts_with("2,")).unwrap();
    let iou_worst = row.split(',').nth(10).unwrap();
    let line = out
        .lines()
        .find(|l| l.trim_start().starts_with("worst"))
        .unwrap();
    let fields: Vec<&str> = line.split_whitespace().collect();
    assert_eq!(fields[1], iou_worst, "{line} against fit.csv's {row}");
    let (fitted, found): (f64, f64) = (fields[1].parse().unwrap(), fields[4].parse().unwrap());
    // A good fit (within millimetres of the truth) sits at the silhouettes' optimum.
    assert!(found >= fitted && found - fitted < 0.005, "{line}");

    // A bone knocked 25 degrees off its fitted turn: the silhouettes see it, and the search
    // turns it back.
    let config = hullpose::config::Config::load(&path).unwrap();
    let job = hullpose::runner::Job::load(config, None).unwrap();
    let ctx = job.context();
    let mut judge = hullpose::stages::fit::FrameSilhouettes::load(&ctx, 2).unwrap();
    let good = worst(&judge.ious(&judge.fitted)).0;
    let fitted_pose = judge.fitted.clone();
    let bone = judge
        .model
        .skeleton
        .bones
        .iter()
        .position(|b| b.name == "arm1_upper")
        .unwrap();
    judge.fitted.rotations[bone] *=
        Rotation3::new(Vector3::new(1.0, 1.0, 0.0).normalize() * 25f64.to_radians());
    let knocked = worst(&judge.ious(&judge.fitted)).0;
    assert!(
        knocked < good - 0.05,
        "knocked {knocked:.4}, fitted {good:.4}"
    );
    let r = search(&judge, 300, &|_, _| {});
    let back = worst(&r.found).0;
    eprintln!(
        "knocked {knocked:.4} -> {back:.4} (fitted {good:.4}); moved {:?}",
        r.moved
    );
    // Nine tenths of the lost IoU regained, by moving the knocked limb most, and the limb's
    // tip back within 5 cm of the fit's (the 25-degree knock put it 30 cm off; 3.2 cm now).
    assert!(back > good - 0.1 * (good - knocked), "{back:.4}");
    assert!(r.moved[0].0.starts_with("arm1_"), "{:?}", r.moved);
    let skeleton = &judge.model.skeleton;
    let (a, b) = (
        hullpose::skeleton::pose::PosedBones::new(skeleton, &fitted_pose),
        hullpose::skeleton::pose::PosedBones::new(skeleton, &r.pose),
    );
    let tip = skeleton
        .bones
        .iter()
        .position(|b| b.name == "arm1_lower")
        .unwrap();
    let off = (a.tails[tip] - b.tails[tip]).norm();
    assert!(
        off < 0.05,
        "arm1's tip {:.1} cm from the fit's",
        100.0 * off
    );

    // A frame without a fit is refused by name.
    let (ok, _, err) = run_cli(&["pose-search", "pipeline.yaml", "--frame", "5"], d);
    assert!(!ok);
    assert!(
        err.contains("the cached fit result of frame 5 is missing"),
        "{err}"
    );

    // A hand-edited state (which `run` would recompute) is refused, never searched from.
    let state = d.join("cache/fit/000002.state.json");
    let text = std::fs::read_to_string(&state).unwrap();
    let digit = text.find(|c: char| c.is_ascii_digit() && c != '0').unwrap();
    let mut edited = text.clone();
    edited.replace_range(digit..digit + 1, "0");
    std::fs::write(&state, edited).unwrap();
    let (ok, out, err) = run_cli(&["pose-search", "pipeline.yaml", "--frame", "2"], d);
    assert!(!ok, "{out}");
    assert!(err.contains("fit result of frame 2 is damaged"), "{err}");
}
