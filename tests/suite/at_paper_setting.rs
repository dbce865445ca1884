//! The tripod at the paper's setting (15 cameras, 1024x768, 1 cm voxels, t0..t18), run
//! once through the whole pipeline: stage 4 (ZNCC tells the true surface from phantom
//! volume and bridges) and stage 6 (the robust fit and the baselines it is compared with).

use crate::common;

use common::*;
use hullpose::synth::{SceneKind, SynthOptions};
use std::sync::OnceLock;

/// The full tripod sequence, reconstructed through the body model and evaluated once for
/// all tests here (the fit test runs the fit stage beside the baselines).
fn run_tripod() -> &'static (tempfile::TempDir, String) {
    static CELL: OnceLock<(tempfile::TempDir, String)> = OnceLock::new();
    CELL.get_or_init(|| {
        let dir = process_tempdir();
        hullpose::synth::generate(&SynthOptions::new(SceneKind::Tripod, dir.path())).unwrap();
        let (ok, out, err) = run_cli(&["run", "pipeline.yaml", "--until", "model"], dir.path());
        assert!(ok, "{err}");
        eprintln!("{out}");
        let (ok, out, err) = run_cli(&["evaluate", "pipeline.yaml"], dir.path());
        assert!(ok, "{err}");
        eprintln!("{out}");
        (dir, out)
    })
}

/// Mean joint error per frame (cm) of a joints CSV against the ground truth.
fn errors_cm(d: &std::path::Path, rows: &[hullpose::joints::JointRow]) -> Vec<f64> {
    let truth_path = d.join("data/tripod/ground_truth/joints.csv");
    let truth = hullpose::joints::read(&truth_path).unwrap();
    hullpose::eval::pose::joint_errors(&truth, rows, &truth_path)
        .unwrap()
        .into_iter()
        .map(|x| x.1 * 100.0)
        .collect()
}

#[test]
fn zncc_separates_true_from_false_surface() {
    let (dir, _) = run_tripod();
    let d = dir.path();
    let csv = std::fs::read_to_string(d.join("output/evaluation/reliability.csv")).unwrap();
    let rows: Vec<Vec<f64>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 19);
    // On every frame, where ZNCC is defined (two or more cameras see the vertex), the issue's
    // bound is 0.9.
    for r in &rows {
        assert!(
            r[6] >= 0.95,
            "t{}: ROC AUC over seen vertices {}",
            r[0],
            r[6]
        );
    }
    for r in rows
        .iter()
        .filter(|r| [6.0, 7.0, 8.0, 11.0, 12.0, 13.0].contains(&r[0]))
    {
        let (frame, false_vertices, auc, rho_false, rho_true) = (r[0], r[2], r[3], r[4], r[5]);
        assert!(false_vertices > 1000.0, "t{frame}: phantom volume present");
        assert!(auc >= 0.85, "t{frame}: ROC AUC {auc}");
        assert!(
            rho_false < 0.2,
            "t{frame}: mean rho_p of false vertices {rho_false}"
        );
        assert!(
            rho_true > 0.4,
            "t{frame}: mean rho_p of true seen vertices {rho_true}"
        );
    }
    // The artifacts: a PLY MeshLab reads (quality = ZNCC) and the compact form agree.
    let ply = std::fs::read(d.join("cache/reliability/000008.ply")).unwrap();
    let header = String::from_utf8_lossy(&ply[..ply.len().min(600)]).to_string();
    for prop in ["quality", "zncc", "rho_p", "cameras", "red"] {
        assert!(header.contains(&format!(" {prop}\n")), "{prop} in {header}");
    }
    let cache = hullpose::cache::Cache::new(d.join("cache"));
    let obs = hullpose::artifacts::observation::read(&cache, 8).unwrap();
    let mesh = hullpose::geometry::ply::read_ply(&d.join("cache/graphcut/000008.ply")).unwrap();
    assert_eq!(obs.vertices.len(), mesh.vertices.len());
    assert!(obs.zncc.iter().all(|z| (-1.0..=1.0).contains(z)));
    assert!(obs
        .zncc
        .iter()
        .zip(&obs.cameras)
        .all(|(&z, &c)| c >= 2 || z == -1.0));
    assert!(obs
        .rho_p
        .iter()
        .all(|r| r.is_finite() && *r > 0.0 && *r < 1.0));
}

