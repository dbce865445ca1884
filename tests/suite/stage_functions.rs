//! The stages as functions: each per-frame stage, called directly with its settings and
//! its inputs, writes nothing (the cache is unchanged to the byte) and returns exactly the
//! artifact the runner committed for it; a stage asking for an artifact it does not
//! declare as an input is refused.

use crate::common;

use common::*;
use hullpose::artifacts::reconstruction::Surface;
use hullpose::stages::{Compute, STAGES};
use hullpose::synth::{SceneKind, SynthOptions};

#[test]
fn per_frame_stages_are_pure_functions_of_their_inputs() {
    let dir = process_tempdir();
    let d = dir.path();
    let mut options = SynthOptions::new(SceneKind::Tripod, d);
    (options.cameras, options.width, options.height) = (6, 240, 180);
    options.frames = Some(1);
    hullpose::synth::generate(&options).unwrap();
    let (ok, _, err) = run_cli(&["run", "pipeline.yaml", "--until", "reliability"], d);
    assert!(ok, "{err}");

    let config = hullpose::config::Config::load(&d.join("pipeline.yaml")).unwrap();
    let job = hullpose::runner::Job::load(config, None).unwrap();
    let ctx = job.context();
    let cache = d.join("cache");
    let mut checked = Vec::new();
    for def in STAGES {
        let Compute::Frame(stage) = def.compute else {
            continue;
        };
        if !std::path::Path::new(&cache.join(def.name)).is_dir() {
            continue;
        }
        let before = tree_files(&cache);
        let produced = stage.compute(&job.config, &ctx.inputs(def), 0).unwrap();
        assert_same_files(&before, &tree_files(&cache), "cache", def.name);
        // Written to a scratch folder, the artifact is the runner's, file for file.
        let scratch = tempfile::tempdir().unwrap();
        let files = produced.artifact.write(scratch.path(), 0).unwrap();
        assert!(!files.is_empty(), "{}", def.name);
        for f in &files {
            assert_eq!(
                std::fs::read(scratch.path().join(f)).unwrap(),
                std::fs::read(cache.join(def.name).join(f)).unwrap(),
                "{}: {f}",
                def.name
            );
        }
        checked.push(def.name);
    }
    assert_eq!(
        checked,
        ["silhouette", "visual_hull", "graphcut", "reliability"]
    );
    // The silhouette stage declares no input: the hull is refused to it, by name.
    let silhouette = STAGES.iter().find(|s| s.name == "silhouette").unwrap();
    let refused = ctx.inputs(silhouette).mesh(Surface::Hull, 0).unwrap_err();
    assert!(
        refused.to_string().contains("without declaring"),
        "{refused}"
    );
}
