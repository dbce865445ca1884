//! The cached runner and the silhouette stage: background subtraction against the true
//! masks, caching behaviour (reuse, parameter changes, SIGKILL, concurrency, disjoint frame
//! ranges) and bad pipeline input.

use crate::common;

use common::*;
use std::path::{Path, PathBuf};

/// A run folder whose pipeline.yaml points at a shared synthetic capture (frames and plates
/// linked, given masks left out) with its own cache.
struct RunDir {
    dir: tempfile::TempDir,
    truth: PathBuf,
}

fn run_dir(made: &Made, seq: &str, extra_yaml: &str) -> RunDir {
    RunDir {
        dir: linked_capture(
            made,
            seq,
            &["frames", "background", "skeleton.yaml"],
            extra_yaml,
        ),
        truth: made.root.join("data").join(seq).join("masks"),
    }
}

impl RunDir {
    fn path(&self) -> &Path {
        self.dir.path()
    }
    /// `pipeline run pipeline.yaml --until silhouette ARGS` (these tests are about the runner
    /// and the first stage).
    fn run(&self, args: &[&str]) -> (bool, String, String) {
        let mut all = vec!["run", "pipeline.yaml", "--until", "silhouette"];
        all.extend_from_slice(args);
        run_cli(&all, self.path())
    }
    fn manifests(&self) -> usize {
        std::fs::read_dir(self.path().join("cache/silhouette"))
            .map(|d| {
                d.flatten()
                    .filter(|e| e.file_name().to_string_lossy().ends_with(".manifest.yaml"))
                    .count()
            })
            .unwrap_or(0)
    }
}

fn iou_against_truth(rd: &RunDir) -> (f64, String) {
    let (worst, at, count) = worst_silhouette_iou(rd.path(), &rd.truth);
    assert!(count > 0);
    (worst, at)
}

#[test]
fn background_subtraction_matches_the_true_masks_on_both_scenes() {
    for (made, seq) in [(tripod(), "tripod"), (humanoid(), "humanoid")] {
        let rd = run_dir(made, seq, "");
        let (ok, out, err) = rd.run(&[]);
        assert!(ok, "{err}");
        assert!(out.contains("silhouette:"), "{out}");
        let (worst, which) = iou_against_truth(&rd);
        eprintln!("{seq}: worst IoU {worst:.4} ({which})");
        assert!(worst >= 0.98, "{seq}: IoU {worst:.4} at {which}");
    }
}

#[test]
fn unchanged_runs_reuse_everything_and_a_parameter_change_reruns_its_stage() {
    let rd = run_dir(tripod(), "tripod", "");
    let (ok, out, err) = rd.run(&["--frames", "0..5"]);
    assert!(ok, "{err}");
    assert!(out.contains("silhouette: 6 computed, 0 reused"), "{out}");
    let (_, out, _) = rd.run(&["--frames", "0..5"]);
    assert!(out.contains("silhouette: 0 computed, 6 reused"), "{out}");
    assert!(out.contains("0 artifacts computed"), "{out}");
    let yaml = std::fs::read_to_string(rd.path().join("pipeline.yaml")).unwrap();
    std::fs::write(
        rd.path().join("pipeline.yaml"),
        format!("{yaml}silhouette:\n  color_threshold: 13\n"),
    )
    .unwrap();
    let (_, status, _) = run_cli(&["status", "pipeline.yaml", "--frames", "0..5"], rd.path());
    assert!(
        status
            .lines()
            .any(|l| l.split_whitespace().collect::<Vec<_>>() == ["silhouette", "0", "6", "0"]),
        "{status}"
    );
    let (_, out, _) = rd.run(&["--frames", "0..5"]);
    assert!(out.contains("silhouette: 6 computed, 0 reused"), "{out}");
    // --only re-runs the stage even when it is up to date.
    let (_, out, _) = rd.run(&["--frames", "2..3", "--only", "silhouette"]);
    assert!(out.contains("silhouette: 2 computed, 0 reused"), "{out}");
}

