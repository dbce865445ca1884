//! Stage 6 on exact observations: with the true surface observed, the fit recovers the
//! true pose from the previous frame's (`proposed`'s Gauss-Newton rounds and the
//! baselines' point-to-point rounds); a frame without observation keeps the previous pose
//! and is flagged; damaged observations never put NaN into a pose; a lost fit's restarts
//! never repeat a start; the round log records the rounds the fit did.

use hullpose::fit::{
    FitDiagnostics, FitParams, FitStatus, Fitter, Method, Observation, RoundKind, RoundRecord,
};
use hullpose::skeleton::{pose::joints, Pose, Skeleton};
use hullpose::synth::{SceneKind, SynthOptions};
use nalgebra::Vector3;
use std::path::Path;

/// The tripod's skeleton, true poses and true meshes (two small cameras: only the ground
/// truth is used here).
fn truth() -> (tempfile::TempDir, Skeleton, Vec<(u32, Pose)>) {
    let dir = tempfile::tempdir().unwrap();
    let mut opts = SynthOptions::new(SceneKind::Tripod, dir.path());
    opts.cameras = 2;
    opts.width = 64;
    opts.height = 48;
    hullpose::synth::generate(&opts).unwrap();
    let data = dir.path().join("data/tripod");
    let skeleton = Skeleton::read(&data.join("skeleton.yaml")).unwrap();
    let poses = hullpose::poses::read(&data.join("ground_truth/poses.csv"), &skeleton).unwrap();
    (dir, skeleton, poses)
}

fn mesh(dir: &Path, frame: u32) -> hullpose::geometry::TriMesh {
    hullpose::geometry::ply::read_ply(
        &dir.join(format!("data/tripod/ground_truth/meshes/{frame:06}.ply")),
    )
    .unwrap()
}

fn observe(m: &hullpose::geometry::TriMesh) -> Observation {
    Observation {
        vertices: m.vertices.clone(),
        normals: m.vertex_normals(),
        rho_p: vec![0.9; m.vertices.len()],
    }
}

/// Mean distance between the joints of two poses, metres.
fn joint_error(s: &Skeleton, a: &Pose, b: &Pose) -> f64 {
    let (ja, jb) = (joints(s, a), joints(s, b));
    ja.iter()
        .zip(&jb)
        .map(|(x, y)| (x.0 - y.0).norm() + (x.1 - y.1).norm())
        .sum::<f64>()
        / (2 * ja.len()) as f64
}

/// The rounds a fit recorded (`pipeline bench track --rounds`) are the rounds it did: one
/// per counted round, numbered in order; each kept Anderson extrapolation (the baselines)
/// lowered eq. 4 below the pose it started from; the result is the last round's pose
/// (baselines, which stop when it moved less than the tolerance) or the recorded pose with
/// the lowest eq. 4 (`proposed`).
fn check_round_log(log: &[RoundRecord], r: &hullpose::fit::FitResult, method: Method) {
    assert_eq!(log.len(), r.diagnostics.iterations, "{method:?}");
    let mut current: Option<f64> = None;
    for (k, x) in log.iter().enumerate() {
        assert_eq!((x.start, x.round), (0, k + 1), "{method:?}");
        assert!(x.energy.is_finite() && x.energy > 0.0 && x.moved.is_finite());
        if x.kind == RoundKind::Extrapolated {
            assert!(method != Method::Proposed);
            assert!(x.energy < current.expect("never the first round"));
        }
        current = Some(x.energy);
    }
    let params = FitParams::default();
    let (tolerance, _) = params.stopping(method);
    if method == Method::Proposed {
        let lowest = log
            .iter()
            .min_by(|a, b| a.energy.total_cmp(&b.energy))
            .expect("a round");
        assert_eq!(lowest.pose, r.pose);
    } else {
        let last = log.last().expect("a round");
        assert_eq!(last.pose, r.pose);
        assert!(last.moved < tolerance);
    }
}

