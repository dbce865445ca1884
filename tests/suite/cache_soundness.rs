//! The cache cannot go stale: for each section of `pipeline.yaml`, a change of its
//! parameters followed by a run over the cache writes exactly what a fresh run with the
//! changed file writes (every file of `output/`, byte for byte). A stage whose key missed a
//! parameter it reads (as the fit's key once missed `export.frame_rate`) would reuse its old
//! result and fail this.
//!
//! Parameters are changed a section at a time: a miss in stage X's key is seen as long as
//! nothing upstream of X changed too, and each section's parameters are read by its own
//! stage and those after it. Frames 0..1 of the bundled sample keep it small.

use crate::common;

use common::*;
use std::path::Path;

/// The sample set up for frames 0..1, with `section` (YAML text) appended.
fn project(dir: &Path, section: &str) {
    copy_sample(dir);
    let path = dir.join("pipeline.yaml");
    let text = std::fs::read_to_string(&path).unwrap();
    let text = text.replace("frames: all", "frames: 0..1");
    // The export section stays last: a changed export section replaces it.
    let text = if section.starts_with("export:") {
        text[..text.find("export:").unwrap()].to_string() + section
    } else {
        text.replace("export:\n", &format!("{section}export:\n"))
    };
    std::fs::write(path, text).unwrap();
}

fn run(dir: &Path) -> String {
    let (ok, out, err) = run_cli(&["run", "pipeline.yaml"], dir);
    assert!(ok, "{}: {err}", dir.display());
    out
}

#[test]
fn a_changed_parameter_over_the_cache_equals_a_fresh_run() {
    let sections = [
        (
            "silhouette",
            "silhouette:\n  method: background\n  open_radius: 2\n",
        ),
        (
            "visual_hull",
            "visual_hull:\n  voxel_size: 0.012\n  margin: 0.05\n  smoothing_iterations: 4\n",
        ),
        (
            "graphcut",
            "graphcut:\n  ballooning: 120\n  window: 5\n  sigma: 0.4\n",
        ),
        (
            "reliability",
            "reliability:\n  window: 5\n  depth_tolerance: 2.0\n  normal_search: 0.5\n",
        ),
        ("model", "model:\n  blend_width: 0.04\n"),
        (
            "fit",
            "fit:\n  method: rho_c\n  motion_prior_acceleration: 9\n",
        ),
        (
            "export",
            "export:\n  frame_rate: 40\n  bvh_rotation_order: XYZ\n  formats: [glb, bvh, ply, obj, overlay, surface]\n",
        ),
    ];
    let outer = tempfile::tempdir().unwrap();
    let base = outer.path().join("base");
    project(&base, "");
    run(&base);
    for (name, section) in sections {
        let cached = outer.path().join(format!("cached-{name}"));
        copy_tree(&base, &cached);
        project(&cached, section);
        let out = run(&cached);
        let fresh = outer.path().join(format!("fresh-{name}"));
        project(&fresh, section);
        run(&fresh);
        let (a, b) = (
            tree_files(&cached.join("output")),
            tree_files(&fresh.join("output")),
        );
        let what =
            format!("{name} changed, over the cache, against a fresh run; the run said:\n{out}");
        assert_same_files(&a, &b, "output", &what);
        // The change did change something: the test can fail.
        assert_ne!(
            a,
            tree_files(&base.join("output")),
            "{name}: nothing changed"
        );
    }
}
