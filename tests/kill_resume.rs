//! A run killed (SIGKILL) while any stage is computing, then resumed, leaves exactly what a
//! fresh run leaves: every output file and every cached artifact, byte for byte (the
//! manifests aside, which record seconds). Frames 0..2 of the bundled sample keep it small.

mod common;

use common::*;
use std::collections::BTreeMap;
use std::path::Path;

/// Every file under `dir` but the manifests and the lock, with its bytes.
fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            let name = p.file_name().unwrap().to_string_lossy().to_string();
            if p.is_dir() {
                stack.push(p);
            } else if !name.ends_with(".manifest.yaml") && name != ".lock" {
                let rel = p.strip_prefix(dir).unwrap().display().to_string();
                out.insert(rel, std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

fn project(dir: &Path) {
    copy_sample(dir);
    let path = dir.join("pipeline.yaml");
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::write(path, text.replace("frames: all", "frames: 0..2")).unwrap();
}

/// The committed artifacts of `stage` in `dir`'s cache.
fn committed(dir: &Path, stage: &str) -> usize {
    std::fs::read_dir(dir.join("cache").join(stage)).map_or(0, |d| {
        d.flatten()
            .filter(|e| e.file_name().to_string_lossy().ends_with(".manifest.yaml"))
            .count()
    })
}

#[test]
fn a_run_killed_during_any_stage_and_resumed_equals_a_fresh_run() {
    let outer = tempfile::tempdir().unwrap();
    let fresh = outer.path().join("fresh");
    project(&fresh);
    let (ok, _, err) = run_cli(&["run", "pipeline.yaml"], &fresh);
    assert!(ok, "{err}");
    let (out_ref, cache_ref) = (files(&fresh.join("output")), files(&fresh.join("cache")));
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
        let mut child = std::process::Command::new(pipeline_bin())
            .args(["run", "pipeline.yaml"])
            .current_dir(&dir)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        // Killed as soon as the stage has committed its first artifact (or when the run
        // ends first, which the resume then reuses).
        let started = std::time::Instant::now();
        while started.elapsed().as_secs() < 120
            && committed(&dir, stage) == 0
            && child.try_wait().unwrap().is_none()
        {
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        let _ = child.kill();
        let _ = child.wait();
        let (ok, _, err) = run_cli(&["run", "pipeline.yaml"], &dir);
        assert!(ok, "{stage}: {err}");
        let (out, cache) = (files(&dir.join("output")), files(&dir.join("cache")));
        assert_eq!(
            cache.keys().collect::<Vec<_>>(),
            cache_ref.keys().collect::<Vec<_>>(),
            "killed during {stage}: other cache files"
        );
        for (path, bytes) in &cache {
            assert!(
                bytes == &cache_ref[path],
                "killed during {stage}: cache/{path} differs from a fresh run's"
            );
        }
        assert_eq!(
            out.keys().collect::<Vec<_>>(),
            out_ref.keys().collect::<Vec<_>>(),
            "killed during {stage}: other output files"
        );
        for (path, bytes) in &out {
            assert!(
                bytes == &out_ref[path],
                "killed during {stage}: output/{path} differs from a fresh run's"
            );
        }
    }
}
