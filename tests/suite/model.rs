//! Stage 5: the skin-bone model built at t0 and posed with the true poses reproduces the
//! true surface of every frame; bad skeletons and surfaces are refused clearly.

use crate::common;

use common::*;
use hullpose::geometry::nearest::NearestTree;
use hullpose::skeleton::model::BodyModel;
use hullpose::skeleton::Skeleton;
use nalgebra::Vector3;
use std::path::Path;

fn load_model(dir: &Path) -> BodyModel {
    hullpose::artifacts::body_model::read(&hullpose::cache::Cache::new(dir.join("cache"))).unwrap()
}

/// Per frame, the mean distance (metres) from the model posed with the frame's true pose
/// to the true surface, over the model vertices farther than `clearance` from every joint
/// at t0 (the heads of non-root bones and of the root).
fn posing_errors(made: &Made, seq: &str, model: &BodyModel, clearance: f64) -> Vec<(u32, f64)> {
    let data = made.root.join("data").join(seq);
    let skeleton = Skeleton::read(&data.join("skeleton.yaml")).unwrap();
    let poses = hullpose::poses::read(&data.join("ground_truth/poses.csv"), &skeleton).unwrap();
    let joints: Vec<Vector3<f64>> = skeleton.bones.iter().map(|b| b.head).collect();
    let away: Vec<usize> = (0..model.mesh.vertices.len())
        .filter(|&i| {
            joints
                .iter()
                .all(|j| (model.mesh.vertices[i] - j).norm() > clearance)
        })
        .collect();
    assert!(
        away.len() * 2 > model.mesh.vertices.len(),
        "most vertices kept"
    );
    poses
        .iter()
        .map(|(frame, pose)| {
            let truth = hullpose::geometry::ply::read_ply(
                &data.join(format!("ground_truth/meshes/{frame:06}.ply")),
            )
            .unwrap();
            let index = NearestTree::new(&hullpose::eval::sample_surface(&truth, 0.002));
            let posed = model.pose(pose);
            let sum: f64 = away
                .iter()
                .map(|&i| index.nearest(&posed.vertices[i]).unwrap().1.sqrt())
                .sum();
            (*frame, sum / away.len() as f64)
        })
        .collect()
}

/// Runs a folder's pipeline up to the model, on the reference frame only.
fn run_model(dir: &Path) -> (bool, String, String) {
    run_cli(
        &[
            "run",
            "pipeline.yaml",
            "--frames",
            "0..0",
            "--until",
            "model",
        ],
        dir,
    )
}

fn build(made: &Made, seq: &str, extra: &str) -> (tempfile::TempDir, BodyModel) {
    let dir = run_folder(made, seq, extra);
    let (ok, out, err) = run_model(dir.path());
    assert!(ok, "{err}");
    assert!(out.contains("model: 1 computed"), "{out}");
    let model = load_model(dir.path());
    (dir, model)
}

#[test]
fn model_from_the_reference_surface_reproduces_every_frame() {
    for (made, seq) in [(tripod(), "tripod"), (humanoid(), "humanoid")] {
        let (dir, model) = build(made, seq, "");
        assert!(dir.path().join("cache/model/model.ply").is_file());
        assert_eq!(model.labels.len(), model.mesh.vertices.len());
        assert!(model
            .weights
            .iter()
            .all(|w| (w.iter().map(|x| x.1).sum::<f64>() - 1.0).abs() < 1e-5));
        // Every bone owns part of the surface.
        for b in 0..model.skeleton.bones.len() {
            assert!(model.labels.contains(&b), "{seq}: bone {b} has no vertex");
        }
        let errors = posing_errors(made, seq, &model, 0.08);
        eprintln!("{seq}: {errors:?}");
        for (frame, e) in errors {
            assert!(
                e <= 0.015,
                "{seq} t{frame}: mean distance {e} m > 1.5 voxels"
            );
        }
    }
}

#[test]
fn model_from_a_supplied_mesh_is_exact_away_from_the_joints() {
    let made = tripod();
    let truth = made.root.join("data/tripod/ground_truth/meshes/000000.ply");
    let extra = format!("model:\n  mesh: {}\n", truth.display());
    let (_dir, model) = build(made, "tripod", &extra);
    let errors = posing_errors(made, "tripod", &model, 0.08);
    for (frame, e) in errors {
        assert!(e <= 0.002, "t{frame}: mean distance {e} m");
    }
}

#[test]
fn a_skeleton_outside_the_surface_is_refused() {
    let made = tripod();
    // A small closed box far from the skeleton, given as the subject's mesh.
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("box.obj");
    let mut text = String::new();
    for i in 0..8 {
        let (x, y, z) = ((i & 1) as f64, ((i >> 1) & 1) as f64, ((i >> 2) & 1) as f64);
        text += &format!("v {} {} {}\n", 5.0 + 0.1 * x, 5.0 + 0.1 * y, 0.1 * z);
    }
    for f in [
        [1, 3, 4, 2],
        [5, 6, 8, 7],
        [1, 2, 6, 5],
        [3, 7, 8, 4],
        [1, 5, 7, 3],
        [2, 4, 8, 6],
    ] {
        text += &format!("f {} {} {} {}\n", f[0], f[1], f[2], f[3]);
    }
    std::fs::write(&obj, text).unwrap();
    let run = run_folder(
        made,
        "tripod",
        &format!("model:\n  mesh: {}\n", obj.display()),
    );
    let (ok, _, err) = run_model(run.path());
    assert!(!ok);
    assert!(
        err.contains("box.obj") && err.contains("bone 'arm0_upper' lies outside"),
        "{err}"
    );
    assert!(!run.path().join("cache/model/model.hpm").exists());
}
