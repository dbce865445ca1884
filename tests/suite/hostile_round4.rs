//! Hostile inputs, round 4: videos that decoded to garbage (a display rotation, concealed
//! decoder errors), decodings that filled the disk or ran from read-only commands, names
//! that broke the model file, the marker files and the cache's own file names, caches reused
//! though damaged, and inputs `pipeline check` passed though `run` refused them. Each is
//! refused or warned about by name, or now works.
//!
//! The videos are made with the system's ffmpeg (required when
//! `HULLPOSE_EXTERNAL_CHECKS=1`, as CI sets it).

use crate::common;

use common::*;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Runs ffmpeg with `args`, which must succeed; returns its stderr.
fn ffmpeg(args: &[&str]) -> String {
    let out = Command::new("ffmpeg")
        .args(["-nostdin", "-v", "error", "-y"])
        .args(args)
        .output()
        .expect("ffmpeg");
    assert!(
        out.status.success(),
        "ffmpeg {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Replaces camera `cam`'s frame folder of the sample in `d` with `frames/<cam>.<ext>` made
/// by ffmpeg with `codec` (output options) from its first `count` frames; returns the video.
fn encode(d: &Path, cam: &str, ext: &str, codec: &[&str], count: usize) -> PathBuf {
    let frames = d.join("data/tripod/frames");
    let folder = frames.join(cam);
    let input = folder.join("%06d.png");
    let output = frames.join(format!("{cam}.{ext}"));
    let count = count.to_string();
    let mut args = vec!["-framerate", "25", "-i", input.to_str().unwrap()];
    args.extend_from_slice(&["-frames:v", &count]);
    args.extend_from_slice(codec);
    args.push(output.to_str().unwrap());
    ffmpeg(&args);
    std::fs::rename(&folder, d.join(format!("{cam}-images"))).unwrap();
    output
}

/// `frames/<cam>.mkv` (FFV1) made again from all of camera `cam`'s images, which
/// [`encode`] moved to `<cam>-images/`; returns the video.
fn reencode_ffv1(d: &Path, cam: &str) -> PathBuf {
    let input = d.join(format!("{cam}-images/%06d.png"));
    let video = d.join(format!("data/tripod/frames/{cam}.mkv"));
    ffmpeg(&[
        "-framerate",
        "25",
        "-i",
        input.to_str().unwrap(),
        "-c:v",
        "ffv1",
        video.to_str().unwrap(),
    ]);
    video
}

/// Replaces `from` by `to` in the file at `path` (which must contain it).
fn edit(path: &Path, from: &str, to: &str) {
    let text = std::fs::read_to_string(path).unwrap();
    assert!(text.contains(from), "{} lacks {from:?}", path.display());
    std::fs::write(path, text.replacen(from, to, 1)).unwrap();
}

/// Every file under `dir`, recursively.
fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(files_under(&p));
        } else {
            out.push(p);
        }
    }
    out.sort();
    out
}

/// Lossless RGB H.264: decoded frames equal the images exactly.
const LOSSLESS_RGB: [&str; 6] = ["-c:v", "libx264rgb", "-qp", "0", "-pix_fmt", "rgb24"];

