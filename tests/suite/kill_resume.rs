//! A run killed (SIGKILL) while any stage is computing, then resumed, leaves exactly what a
//! fresh run leaves: every output file and every cached artifact, byte for byte (the
//! manifests aside, which record seconds). Frames 0..2 of the bundled sample keep it small.

use crate::common;

use common::*;
use std::path::Path;

fn project(dir: &Path) {
    copy_sample(dir);
    let path = dir.join("pipeline.yaml");
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::write(path, text.replace("frames: all", "frames: 0..2")).unwrap();
}

#[test]
fn a_run_killed_during_any_stage_and_resumed_equals_a_fresh_run() {
    let outer = tempfile::tempdir().unwrap();
    let fresh = outer.path().join("fresh");
    project(&fresh);
    let (ok, _, err) = run_cli(&["run", "pipeline.yaml"], &fresh);
    assert!(ok, "{err}");
    let (out_ref, cache_ref) = (
        tree_files(&fresh.join("output")),
        tree_files(&fresh.join("cache")),
    );
    assert!(cache_ref.keys().any(|k| k.starts_with("fit/")));

    let stages = [
        (None, "silhouette"),
        (Some("silhouette"), "visual_hull"),
        (Some("visual_hull"), "graphcut"),
        (Some("graphcut"), "reliability"),
        (Some("reliability"), "model"),
        (Some("model"), "fit"),
    ];
    for (before, stage) in stages {
        let dir = outer.path().join(format!("killed-{stage}"));
        project(&dir);
        if let Some(before) = before {
            let (ok, _, err) = run_cli(&["run", "pipeline.yaml", "--until", before], &dir);
            assert!(ok, "{err}");
        }
        // Killed as soon as the stage has committed its first artifact (or when the run
        // ends first, which the resume then reuses).
        run_killed_when(&dir, || {
            count_files_ending(&dir.join("cache").join(stage), ".manifest.yaml") > 0
        });
        let (ok, _, err) = run_cli(&["run", "pipeline.yaml"], &dir);
        assert!(ok, "{stage}: {err}");
        let (out, cache) = (
            tree_files(&dir.join("output")),
            tree_files(&dir.join("cache")),
        );
        let what = format!("killed during {stage}, resumed, against a fresh run");
        assert_same_files(&cache, &cache_ref, "cache", &what);
        assert_same_files(&out, &out_ref, "output", &what);
    }
}