/// The fit at the paper's setting: the proposed method against the truth, and the baselines
/// where the scene makes them fail.
#[test]
fn proposed_fit_tracks_the_tripod_where_baselines_slip() {
    let (dir, _) = run_tripod();
    let d = dir.path();
    // The baselines over the same cached reconstruction.
    let config = hullpose::config::Config::load(&d.join("pipeline.yaml")).unwrap();
    let job = hullpose::runner::Job::load(config, None).unwrap();
    let ctx = job.context();
    let tracked = job.tracked_frames().unwrap();
    let model = hullpose::artifacts::body_model::read(ctx.cache).unwrap();
    // Tracked from t0 up to frame `last` (rho_p is only needed up to the contact frames).
    let baseline = |params: hullpose::fit::FitParams, last: u32| {
        let frames: Vec<u32> = tracked.iter().copied().filter(|&f| f <= last).collect();
        errors_cm(
            d,
            &tracked_joint_rows(&ctx, &model.skeleton, &frames, &params),
        )
    };
    // The fit stage (method `proposed`, every frame) and the four baselines side by side:
    // each round's serial parts (LM steps, trees) of one overlap with the others' parallel
    // searches.
    // Also `proposed` under neutral changes of its stopping rule (the tolerance halved and
    // doubled, the round cap doubled), over every frame: the bounds must not hinge on them.
    // The baselines start from the constant-velocity prediction, as in the README's table,
    // and run as the paper ran them: without the restarts and recovery this project adds
    // (which cost the `normals` baseline 6 s on each phantom frame in a release build and do
    // not save it).
    use hullpose::fit::{FitParams, Method, Start};
    let method = |method| {
        let mut p = FitParams {
            method,
            start: Start::Predicted,
            ..Default::default()
        };
        p.restart.enabled = false;
        p
    };
    let neutral = |tolerance_factor: f64, cap_factor: usize| {
        let mut p = FitParams::default();
        p.stop.tolerance *= tolerance_factor;
        p.stop.max_rounds *= cap_factor;
        p
    };
    let runs = [
        (method(Method::Icp), 11),
        (method(Method::Normals), 11),
        (method(Method::RhoC), 8),
        (method(Method::RhoP), 10),
        (neutral(0.5, 1), 18),
        (neutral(2.0, 1), 18),
        (neutral(1.0, 2), 18),
    ];
    let (fit_run, [icp, normals, rho_c, rho_p, halved, doubled, longer]) =
        std::thread::scope(|s| {
            let fit_run = s.spawn(|| {
                let (ok, out, err) = run_cli(&["run", "pipeline.yaml", "--only", "fit"], d);
                assert!(ok, "{err}");
                let (ok, eval, err) = run_cli(&["evaluate", "pipeline.yaml"], d);
                assert!(ok, "{err}");
                format!("{out}\n{eval}")
            });
            let baseline = &baseline;
            let handles = runs.map(|(params, last)| s.spawn(move || baseline(params, last)));
            (fit_run.join().unwrap(), handles.map(|h| h.join().unwrap()))
        });
    eprintln!("{fit_run}");
    // The run's outputs: joints for every frame and bone, finite; a converged fit per frame.
    let rows = hullpose::joints::read(&d.join("output/joints.csv")).unwrap();
    assert_eq!(rows.len(), 19 * 6);
    assert!(rows
        .iter()
        .all(|r| r.head.iter().chain(r.tail.iter()).all(|v| v.is_finite())));
    let diag_path = d.join("output/fit.csv");
    let diag = hullpose::stages::fit::parse_diagnostics(
        &diag_path,
        &std::fs::read_to_string(&diag_path).unwrap(),
    )
    .unwrap();
    assert_eq!(diag.len(), 19);
    // Every tracked frame fitted (a contact frame may end at the round cap after the
    // restarts; its accuracy is asserted below).
    assert!(diag[1..].iter().all(|x| matches!(
        x.1.status,
        hullpose::fit::FitStatus::Converged | hullpose::fit::FitStatus::IterationCap
    )));
    assert!(d.join("cache/fit/000009.ply").is_file());
    assert!(d.join("output/evaluation/joint_error.png").is_file());
    let proposed = errors_cm(d, &rows);
    eprintln!("proposed: {proposed:.2?}");
    eprintln!("icp: {icp:.2?}\nnormals: {normals:.2?}\nrho_c: {rho_c:.2?}\nrho_p: {rho_p:.2?}");
    eprintln!("proposed, tolerance halved: {halved:.2?}\ndoubled: {doubled:.2?}");
    eprintln!("proposed, round cap doubled: {longer:.2?}");
    // The paper's Fig. 8: ICP and Ogawara's normal test slip both where the phantom volume
    // forms (t6-t8, t11-t13) and where the lower arms press together (t9-t10); rho_c alone
    // on the phantom frames, rho_p alone on the contact frames.
    let worst = |e: &[f64], frames: &[usize]| frames.iter().map(|&f| e[f]).fold(0.0, f64::max);
    let (phantom, contact) = ([6, 7, 8, 11], [9, 10]);
    let all: Vec<usize> = (0..19).collect();
    // Within 1 cm on every frame (the paper's result; the README's table) and 0.35 cm on
    // average (0.165 now; 0.36 before the surfaces lay on the silhouette cones).
    for (name, e) in [
        ("default", &proposed),
        ("tolerance halved", &halved),
        ("tolerance doubled", &doubled),
        ("round cap doubled", &longer),
    ] {
        let proposed_worst = worst(e, &all);
        assert!(
            proposed_worst <= 1.0,
            "proposed, {name}: worst {proposed_worst}"
        );
        let mean = e.iter().sum::<f64>() / e.len() as f64;
        assert!(mean <= 0.35, "proposed, {name}: mean {mean:.3} cm: {e:.2?}");
    }
    // A baseline slips on frames when its worst error there is over 1.5 cm and 4 times
    // `proposed`'s. (With the surfaces and the model on the silhouette cones rather than a
    // voxel outside them, the baselines slip 1.8-6.5 cm there, `proposed` stays within
    // 0.4 cm; before, with everything a voxel too fat, they slipped over 3 cm.)
    let slips = |e: &[f64], frames: &[usize]| {
        let w = worst(e, frames);
        w > 1.5 && w > 4.0 * worst(&proposed, frames)
    };
    assert!(slips(&icp, &phantom), "icp on phantom frames {icp:.2?}");
    assert!(slips(&icp, &contact), "icp on contact frames {icp:.2?}");
    // Ogawara's normal test pairs a vertex with the nearest one whose normal agrees, which
    // may lie on the phantom or on the far side of the touching part (Fig. 12).
    assert!(
        slips(&normals, &phantom),
        "normals on phantom frames {normals:.2?}"
    );
    assert!(
        slips(&normals, &contact),
        "normals on contact frames {normals:.2?}"
    );
    assert!(
        slips(&rho_c, &[6, 7, 8]),
        "rho_c on phantom frames {rho_c:.2?}"
    );
    assert!(
        slips(&rho_p, &contact),
        "rho_p on contact frames {rho_p:.2?}"
    );
}
