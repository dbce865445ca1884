//! Camera videos as frames (`frames/<camera>.<ext>`, README "Bring your own capture"):
//! the bundled sample encoded losslessly gives the joints of its image folders byte for
//! byte, sync offsets included; encoded at H.264 -crf 18 it is tracked within a
//! centimetre; a short video, a video of another size, a damaged file and a machine without
//! ffmpeg are each refused by name with nothing half-written.
//!
//! The videos are made with the system's ffmpeg. Without it the tests say so and pass,
//! unless `HULLPOSE_EXTERNAL_CHECKS=1` (as CI sets it, after installing it).

use crate::common;

use common::*;
use std::path::Path;
use std::process::Command;

/// A copy of the bundled sample (7 frames, 15 cameras at 256x192) in a fresh folder.
fn sample() -> tempfile::TempDir {
    let dir = process_tempdir();
    copy_sample(dir.path());
    dir
}

/// Runs ffmpeg with `args` in `cwd`, which must succeed.
fn ffmpeg(cwd: &Path, args: &[&str]) {
    let out = Command::new("ffmpeg")
        .args(["-v", "error", "-y"])
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("ffmpeg");
    assert!(
        out.status.success(),
        "ffmpeg {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Replaces camera `cam`'s image folder with `frames/<cam>.<ext>` encoded with `codec`
/// (ffmpeg output options), its frames first preceded by `lead` copies of the last frames.
fn encode(seq: &Path, cam: &str, ext: &str, codec: &[&str], lead: usize) {
    let frames = seq.join("frames");
    let folder = frames.join(cam);
    let mut files: Vec<_> = std::fs::read_dir(&folder)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    let staged = frames.join(format!(".{cam}-staged"));
    std::fs::create_dir_all(&staged).unwrap();
    let order = files[files.len() - lead..].iter().chain(&files);
    for (i, f) in order.enumerate() {
        std::fs::copy(f, staged.join(format!("{i:06}.png"))).unwrap();
    }
    let input = staged.join("%06d.png");
    let output = frames.join(format!("{cam}.{ext}"));
    let mut args = vec!["-framerate", "25", "-i", input.to_str().unwrap()];
    args.extend_from_slice(codec);
    args.push(output.to_str().unwrap());
    ffmpeg(seq, &args);
    std::fs::remove_dir_all(&staged).unwrap();
    std::fs::remove_dir_all(&folder).unwrap();
}

const LOSSLESS: [&str; 4] = ["-c:v", "ffv1", "-pix_fmt", "bgr0"];

fn cameras(seq: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(seq.join("frames"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// Every file under `dir` with its modification time.
fn listing(dir: &Path) -> Vec<(std::path::PathBuf, std::time::SystemTime)> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(listing(&p));
        } else {
            out.push((p.clone(), p.metadata().unwrap().modified().unwrap()));
        }
    }
    out.sort();
    out
}

#[test]
fn lossless_videos_give_the_joints_of_the_image_folders_byte_for_byte() {
    if !have_ffmpeg() {
        return;
    }
    let folders = sample();
    let (ok, _, err) = run_cli(
        &["run", "pipeline.yaml", "--frames", "0..3"],
        folders.path(),
    );
    assert!(ok, "{err}");

    let videos = sample();
    let seq = videos.path().join("data/tripod");
    for cam in cameras(&seq) {
        // cam03 started recording two frames early: its video leads by two frames, which
        // sync.offsets takes back.
        let lead = if cam == "cam03" { 2 } else { 0 };
        let ext = if cam == "cam05" { "avi" } else { "mkv" };
        encode(&seq, &cam, ext, &LOSSLESS, lead);
    }
    let yaml = videos.path().join("pipeline.yaml");
    let text = std::fs::read_to_string(&yaml).unwrap();
    std::fs::write(&yaml, format!("{text}sync:\n  offsets: {{cam03: 2}}\n")).unwrap();
    let (ok, out, err) = run_cli(&["check", "pipeline.yaml"], videos.path());
    assert!(ok, "{err}");
    assert!(
        out.contains("video cam03: data/tripod/frames/cam03.mkv holds 9 frames, 256x192 (calibrated 256x192), 25.000 fps, offset 2"),
        "{out}"
    );
    let (ok, out, err) = run_cli(&["run", "pipeline.yaml", "--frames", "0..3"], videos.path());
    assert!(ok, "{err}");
    assert!(out.contains("decoded earlier, reused from"), "{out}");
    for file in ["output/joints.csv", "output/poses.csv"] {
        assert_eq!(
            std::fs::read(folders.path().join(file)).unwrap(),
            std::fs::read(videos.path().join(file)).unwrap(),
            "{file} differs"
        );
    }
    // Decoded once: a second run reads the cache and decodes nothing.
    let decoded = videos.path().join("cache/decoded");
    let before = listing(&decoded);
    assert_eq!(
        before.len(),
        15 * 8,
        "7 frames and info.yaml per camera: cam03's two leading frames are not decoded"
    );
    let (ok, out, err) = run_cli(&["run", "pipeline.yaml", "--frames", "0..3"], videos.path());
    assert!(ok, "{err}");
    assert!(!out.contains("decoded into"), "{out}");
    assert_eq!(listing(&decoded), before);
}

#[test]
fn h264_at_crf_18_keeps_the_sample_within_a_centimetre() {
    if !have_ffmpeg() {
        return;
    }
    let dir = sample();
    let seq = dir.path().join("data/tripod");
    let h264 = ["-c:v", "libx264", "-crf", "18", "-pix_fmt", "yuv420p"];
    for cam in cameras(&seq) {
        encode(&seq, &cam, "mp4", &h264, 0);
    }
    let (ok, _, err) = run_cli(&["run", "pipeline.yaml"], dir.path());
    assert!(ok, "{err}");
    let errors = output_joint_errors_cm(dir.path(), "tripod");
    eprintln!("mean joint error per frame, cm: {errors:.2?}");
    assert_eq!(errors.len(), 7);
    let worst = errors.iter().copied().fold(0.0, f64::max);
    assert!(worst <= 1.0, "worst frame {worst:.2} cm: {errors:.2?}");
}

/// Runs `pipeline run` in `dir`, which must fail without writing outputs or a complete
/// decoding of `cam`; returns its message.
fn refused(dir: &Path, cam: &str) -> String {
    let (ok, out, err) = run_cli(&["run", "pipeline.yaml"], dir);
    assert!(!ok, "{out}");
    assert!(!dir.join("output").exists(), "outputs written: {err}");
    // A refused decoding removes everything it wrote, the folders it made included.
    let decoded = dir.join("cache/decoded").join(cam);
    assert!(
        !decoded.exists(),
        "a refused decoding of {cam} left {:?}: {err}",
        listing(&decoded)
    );
    err
}

#[test]
fn short_resized_and_damaged_videos_and_a_missing_ffmpeg_are_refused_by_name() {
    if !have_ffmpeg() {
        return;
    }
    let base = sample();
    let seq = base.path().join("data/tripod");
    for cam in cameras(&seq) {
        encode(&seq, &cam, "mkv", &LOSSLESS, 0);
    }
    let variant = |f: &dyn Fn(&Path)| {
        let dir = process_tempdir();
        copy_tree(base.path(), dir.path());
        f(&dir.path().join("data/tripod/frames"));
        dir
    };

    // `cam`'s video replaced by ffmpeg's output of it with `options`.
    let transcoded = |cam: &str, options: &[&str]| {
        let cam = cam.to_string();
        let options: Vec<String> = options.iter().map(|o| o.to_string()).collect();
        variant(&move |frames| {
            let v = frames.join(format!("{cam}.mkv"));
            let out = frames.join("transcoded.mkv");
            let mut args = vec!["-i", v.to_str().unwrap()];
            args.extend(options.iter().map(String::as_str));
            args.push(out.to_str().unwrap());
            ffmpeg(frames, &args);
            std::fs::rename(&out, &v).unwrap();
        })
    };

    // One frame short, without an offset that explains it.
    let short = transcoded("cam03", &["-frames:v", "6", "-c", "copy"]);
    let err = refused(short.path(), "none");
    assert!(
        err.contains("cam03.mkv") && err.contains("holds 6 frames") && err.contains("sync.offsets"),
        "{err}"
    );

    // Another camera's size.
    let resized = transcoded("cam05", &["-vf", "scale=320:240", "-c:v", "ffv1"]);
    let err = refused(resized.path(), "cam05");
    assert!(
        err.contains("cam05.mkv") && err.contains("320x240") && err.contains("256x192"),
        "{err}"
    );

    // A damaged file.
    let damaged = variant(&|frames| {
        std::fs::remove_file(frames.join("cam02.mkv")).unwrap();
        let junk: Vec<u8> = (0..50_000u32)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
            .collect();
        std::fs::write(frames.join("cam02.mp4"), junk).unwrap();
    });
    let err = refused(damaged.path(), "cam02");
    assert!(
        err.contains("cam02.mp4") && err.contains("not a video"),
        "{err}"
    );

    // A range past the end of the videos.
    let past = variant(&|_| {});
    let (ok, _, err) = run_cli(&["run", "pipeline.yaml", "--frames", "0..9"], past.path());
    assert!(!ok);
    assert!(
        err.contains("frame range 0..9") && err.contains("cam00.mkv ends at capture frame 6"),
        "{err}"
    );

    // A camera with both a folder and a video: the folder is read, the video named as
    // ignored.
    let both = variant(&|frames| {
        let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
        copy_tree(
            &repo.join("data/tripod/frames/cam00"),
            &frames.join("cam00"),
        );
    });
    let (ok, _, err) = run_cli(&["check", "pipeline.yaml"], both.path());
    assert!(ok, "{err}");
    assert!(
        err.contains("cam00.mkv: ignored, camera 'cam00' has a frame folder"),
        "{err}"
    );

    // A sync offset for a camera that does not exist.
    let yaml = base.path().join("pipeline.yaml");
    let text = std::fs::read_to_string(&yaml).unwrap();
    let unknown = variant(&|_| {});
    std::fs::write(
        unknown.path().join("pipeline.yaml"),
        format!("{text}sync:\n  offsets: {{cam99: 1}}\n"),
    )
    .unwrap();
    let err = refused(unknown.path(), "none");
    assert!(
        err.contains("sync.offsets") && err.contains("cam99"),
        "{err}"
    );

    // No ffmpeg on the machine.
    let bare = variant(&|_| {});
    let empty = process_tempdir();
    let out = Command::new(pipeline_bin())
        .args(["run", "pipeline.yaml"])
        .current_dir(bare.path())
        .env("PATH", empty.path())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("needs ffmpeg") && err.contains("apt install ffmpeg"),
        "{err}"
    );
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(!bare.path().join("output").exists());
    assert!(
        !bare.path().join("cache/decoded").exists()
            || listing(&bare.path().join("cache/decoded")).is_empty()
    );
}
