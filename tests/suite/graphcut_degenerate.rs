//! Degenerate input does not break the graph cut: a band thicker than the object and
//! images of one uniform colour give closed meshes and the documented results.

use crate::common;

use common::*;
use std::path::Path;

/// A copy of the bundled sample (frames 0..1) with `extra` appended to its pipeline.yaml.
fn sample(extra: &str) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    copy_sample_capture(dir.path());
    let yaml = hullpose::config::default_yaml("calib/cameras.yaml", "data/tripod")
        .replace("frames: all", "frames: 0..1");
    std::fs::write(dir.path().join("pipeline.yaml"), format!("{yaml}{extra}")).unwrap();
    dir
}

fn volumes(dir: &Path, frame: u32) -> (f64, f64) {
    let read = |stage: &str| {
        hullpose::geometry::ply::read_ply(&dir.join(format!("cache/{stage}/{frame:06}.ply")))
            .unwrap()
    };
    let (hull, cut) = (read("visual_hull"), read("graphcut"));
    assert!(
        cut.is_watertight() && cut.signed_volume() > 0.0,
        "closed, outward"
    );
    (hull.signed_volume(), cut.signed_volume())
}

#[test]
fn a_band_thicker_than_the_object_keeps_a_core() {
    let dir = sample("graphcut:\n  band: 2.0\n");
    let (ok, _, err) = run_cli(&["run", "pipeline.yaml"], dir.path());
    assert!(ok, "{err}");
    for f in 0..2 {
        let (hull, cut) = volumes(dir.path(), f);
        assert!(
            cut > 0.5 * hull && cut <= hull * 1.01,
            "t{f}: {cut} of {hull} m^3"
        );
    }
}

#[test]
fn uniform_images_keep_the_hulls_shape() {
    let dir = sample("");
    // Every frame one flat grey (the masks still give the hull).
    for cam in std::fs::read_dir(dir.path().join("data/tripod/frames"))
        .unwrap()
        .flatten()
    {
        for f in std::fs::read_dir(cam.path()).unwrap().flatten() {
            image::RgbImage::from_pixel(256, 192, image::Rgb([128, 128, 128]))
                .save(f.path())
                .unwrap();
        }
    }
    let (ok, _, err) = run_cli(&["run", "pipeline.yaml"], dir.path());
    assert!(ok, "{err}");
    for f in 0..2 {
        // No photo-consistency anywhere: rho is flat, the ballooning keeps the hull.
        let (hull, cut) = volumes(dir.path(), f);
        assert!(cut > 0.9 * hull, "t{f}: {cut} of {hull} m^3");
    }
}
