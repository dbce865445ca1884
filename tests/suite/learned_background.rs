//! `silhouette.method: learned` (background plates learned from the frames, for captures
//! without plates): a humanoid walking through every camera's view (`pipeline synth
//! --motion walk`, 8 cameras), and the tripod and the humanoid in place (15 cameras, their
//! torsos never moving), measured against the true masks, the true plates and the true
//! joints; a capture whose pixels never show a steady background is refused by camera.

use crate::common;

use common::*;
use std::path::Path;

/// A walk capture (8 cameras, 320x240, 24 frames) under `dir`, with `extra` appended to its
/// pipeline.yaml.
fn walk_capture(dir: &Path, extra: &str) {
    let mut opts = hullpose::synth::SynthOptions::new(hullpose::synth::SceneKind::Humanoid, dir);
    opts.motion = hullpose::synth::Motion::Walk;
    opts.cameras = 8;
    opts.width = 320;
    opts.height = 240;
    hullpose::synth::generate(&opts).expect("synthesis");
    let yaml = dir.join("pipeline.yaml");
    let text = std::fs::read_to_string(&yaml).unwrap();
    std::fs::write(&yaml, format!("{text}{extra}")).unwrap();
}

/// A run folder of a shared synthetic capture as a capture without plates or masks would
/// be (frames, skeleton and ground truth only), with method `learned` over `frames`.
fn no_plates(made: &Made, seq: &str, frames: &str) -> tempfile::TempDir {
    let dir = linked_capture(
        made,
        seq,
        &["frames", "skeleton.yaml", "ground_truth"],
        "silhouette:\n  method: learned\n",
    );
    let yaml = dir.path().join("pipeline.yaml");
    let text = std::fs::read_to_string(&yaml).unwrap();
    std::fs::write(
        &yaml,
        text.replace("frames: all", &format!("frames: {frames}")),
    )
    .unwrap();
    dir
}

fn grey(path: &Path) -> image::GrayImage {
    image::open(path).unwrap().to_luma8()
}

/// Whether the mask touches the image's border (the subject not wholly in view).
fn touches_border(m: &image::GrayImage) -> bool {
    let (w, h) = m.dimensions();
    (0..w).any(|x| m.get_pixel(x, 0).0[0] >= 128 || m.get_pixel(x, h - 1).0[0] >= 128)
        || (0..h).any(|y| m.get_pixel(0, y).0[0] >= 128 || m.get_pixel(w - 1, y).0[0] >= 128)
}

#[test]
fn a_walking_subject_gets_masks_as_good_as_from_true_plates_without_any() {
    let dir = process_tempdir();
    let d = dir.path();
    walk_capture(d, "silhouette:\n  method: learned\n");
    let (ok, out, err) = run_cli(&["run", "pipeline.yaml", "--until", "silhouette"], d);
    assert!(ok, "{err}");
    assert!(
        out.contains("learned background: learned from 24 frames") && out.contains("cam07 0.0%"),
        "the summary names each camera's never-background share:\n{out}"
    );
    let seq = d.join("data/humanoid");
    let (mut worst_inside, mut worst_any, mut images) = (1.0f64, 1.0f64, 0);
    for f in 0..24 {
        for c in 0..8 {
            let name = format!("cam{c:02}/{f:06}.png");
            let truth = grey(&seq.join("masks").join(&name));
            let learned = grey(
                &d.join("cache/silhouette")
                    .join(format!("{f:06}/cam{c:02}.png")),
            );
            let v = mask_iou(&learned, &truth);
            worst_any = worst_any.min(v);
            if !touches_border(&truth) && truth.pixels().any(|p| p.0[0] >= 128) {
                worst_inside = worst_inside.min(v);
                images += 1;
            }
        }
    }
    eprintln!(
        "worst IoU {worst_inside:.4} over {images} images with the subject wholly in view, \
         {worst_any:.4} over all 192"
    );
    assert!(images >= 120, "{images}");
    assert!(worst_inside >= 0.97, "{worst_inside}");
    assert!(worst_any >= 0.95, "{worst_any}");

    // The learned plates are the true ones wherever they were seen often.
    let plates: Vec<_> = std::fs::read_dir(d.join("cache/learned_background"))
        .unwrap()
        .flatten()
        .collect();
    assert_eq!(plates.len(), 1);
    let plates = plates[0].path();
    for c in 0..8 {
        let learned = image::open(plates.join(format!("cameras/cam{c:02}/plate.png")))
            .unwrap()
            .to_rgb8();
        let truth = image::open(seq.join(format!("background/cam{c:02}.png")))
            .unwrap()
            .to_rgb8();
        let share = grey(&plates.join(format!("cameras/cam{c:02}/share.png")));
        let (mut sum, mut n) = (0.0, 0usize);
        for ((l, t), s) in learned.pixels().zip(truth.pixels()).zip(share.pixels()) {
            if s.0[0] >= 128 {
                sum += (0..3)
                    .map(|k| (l.0[k] as f64 - t.0[k] as f64).abs())
                    .sum::<f64>()
                    / 3.0;
                n += 1;
            }
        }
        let mean = sum / n as f64;
        // The frames' flicker and noise (2 levels) against the plate's own noise.
        assert!(mean < 4.0, "cam{c:02}: plate off by {mean:.2} levels");
    }

    // A second run reuses the plates and the masks.
    let (ok, out, err) = run_cli(&["run", "pipeline.yaml", "--until", "silhouette"], d);
    assert!(ok, "{err}");
    assert!(
        out.contains("learned background: reused") && out.contains("0 computed"),
        "{out}"
    );
}