fn artifact_bytes(root: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    for frame in std::fs::read_dir(root.join("cache/silhouette"))
        .unwrap()
        .flatten()
    {
        if frame.path().is_dir() {
            for img in std::fs::read_dir(frame.path()).unwrap().flatten() {
                let name = format!(
                    "{}/{}",
                    frame.file_name().to_string_lossy(),
                    img.file_name().to_string_lossy()
                );
                out.push((name, std::fs::read(img.path()).unwrap()));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn a_run_killed_midway_leaves_a_cache_the_next_run_completes() {
    let rd = run_dir(tripod(), "tripod", "");
    let mut child = std::process::Command::new(pipeline_bin())
        .args(["run", "pipeline.yaml", "--until", "silhouette"])
        .current_dir(rd.path())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    while rd.manifests() < 2 && start.elapsed().as_secs() < 120 {
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    let done = rd.manifests();
    assert!(
        (2..19).contains(&done),
        "killed midway: {done} of 19 frames were done"
    );
    let (ok, out, err) = rd.run(&[]);
    assert!(ok, "{err}");
    let done_after_kill = rd.manifests();
    assert_eq!(done_after_kill, 19);
    assert!(
        out.contains(&format!("{} computed, {done} reused", 19 - done)),
        "{out}"
    );
    // Every artifact equals an uninterrupted run's.
    let clean = run_dir(tripod(), "tripod", "");
    assert!(clean.run(&[]).0);
    assert!(
        artifact_bytes(rd.path()) == artifact_bytes(clean.path()),
        "artifacts differ from a clean run"
    );
    let leftovers: Vec<_> = walk(&rd.path().join("cache"))
        .into_iter()
        .filter(|p| p.contains(".tmp-"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

fn walk(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        if e.path().is_dir() {
            out.extend(walk(&e.path()));
        } else {
            out.push(e.path().display().to_string());
        }
    }
    out
}

/// Holds a POSIX record lock on byte `frame` of `cache/.lock`, as a running pipeline that
/// computes that frame does.
fn hold_frame(cache: &Path, frame: u32) -> std::fs::File {
    use std::os::fd::AsRawFd;
    std::fs::create_dir_all(cache).unwrap();
    let file = std::fs::File::options()
        .create(true)
        .truncate(false)
        .read(true)
        .write(true)
        .open(cache.join(".lock"))
        .unwrap();
    // SAFETY: a zeroed flock is valid; fcntl on an open descriptor.
    let mut lock: libc::flock = unsafe { std::mem::zeroed() };
    lock.l_type = libc::F_WRLCK as libc::c_short;
    lock.l_whence = libc::SEEK_SET as libc::c_short;
    lock.l_start = frame as libc::off_t;
    lock.l_len = 1;
    assert_eq!(
        unsafe { libc::fcntl(file.as_raw_fd(), libc::F_SETLK, &lock) },
        0
    );
    file
}

#[test]
fn a_concurrent_run_over_the_same_frames_is_refused() {
    let rd = run_dir(tripod(), "tripod", "");
    let lock = hold_frame(&rd.path().join("cache"), 3);
    let (ok, _, err) = rd.run(&["--frames", "2..4"]);
    assert!(!ok);
    assert!(
        err.contains("another pipeline run") && err.contains("frame 3"),
        "{err}"
    );
    assert_eq!(rd.manifests(), 0);
    // Other frames are free: a shard over them runs beside the holder.
    assert!(rd.run(&["--frames", "0..1"]).0, "disjoint frames run");
    drop(lock);
    assert!(
        rd.run(&["--frames", "2..4"]).0,
        "runs once the lock is free"
    );
}

#[test]
fn shards_started_together_on_one_cache_both_finish() {
    let rd = run_dir(tripod(), "tripod", "");
    let spawn = |frames: &str| {
        std::process::Command::new(pipeline_bin())
            .args([
                "run",
                "pipeline.yaml",
                "--until",
                "visual_hull",
                "--frames",
                frames,
            ])
            .current_dir(rd.path())
            .output()
            .unwrap()
    };
    let (a, b) = std::thread::scope(|s| {
        let a = s.spawn(|| spawn("0..9"));
        let b = s.spawn(|| spawn("10..18"));
        (a.join().unwrap(), b.join().unwrap())
    });
    for out in [&a, &b] {
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let (_, out, _) = run_cli(
        &["run", "pipeline.yaml", "--until", "visual_hull"],
        rd.path(),
    );
    assert!(out.contains("visual_hull: 0 computed, 19 reused"), "{out}");
}

#[test]
fn runs_over_disjoint_frame_ranges_fill_one_cache() {
    let rd = run_dir(tripod(), "tripod", "");
    assert!(rd.run(&["--frames", "0..9"]).0);
    assert!(rd.run(&["--frames", "10..18"]).0);
    let (_, status, _) = run_cli(&["status", "pipeline.yaml"], rd.path());
    assert!(
        status
            .lines()
            .any(|l| l.split_whitespace().collect::<Vec<_>>() == ["silhouette", "19", "0", "0"]),
        "{status}"
    );
    let (_, out, _) = rd.run(&[]);
    assert!(out.contains("silhouette: 0 computed, 19 reused"), "{out}");
}

/// A bad invocation: one clear error line, non-zero exit, no panic, no artifact.
fn fails_cleanly(rd: &RunDir, args: &[&str]) -> String {
    let (ok, _, err) = run_cli(args, rd.path());
    assert!(!ok, "must fail: {args:?}");
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "one error line: {err}");
    assert_eq!(rd.manifests(), 0, "no artifact");
    err
}

#[test]
fn bad_pipeline_input_gives_clear_errors() {
    let rd = run_dir(tripod(), "tripod", "silhouette:\n  colour_threshold: 12\n");
    let err = fails_cleanly(&rd, &["run", "pipeline.yaml"]);
    assert!(
        err.contains("pipeline.yaml") && err.contains("colour_threshold") && err.contains("line 9"),
        "{err}"
    );

    let rd = run_dir(tripod(), "tripod", "silhouette:\n  color_threshold: high\n");
    let err = fails_cleanly(&rd, &["run", "pipeline.yaml"]);
    assert!(
        err.contains("pipeline.yaml") && err.contains("color_threshold") && err.contains("line 9"),
        "{err}"
    );

    let rd = run_dir(tripod(), "tripod", "");
    let yaml = std::fs::read_to_string(rd.path().join("pipeline.yaml")).unwrap();
    std::fs::write(
        rd.path().join("pipeline.yaml"),
        yaml.replace("data/tripod", "data/nowhere"),
    )
    .unwrap();
    let err = fails_cleanly(&rd, &["run", "pipeline.yaml"]);
    assert!(
        err.contains("key 'sequence'")
            && err.contains("data/nowhere")
            && err.contains("does not exist"),
        "{err}"
    );

    let rd = run_dir(tripod(), "tripod", "");
    let err = fails_cleanly(&rd, &["run", "pipeline.yaml", "--frames", "30..40"]);
    assert!(
        err.contains("30..40") && err.contains("outside the sequence") && err.contains("0..18"),
        "{err}"
    );

    let err = fails_cleanly(&rd, &["run", "pipeline.yaml", "--only", "voxels"]);
    assert!(
        err.contains("no stage 'voxels'") && err.contains("silhouette"),
        "{err}"
    );

    let err = fails_cleanly(&rd, &["run", "missing.yaml"]);
    assert!(err.contains("missing.yaml"), "{err}");
}

/// Cache keys hold what the inputs contain, not how their paths are spelled: a project run
/// by a relative path, by an absolute one, from inside its folder, and after the folder is
/// moved computes everything once.
#[test]
fn keys_do_not_depend_on_how_the_project_path_is_spelled() {
    let outer = tempfile::tempdir().unwrap();
    let project = outer.path().join("pk");
    copy_sample(&project);
    let until = ["--until", "model", "--frames", "0..2"];
    let run = |file: &Path, cwd: &Path| {
        let mut args = vec!["run", file.to_str().unwrap()];
        args.extend(until);
        let (ok, out, err) = run_cli(&args, cwd);
        assert!(ok, "{err}");
        out
    };
    let first = run(Path::new("pk/pipeline.yaml"), outer.path());
    assert!(!first.contains("0 artifacts computed"), "{first}");
    let absolute = project.join("pipeline.yaml");
    for (file, cwd) in [
        (absolute.as_path(), outer.path()),
        (Path::new("pipeline.yaml"), project.as_path()),
    ] {
        let out = run(file, cwd);
        assert!(
            out.contains("0 artifacts computed"),
            "{}: {out}",
            file.display()
        );
    }
    let moved = outer.path().join("elsewhere/pk2");
    std::fs::create_dir_all(moved.parent().unwrap()).unwrap();
    std::fs::rename(&project, &moved).unwrap();
    let out = run(Path::new("pipeline.yaml"), &moved);
    assert!(out.contains("0 artifacts computed"), "moved: {out}");
}

/// A cached file changed after it was written (one byte flipped, or cut short) is never
/// used: `status` counts its artifact as missing and the next run recomputes it with a note,
/// for every kind of artifact.
#[test]
fn damaged_cache_files_are_recomputed_with_a_note() {
    let outer = tempfile::tempdir().unwrap();
    let project = outer.path().join("pk");
    copy_sample(&project);
    let args = ["run", "pipeline.yaml", "--frames", "0..1", "--until", "fit"];
    let (ok, _, err) = run_cli(&args, &project);
    assert!(ok, "{err}");
    let cache = project.join("cache");
    // One file of each kind: flipped bytes in the middle, or cut short.
    let damaged = [
        ("silhouette", "000001/cam00.png", false),
        ("visual_hull", "000001.grid", false),
        ("visual_hull", "000000.ply", true),
        ("graphcut", "000001.ply", false),
        ("reliability", "000001.obs", false),
        ("model", "model.hpm", true),
        ("fit", "000001.pose.csv", false),
    ];
    for (stage, file, truncate) in damaged {
        let path = cache.join(stage).join(file);
        let mut bytes = std::fs::read(&path).unwrap();
        if truncate {
            bytes.truncate(bytes.len() / 2);
        } else {
            let mid = bytes.len() / 2;
            bytes[mid] ^= 0xff;
        }
        std::fs::write(&path, bytes).unwrap();
    }
    let (_, status, _) = run_cli(&["status", "pipeline.yaml", "--frames", "0..1"], &project);
    for stage in [
        "silhouette",
        "visual_hull",
        "graphcut",
        "reliability",
        "model",
        "fit",
    ] {
        let row = status
            .lines()
            .find(|l| l.split_whitespace().next() == Some(stage))
            .unwrap_or_else(|| panic!("{status}"));
        let missing: usize = row.split_whitespace().last().unwrap().parse().unwrap();
        assert!(missing >= 1, "{stage} not flagged: {status}");
    }
    let (ok, out, err) = run_cli(&args, &project);
    assert!(ok, "{err}");
    let text = format!("{out}{err}");
    for (stage, file, _) in damaged {
        let frame = if file.starts_with("000001") { 1 } else { 0 };
        assert!(
            text.contains(&format!(
                "{stage}: the cached artifact of frame {frame} was damaged"
            )),
            "{stage}/{file}: {text}"
        );
    }
    // Everything is whole again.
    let (_, out, _) = run_cli(&args, &project);
    assert!(!out.contains("damaged"), "{out}");
}