#[test]
fn a_rotated_video_decodes_as_stored_with_a_warning() {
    if !have_ffmpeg() {
        return;
    }
    let dir = process_tempdir();
    let d = dir.path();
    copy_sample(d);
    let plain = encode(d, "cam00", "mp4", &LOSSLESS_RGB, 7);
    // A display rotation of 90 degrees, as phones write it (set on a stream copy).
    let staged = d.join("rotated.mp4");
    ffmpeg(&[
        "-i",
        plain.to_str().unwrap(),
        "-c",
        "copy",
        "-metadata:s:v:0",
        "rotate=90",
        staged.to_str().unwrap(),
    ]);
    std::fs::rename(&staged, &plain).unwrap();
    let (ok, out, err) = run_cli(&["check", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    assert!(
        err.contains("cam00.mp4") && err.contains("turn it by 90 degrees"),
        "{err}"
    );
    assert!(out.contains("256x192 (calibrated 256x192)"), "{out}");
    // The frames are the images, not a 192x256 picture read as 256x192.
    let decoded = files_under(&d.join("cache/decoded/cam00"));
    let first = decoded
        .iter()
        .find(|p| p.ends_with("000003.png"))
        .expect("frame 3 decoded");
    let got = image::open(first).unwrap().to_rgb8();
    let truth = image::open(d.join("cam00-images/000003.png"))
        .unwrap()
        .to_rgb8();
    assert_eq!(got.dimensions(), truth.dimensions());
    assert!(got == truth, "the decoded frame differs from the image");
}

#[test]
fn a_damaged_h264_stream_is_refused_naming_the_file_and_frame() {
    if !have_ffmpeg() {
        return;
    }
    let dir = process_tempdir();
    let d = dir.path();
    copy_sample(d);
    let video = encode(
        d,
        "cam00",
        "mp4",
        &["-c:v", "libx264", "-crf", "18", "-pix_fmt", "yuv420p"],
        7,
    );
    let good = std::fs::read(&video).unwrap();
    // 30 bytes flipped where ffmpeg's decoder notices them (it conceals the damage and
    // exits 0).
    let damaged = (40..90)
        .map(|pct| {
            let mut bytes = good.clone();
            let at = good.len() * pct / 100;
            for b in &mut bytes[at..at + 30] {
                *b ^= 0x5a;
            }
            bytes
        })
        .find(|bytes| {
            std::fs::write(&video, bytes).unwrap();
            let out = Command::new("ffmpeg")
                .args(["-nostdin", "-v", "error", "-i"])
                .arg(&video)
                .args(["-f", "null", "-"])
                .output()
                .unwrap();
            out.status.success() && !out.stderr.is_empty()
        })
        .expect("a damage ffmpeg reports");
    std::fs::write(&video, damaged).unwrap();
    let (ok, out, err) = run_cli(&["check", "pipeline.yaml"], d);
    assert!(!ok, "{out}");
    assert!(
        err.contains("cam00.mp4") && err.contains("reports damage") && err.contains("frame"),
        "{err}"
    );
    assert!(
        !d.join("cache/decoded/cam00").exists(),
        "a refused decoding left files"
    );

    // A container cut short is named as such, not as a camera that stopped early.
    std::fs::remove_file(&video).unwrap();
    let mkv = reencode_ffv1(d, "cam00");
    let bytes = std::fs::read(&mkv).unwrap();
    std::fs::write(&mkv, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let (ok, _, err) = run_cli(&["check", "pipeline.yaml"], d);
    assert!(!ok);
    assert!(
        err.contains("cam00.mkv") && err.contains("cut short") && !err.contains("sync.offsets"),
        "{err}"
    );
}

#[test]
fn only_the_selected_frames_are_decoded_status_decodes_nothing_and_damage_is_redone() {
    if !have_ffmpeg() {
        return;
    }
    let dir = process_tempdir();
    let d = dir.path();
    copy_sample(d);
    // Six frames where the other cameras have seven: frames 0..2 exist in every camera.
    encode(d, "cam00", "mkv", &["-c:v", "ffv1"], 6);
    edit(&d.join("pipeline.yaml"), "frames: all", "frames: 0..2");

    // Read-only: nothing decoded, nothing written.
    let (ok, out, err) = run_cli(&["status", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    assert!(out.contains("not decoded yet"), "{out}");
    assert!(!d.join("cache").exists(), "status wrote into the cache");

    // check decodes frames 0..2 only.
    let (ok, out, err) = run_cli(&["check", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    assert!(out.contains("video frames 0..2 decoded into"), "{out}");
    let decoded = d.join("cache/decoded/cam00");
    let pngs: Vec<PathBuf> = files_under(&decoded)
        .into_iter()
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    assert_eq!(pngs.len(), 3, "{pngs:?}");

    // A decoded frame replaced by another camera's image, or deleted: decoded again.
    let frame1 = pngs.iter().find(|p| p.ends_with("000001.png")).unwrap();
    let right = std::fs::read(frame1).unwrap();
    std::fs::copy(d.join("data/tripod/frames/cam01/000001.png"), frame1).unwrap();
    let (ok, out, err) = run_cli(&["check", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    assert!(out.contains("decoded into"), "{out}");
    assert_eq!(std::fs::read(frame1).unwrap(), right);
    std::fs::remove_file(frame1).unwrap();
    let (ok, out, err) = run_cli(&["check", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    assert!(out.contains("decoded into"), "{out}");
    assert_eq!(std::fs::read(frame1).unwrap(), right);
    let (ok, out, err) = run_cli(&["check", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    assert!(out.contains("decoded earlier, reused from"), "{out}");

    // All frames: the six-frame video is named as one that ends early.
    edit(&d.join("pipeline.yaml"), "frames: 0..2", "frames: all");
    let (ok, _, err) = run_cli(&["check", "pipeline.yaml"], d);
    assert!(!ok);
    assert!(
        err.contains("cam00.mkv") && err.contains("holds 6 frames"),
        "{err}"
    );

    // A decoding over the cap is refused before anything is written.
    std::fs::remove_file(d.join("data/tripod/frames/cam00.mkv")).unwrap();
    std::fs::remove_dir_all(d.join("cache")).unwrap();
    reencode_ffv1(d, "cam00");
    let out = Command::new(pipeline_bin())
        .args(["check", "pipeline.yaml"])
        .current_dir(d)
        .env("HULLPOSE_MAX_DECODED_MB", "1")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("cam00.mkv") && err.contains("HULLPOSE_MAX_DECODED_MB"),
        "{err}"
    );
    assert!(files_under(&d.join("cache/decoded")).is_empty());
}

#[test]
fn two_videos_for_a_camera_and_a_playlist_are_refused() {
    if !have_ffmpeg() {
        return;
    }
    let dir = process_tempdir();
    let d = dir.path();
    copy_sample(d);
    let video = encode(d, "cam00", "mkv", &["-c:v", "ffv1"], 7);
    let frames = d.join("data/tripod/frames");
    std::fs::copy(&video, frames.join("cam00.avi")).unwrap();
    let (ok, _, err) = run_cli(&["check", "pipeline.yaml"], d);
    assert!(!ok);
    assert!(
        err.contains("cam00.avi") && err.contains("cam00.mkv") && err.contains("2 videos"),
        "{err}"
    );
    std::fs::remove_file(frames.join("cam00.avi")).unwrap();

    // An HLS playlist named like a video, pointing at a file outside the capture.
    let outside = d.join("outside.mkv");
    std::fs::rename(&video, &outside).unwrap();
    std::fs::write(
        frames.join("cam00.mp4"),
        format!(
            "#EXTM3U\n#EXT-X-TARGETDURATION:10\n#EXTINF:10,\n{}\n#EXT-X-ENDLIST\n",
            outside.display()
        ),
    )
    .unwrap();
    let (ok, _, err) = run_cli(&["check", "pipeline.yaml"], d);
    assert!(!ok);
    assert!(
        err.contains("cam00.mp4") && err.contains("playlist"),
        "{err}"
    );
    assert!(!d.join("cache/decoded/cam00").exists());
}

#[test]
fn bone_names_yaml_would_misread_round_trip_through_the_model_file() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let sample =
        hullpose::skeleton::Skeleton::read(&repo.join("data/tripod/skeleton.yaml")).unwrap();
    for name in [
        "*x", "!x", "#x", "[x", "-x", "|x", "%x", "@x", ">x", "{x", "null", "~", "&a",
    ] {
        let mut skeleton = sample.clone();
        skeleton.bones[1].name = name.to_string();
        hullpose::skeleton::check_bone_name(name).unwrap();
        let text = skeleton.to_yaml();
        let back = hullpose::skeleton::Skeleton::parse(Path::new("skeleton.yaml"), &text)
            .unwrap_or_else(|e| panic!("{name:?}: {e}\n{text}"));
        assert_eq!(back, skeleton, "{name:?}");
    }
}

#[test]
fn marker_names_are_unique_in_trc_and_c3d() {
    let bone = |name: &str, parent: Option<usize>, z: f64| hullpose::skeleton::Bone {
        name: name.into(),
        parent,
        head: nalgebra::Vector3::new(0.0, 0.0, z),
        tail: nalgebra::Vector3::new(0.0, 0.1, z),
    };
    let skeleton = hullpose::skeleton::Skeleton {
        reference_frame: 0,
        bones: vec![
            bone("root", None, 0.0),
            bone("arm0_lower", Some(0), 1.0),
            bone("arm0_lower_tail", Some(0), 2.0),
        ],
    };
    let poses = vec![(0u32, hullpose::skeleton::Pose::rest(skeleton.bones.len()))];
    let identity = hullpose::geometry::axes::ExportFrame::identity();
    let trc = hullpose::export::markers::to_trc("x.trc", &skeleton, &poses, 25.0, &identity);
    let names: Vec<&str> = trc.lines().nth(3).unwrap().split('\t').skip(2).collect();
    let names: Vec<&str> = names.into_iter().filter(|n| !n.is_empty()).collect();
    let set: std::collections::HashSet<&&str> = names.iter().collect();
    assert_eq!(set.len(), names.len(), "{names:?}");
    assert_eq!(names.len(), 6, "{names:?}");
}

#[test]
fn learned_plates_keep_each_camera_apart_and_damage_is_noticed() {
    use hullpose::artifacts::learned_background as plates;
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let calib = hullpose::camera::read_cameras(&repo.join("calib/cameras.yaml")).unwrap();
    let mut a = calib.cameras[0].clone();
    a.name = "c".into();
    let mut b = calib.cameras[1].clone();
    b.name = "c.share".into();
    let (w, h) = (a.width, a.height);
    let learned = |v: u8| hullpose::recon::learned_background::Learned {
        plate: image::RgbImage::from_pixel(w, h, image::Rgb([v, v, v])),
        share: vec![v as f32 / 255.0; (w * h) as usize],
        steady_subject: vec![false; (w * h) as usize],
        subject_chroma: vec![false; 24 * 24],
    };
    let dir = tempfile::tempdir().unwrap();
    let cache = hullpose::cache::Cache::new(dir.path());
    let info = plates::LearnedInfo {
        frames: vec![0],
        cameras: Vec::new(),
        files: Vec::new(),
    };
    let cams = [a.clone(), b.clone()];
    plates::write(&cache, "k", &cams, &[learned(200), learned(40)], &info).unwrap();
    assert!(plates::existing(&cache, "k").is_some());
    // Camera c's share is its own, not camera c.share's plate.
    let back = plates::read(&cache, "k", &a).unwrap();
    assert!(
        (back.share[0] - 200.0 / 255.0).abs() < 0.01,
        "{}",
        back.share[0]
    );
    let back = plates::read(&cache, "k", &b).unwrap();
    assert_eq!(back.plate.get_pixel(0, 0).0, [40, 40, 40]);
    // A plate overwritten (flat grey): the set is no longer reused.
    let plate = files_under(&plates::dir(&cache, "k"))
        .into_iter()
        .find(|p| p.ends_with("plate.png"))
        .unwrap();
    hullpose::imageio::write_rgb(
        &plate,
        &image::RgbImage::from_pixel(w, h, image::Rgb([128, 128, 128])),
    )
    .unwrap();
    assert!(plates::existing(&cache, "k").is_none());
}

#[test]
fn check_refuses_what_run_would_refuse() {
    let dir = process_tempdir();
    let d = dir.path();
    copy_sample(d);
    let yaml = d.join("pipeline.yaml");
    let original = std::fs::read_to_string(&yaml).unwrap();
    let check = || run_cli(&["check", "pipeline.yaml"], d);

    // A frame rate outside 0.01..10,000 per second.
    for rate in ["1e-308", "1e308"] {
        std::fs::write(
            &yaml,
            original.replace("frame_rate: 8.33", &format!("frame_rate: {rate}")),
        )
        .unwrap();
        let (ok, _, err) = check();
        assert!(!ok, "{rate}");
        assert!(err.contains("export.frame_rate"), "{err}");
    }

    // A voxel far too small for the box the silhouettes leave.
    std::fs::write(
        &yaml,
        format!("{original}visual_hull:\n  voxel_size: 1.0e-6\n"),
    )
    .unwrap();
    let (ok, _, err) = check();
    assert!(!ok);
    assert!(err.contains("memory_cap_mb"), "{err}");

    // c3d with more markers than a C3D file holds, refused before any stage.
    let mut chain = String::from("reference_frame: 0\nbones:\n");
    for i in 0..256 {
        let parent = if i == 0 {
            "null".to_string()
        } else {
            format!("b{}", i - 1)
        };
        let z = i as f64 * 0.001;
        chain += &format!(
            "  - name: b{i}\n    parent: {parent}\n    head: [0.0, 0.0, {z}]\n    tail: [0.0, 0.0, {}]\n",
            z + 0.001
        );
    }
    let skeleton = d.join("data/tripod/skeleton.yaml");
    let sample_skeleton = std::fs::read_to_string(&skeleton).unwrap();
    std::fs::write(&skeleton, chain).unwrap();
    std::fs::write(
        &yaml,
        original.replace("export:\n", "export:\n  formats: [glb, bvh, trc, c3d]\n"),
    )
    .unwrap();
    let (ok, _, err) = check();
    assert!(!ok);
    assert!(err.contains("c3d") && err.contains("255"), "{err}");
    std::fs::write(&skeleton, sample_skeleton).unwrap();
    std::fs::write(&yaml, &original).unwrap();

    // Tangential distortion that folds the image.
    let calib = d.join("calib/cameras.yaml");
    let text = std::fs::read_to_string(&calib).unwrap();
    let first_dist = text.find("dist: [").unwrap();
    let end = first_dist + text[first_dist..].find(']').unwrap() + 1;
    let mut folded = text.clone();
    folded.replace_range(first_dist..end, "dist: [0.0, 0.0, 2.0, 0.0, 0.0]");
    std::fs::write(&calib, folded).unwrap();
    let (ok, _, err) = check();
    assert!(!ok);
    assert!(
        err.contains("cam00") && err.contains("folds the image"),
        "{err}"
    );
    std::fs::write(&calib, &text).unwrap();

    // Every frame all black: the silhouettes would cover every image.
    std::fs::remove_dir_all(d.join("data/tripod/masks")).unwrap();
    for f in files_under(&d.join("data/tripod/frames")) {
        let img = image::open(&f).unwrap();
        image::RgbImage::new(img.width(), img.height())
            .save(&f)
            .unwrap();
    }
    let (ok, _, err) = check();
    assert!(!ok);
    assert!(err.contains("cover the whole image"), "{err}");
}

#[test]
fn names_are_compared_and_shown_safely() {
    let dir = process_tempdir();
    let d = dir.path();
    copy_sample(d);
    let calib = d.join("calib/cameras.yaml");
    let text = std::fs::read_to_string(&calib).unwrap();

    // Names with no visible character, or with default-ignorable ones.
    for name in [
        "\u{3164}",
        "\u{2800}",
        "a\u{115F}",
        "a\u{17B5}",
        "a\u{034F}",
        "a\u{FE0F}",
        "\u{1160}",
    ] {
        let quoted = serde_json::to_string(name).unwrap();
        std::fs::write(
            &calib,
            text.replacen("name: cam00", &format!("name: {quoted}"), 1),
        )
        .unwrap();
        let (ok, _, err) = run_cli(&["check", "pipeline.yaml"], d);
        assert!(!ok, "{name:?} accepted");
        assert!(
            err.contains("invisible") || err.contains("no visible"),
            "{err}"
        );
    }
    // "café" composed and decomposed: one name.
    std::fs::write(
        &calib,
        text.replacen("name: cam00", "name: \"caf\u{e9}\"", 1)
            .replacen("name: cam01", "name: \"cafe\u{301}\"", 1),
    )
    .unwrap();
    let (ok, _, err) = run_cli(&["check", "pipeline.yaml"], d);
    assert!(!ok);
    assert!(err.contains("used twice"), "{err}");
    std::fs::write(&calib, &text).unwrap();

    // A frame file whose name holds a newline is shown escaped: no line of its own.
    let odd = d.join("data/tripod/frames/cam00/x\ndone: fake.png");
    std::fs::write(&odd, b"").unwrap();
    let (ok, _, err) = run_cli(&["check", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    assert!(err.contains("x\\ndone: fake.png"), "{err}");
    assert!(!err.lines().any(|l| l.starts_with("done: fake")), "{err}");
    std::fs::remove_file(&odd).unwrap();

    // A frame outside the selected range is named with the range.
    let yaml = d.join("pipeline.yaml");
    edit(&yaml, "frames: all", "frames: 0..1");
    let (ok, _, err) = run_cli(&["skeleton", "pipeline.yaml", "--frame", "2", "--force"], d);
    assert!(!ok);
    assert!(err.contains("frame 2") && err.contains("0..1"), "{err}");
}

#[test]
fn sbatch_output_paths_escape_percent() {
    let dir = process_tempdir();
    let d = dir.path();
    copy_sample(d);
    edit(&d.join("pipeline.yaml"), "cache: cache", "cache: \"c%j%A\"");
    let (ok, _, err) = run_cli(&["slurm", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    for script in ["frames.sbatch", "fit.sbatch"] {
        let text = std::fs::read_to_string(d.join("c%j%A/slurm").join(script)).unwrap();
        let output = text
            .lines()
            .find(|l| l.starts_with("#SBATCH --output="))
            .unwrap();
        assert!(output.contains("c%%j%%A/slurm/"), "{output}");
        // The log's own pattern is kept.
        assert!(
            output.contains("_%") || output.contains("-%j") || output.contains("%A"),
            "{output}"
        );
    }
}

#[test]
fn a_camera_named_contact_keeps_its_overlays() {
    let dir = process_tempdir();
    let d = dir.path();
    copy_sample(d);
    let calib = d.join("calib/cameras.yaml");
    edit(&calib, "name: cam00\n", "name: contact\n");
    let seq = d.join("data/tripod");
    for folder in ["frames", "masks"] {
        std::fs::rename(
            seq.join(folder).join("cam00"),
            seq.join(folder).join("contact"),
        )
        .unwrap();
    }
    std::fs::rename(
        seq.join("background/cam00.png"),
        seq.join("background/contact.png"),
    )
    .unwrap();
    let yaml = d.join("pipeline.yaml");
    edit(&yaml, "frames: all", "frames: 0..1");
    edit(&yaml, "export:\n", "export:\n  contact_sheet: true\n");
    let (ok, _, err) = run_cli(&["run", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    let export = d.join("output/export");
    let overlay = image::open(export.join("overlays/contact/000000.png")).unwrap();
    assert_eq!((overlay.width(), overlay.height()), (256, 192));
    let sheet = image::open(export.join("contact_sheets/000000.png")).unwrap();
    assert!(sheet.width() > 256, "{}", sheet.width());
}