#[test]
fn pixels_that_never_show_a_steady_background_are_refused_by_camera() {
    let dir = process_tempdir();
    let d = dir.path();
    walk_capture(d, "silhouette:\n  method: learned\n");
    // cam03's frames become noise: no colour holds at any pixel.
    let mut rng = 12345u64;
    for f in 0..24 {
        let path = d.join(format!("data/humanoid/frames/cam03/{f:06}.png"));
        let mut img = image::open(&path).unwrap().to_rgb8();
        for p in img.pixels_mut() {
            for k in 0..3 {
                rng = rng
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                p.0[k] = (rng >> 56) as u8;
            }
        }
        img.save(&path).unwrap();
    }
    let (ok, out, err) = run_cli(&["run", "pipeline.yaml"], d);
    assert!(!ok, "{out}");
    assert!(
        err.contains("cam03") && !err.contains("cam02") && err.contains("background plates"),
        "{err}"
    );
    assert!(!d.join("cache/silhouette").exists(), "nothing computed");
    assert!(
        !d.join("cache/learned_background").exists(),
        "nothing written"
    );
}

#[test]
fn a_range_where_nothing_moves_is_refused() {
    let dir = no_plates(humanoid(), "humanoid", "3..3");
    let (ok, out, err) = run_cli(&["run", "pipeline.yaml"], dir.path());
    assert!(!ok, "{out}");
    assert!(
        err.contains("nothing moved in camera(s) cam00") && err.contains("masks"),
        "{err}"
    );
    assert!(
        !dir.path().join("cache/silhouette").exists(),
        "nothing computed"
    );
}

#[test]
fn subjects_in_place_get_masks_within_the_bound_without_plates() {
    for (made, seq) in [(tripod(), "tripod"), (humanoid(), "humanoid")] {
        let dir = no_plates(made, seq, "all");
        let (ok, out, err) = run_cli(
            &["run", "pipeline.yaml", "--until", "silhouette"],
            dir.path(),
        );
        assert!(ok, "{err}");
        // A part of the subject stays in every view: its share is reported per camera.
        assert!(
            out.contains("never background") && out.contains("cam14"),
            "{out}"
        );
        let (worst, at, _) =
            worst_silhouette_iou(dir.path(), &made.root.join("data").join(seq).join("masks"));
        let images = made_images(made, seq);
        eprintln!("{seq}: worst IoU {worst:.4} ({at}) over {images} images");
        assert!(worst >= 0.95, "{seq}: IoU {worst:.4} at {at}");
    }
}

fn made_images(made: &Made, seq: &str) -> usize {
    let frames = made.root.join("data").join(seq).join("frames");
    std::fs::read_dir(&frames)
        .unwrap()
        .flatten()
        .map(|cam| std::fs::read_dir(cam.path()).unwrap().count())
        .sum()
}

#[test]
fn the_humanoid_tracked_from_learned_masks_stays_within_its_bound() {
    // The hands moving onto the hips and resting there (frames 0..5), 15 cameras, 384x288:
    // the whole pipeline on masks learned without plates from these six frames (the whole
    // motion at 1024x768: BENCHMARKS.md).
    let dir = no_plates(humanoid(), "humanoid", "0..5");
    let (ok, out, err) = run_cli(&["run", "pipeline.yaml"], dir.path());
    assert!(ok, "{err}");
    let errors = output_joint_errors_cm(dir.path(), "humanoid");
    eprintln!("mean joint error per frame, cm: {errors:.2?}");
    assert_eq!(errors.len(), 6, "{out}");
    let worst = errors.iter().copied().fold(0.0, f64::max);
    assert!(worst <= 1.5, "worst frame {worst:.2} cm: {errors:.2?}");
}