#[test]
fn exact_observations_give_the_true_pose_and_bad_ones_keep_the_previous() {
    let probe = hullpose::fit::Probe::default();
    let (dir, skeleton, poses) = truth();
    let model =
        hullpose::skeleton::model::build(&skeleton, &mesh(dir.path(), 0), &Default::default())
            .unwrap();
    for method in [Method::Proposed, Method::Icp] {
        let fitter = Fitter::new(
            &model,
            FitParams {
                method,
                ..Default::default()
            },
        );
        // From the previous true pose to this frame's, over the motion's hardest frames.
        for f in [5u32, 9, 13] {
            let r = fitter.fit(
                &observe(&mesh(dir.path(), f)),
                &poses[f as usize - 1].1,
                &probe,
            );
            let e = joint_error(&skeleton, &r.pose, &poses[f as usize].1);
            eprintln!("{method:?} t{f}: {:.2} mm, {:?}", e * 1000.0, r.diagnostics);
            assert!(e < 0.004, "{method:?} t{f}: joint error {e} m");
            assert_eq!(r.diagnostics.status, FitStatus::Converged);
            check_round_log(&probe.take_rounds(), &r, method);
        }
    }
    let fitter = Fitter::new(&model, FitParams::default());
    let previous = poses[4].1.clone();
    // The round log as CSV: a row per round, its error against the truth as measured here.
    let r = fitter.fit(&observe(&mesh(dir.path(), 5)), &previous, &probe);
    let log: Vec<(u32, RoundRecord)> = probe.take_rounds().into_iter().map(|x| (5, x)).collect();
    let truth_rows = hullpose::stages::fit::joint_rows(&skeleton, 5, &poses[5].1);
    let csv =
        hullpose::bench::rounds_csv(&skeleton, &log, Some((&truth_rows, dir.path()))).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines[0], hullpose::bench::ROUNDS_HEADER);
    assert_eq!(lines.len(), r.diagnostics.iterations + 1);
    let last_error: f64 = lines
        .last()
        .unwrap()
        .rsplit(',')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    let e = joint_error(&skeleton, &r.pose, &poses[5].1) * 100.0;
    assert!(
        (last_error - e).abs() < 1e-4,
        "{last_error} cm logged, {e} cm measured"
    );
    // No observation (the subject out of view): the previous pose, flagged.
    let r = fitter.fit(&Observation::default(), &previous, &probe);
    assert_eq!(r.diagnostics.status, FitStatus::NoObservation);
    assert_eq!(r.pose, previous);
    // Too little observed surface (a sliver): the same.
    let mut sliver = observe(&mesh(dir.path(), 5));
    sliver.vertices.truncate(50);
    sliver.normals.truncate(50);
    sliver.rho_p.truncate(50);
    assert_eq!(
        fitter.fit(&sliver, &previous, &probe).diagnostics.status,
        FitStatus::NoObservation
    );
    // NaN in the observation never reaches the pose.
    let mut damaged = observe(&mesh(dir.path(), 5));
    for i in (0..damaged.vertices.len()).step_by(7) {
        damaged.vertices[i] = Vector3::repeat(f64::NAN);
        damaged.rho_p[i + 1] = f64::NAN;
    }
    let r = fitter.fit(&damaged, &previous, &probe);
    assert!(r.pose.is_finite());
    assert!(r.diagnostics.energy.is_finite() && r.diagnostics.rms.is_finite());
    assert!(joint_error(&skeleton, &r.pose, &poses[5].1) < 0.004);
    // A fit that hits the round cap (with the previous frame's score unknown, or its own
    // score above 3 times that) is tried again from the other starts, each once: from the
    // reference pose (the frame after t0) the other starts are that same pose, so none;
    // with a frame further back, the previous pose and the reference pose at its root.
    let capped_at = |max_rounds, rounds_factor| {
        let mut params = FitParams::default();
        params.stop.max_rounds = max_rounds;
        params.restart.rounds_factor = rounds_factor;
        Fitter::new(&model, params)
    };
    let capped = capped_at(2, 2);
    let obs = observe(&mesh(dir.path(), 1));
    let reference = Pose::rest(skeleton.bones.len());
    let r = capped.fit_tracked(&obs, &reference, None, None, None, &probe);
    assert_eq!(r.diagnostics.status, FitStatus::IterationCap);
    assert_eq!(r.diagnostics.iterations, 2);
    let obs = observe(&mesh(dir.path(), 6));
    let r = capped.fit_tracked(&obs, &poses[5].1, Some(&poses[4].1), None, None, &probe);
    assert_eq!(r.diagnostics.iterations, 2 + 4 + 4);
    let previous_fit = |score: f64| FitDiagnostics {
        score,
        ..FitDiagnostics::unfitted(FitStatus::Converged, obs.vertices.len())
    };
    let far_lower = previous_fit(r.diagnostics.score / 10.0);
    let r = capped.fit_tracked(
        &obs,
        &poses[5].1,
        Some(&poses[4].1),
        Some(&far_lower),
        None,
        &probe,
    );
    assert_eq!(r.diagnostics.iterations, 2 + 4 + 4);
    // A capped fit whose score did not rise above the previous frame's is kept as it is.
    let higher = previous_fit(r.diagnostics.score * 100.0);
    let r = capped.fit_tracked(
        &obs,
        &poses[5].1,
        Some(&poses[4].1),
        Some(&higher),
        None,
        &probe,
    );
    assert_eq!(r.diagnostics.iterations, 2);
    // Restarts have a cap of their own (`restart.rounds_factor` times the cap); from these
    // starts they may converge before it.
    let r = capped_at(2, 3).fit_tracked(&obs, &poses[5].1, Some(&poses[4].1), None, None, &probe);
    let rounds = r.diagnostics.iterations;
    assert!(rounds > 2 + 2 && rounds <= 2 + 6 + 6, "{rounds} rounds");
}
