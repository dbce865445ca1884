//! Hostile and broken captures: names that would become paths outside the run are refused
//! and nothing is written outside the run's folders; a PLY header claiming 4e9 vertices in a
//! 1 KB file, a PNG header claiming 100000 x 100000 pixels and a 100 MB YAML are refused with
//! clear errors while the process's peak memory stays under 100 MB (each case runs in a
//! fresh child process that reports its VmHWM from /proc/self/status).

use crate::common;

use common::*;
use std::path::Path;

/// Every path under `dir`, relative.
fn tree(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let rel = e.file_name().to_string_lossy().into_owned();
        out.push(rel.clone());
        if e.path().is_dir() {
            out.extend(tree(&e.path()).into_iter().map(|r| format!("{rel}/{r}")));
        }
    }
    out.sort();
    out
}

#[test]
fn camera_names_that_are_paths_are_refused_and_nothing_escapes() {
    // As YAML double-quoted scalars.
    for name in [
        r#""../../escape""#,
        r#""a/b""#,
        "\"..\"",
        r#""a\\b""#,
        r#""bad\abell""#,
    ] {
        let outer = tempfile::tempdir().unwrap();
        let run = outer.path().join("deep/run");
        copy_sample(&run);
        let calib = run.join("calib/cameras.yaml");
        let text = std::fs::read_to_string(&calib).unwrap();
        std::fs::write(
            &calib,
            text.replacen("name: cam00\n", &format!("name: {name}\n"), 1),
        )
        .unwrap();
        assert_ne!(std::fs::read_to_string(&calib).unwrap(), text, "renamed");
        let before = tree(outer.path());
        for args in [
            &["run", "pipeline.yaml"][..],
            &["check", "pipeline.yaml"],
            &["export", "pipeline.yaml"],
            &["slurm", "pipeline.yaml"],
        ] {
            let (ok, _, err) = run_cli(args, &run);
            assert!(!ok, "{name}: {args:?} must fail");
            assert!(
                err.contains("cameras.yaml") && err.contains("name"),
                "{name}: {args:?}: {err}"
            );
            assert!(!err.contains("panicked"), "{err}");
        }
        assert_eq!(tree(outer.path()), before, "{name}: files appeared");
    }
}

#[test]
fn camera_names_equal_but_for_case_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cameras.yaml");
    let cam = |name: &str| {
        format!(
            "  - name: {name}\n    width: 4\n    height: 3\n    K: [[2.0, 0.0, 1.5], [0.0, 2.0, 1.0], [0.0, 0.0, 1.0]]\n    R: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]\n    t: [0.0, 0.0, 1.0]\n"
        )
    };
    std::fs::write(&path, format!("cameras:\n{}{}", cam("Cam0"), cam("cam0"))).unwrap();
    let err = hullpose::camera::read_cameras(&path)
        .unwrap_err()
        .to_string();
    assert!(err.contains("cam0") && err.contains("case"), "{err}");
}

#[test]
fn bone_names_that_break_files_are_refused() {
    for bad in ["a,b", "a b", "../x", "\"q\""] {
        let text = format!(
            "reference_frame: 0\nbones:\n  - name: {bad:?}\n    parent: null\n    head: [0, 0, 0]\n    tail: [0, 0, 1]\n"
        );
        let err = hullpose::skeleton::Skeleton::parse(Path::new("skeleton.yaml"), &text)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("skeleton.yaml") && err.contains("bone"),
            "{bad}: {err}"
        );
    }
}

/// Peak resident memory of this process, kB.
fn peak_kb() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap()
}

/// CRC-32 (IEEE) of PNG chunks.
fn crc32(bytes: &[u8]) -> u32 {
    let mut c = 0xffff_ffffu32;
    for &b in bytes {
        c ^= b as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 {
                0xedb8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// A PNG file whose header says `w` x `h` pixels (RGB, 8-bit) with a tiny body.
fn png_claiming(w: u32, h: u32) -> Vec<u8> {
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut chunk = |kind: &[u8], data: &[u8]| {
        out.extend((data.len() as u32).to_be_bytes());
        let mut body = kind.to_vec();
        body.extend(data);
        out.extend(&body);
        out.extend(crc32(&body).to_be_bytes());
    };
    let mut ihdr = Vec::new();
    ihdr.extend(w.to_be_bytes());
    ihdr.extend(h.to_be_bytes());
    ihdr.extend([8, 2, 0, 0, 0]);
    chunk(b"IHDR", &ihdr);
    chunk(b"IDAT", &[0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01]);
    chunk(b"IEND", &[]);
    out
}

/// One hostile case, run in this child process (selected by HULLPOSE_HOSTILE_CASE): the
/// error text, then the peak memory.
fn hostile_case(case: &str, dir: &Path) -> String {
    match case {
        "ply" => {
            let path = dir.join("huge.ply");
            let mut bytes = b"ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
            bytes.resize(1024, 0);
            std::fs::write(&path, bytes).unwrap();
            hullpose::geometry::ply::read_ply(&path)
                .unwrap_err()
                .to_string()
        }
        "png" => {
            let side = 100_000;
            std::fs::create_dir_all(dir.join("calib")).unwrap();
            let calib = dir.join("calib/cameras.yaml");
            std::fs::write(
                &calib,
                format!(
                    "cameras:\n  - name: cam00\n    width: {side}\n    height: {side}\n    K: [[1000.0, 0.0, 50000.0], [0.0, 1000.0, 50000.0], [0.0, 0.0, 1.0]]\n    R: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]\n    t: [0.0, 0.0, 3.0]\n"
                ),
            )
            .unwrap();
            let frames = dir.join("seq/frames/cam00");
            std::fs::create_dir_all(&frames).unwrap();
            std::fs::write(frames.join("000000.png"), png_claiming(side, side)).unwrap();
            let seq = hullpose::dataset::Sequence::open_with_calibration(&calib, &dir.join("seq"))
                .unwrap();
            seq.load_frame(0, 0).unwrap_err().to_string()
        }
        "yaml" => {
            use std::io::Write;
            let path = dir.join("pipeline.yaml");
            let mut w = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
            w.write_all(b"calibration: calib/cameras.yaml\nsequence: seq\n")
                .unwrap();
            let filler = "# padding padding padding padding padding padding padding padding\n";
            for _ in 0..(100 << 20) / filler.len() + 1 {
                w.write_all(filler.as_bytes()).unwrap();
            }
            drop(w);
            hullpose::config::Config::load(&path)
                .unwrap_err()
                .to_string()
        }
        other => panic!("unknown case {other}"),
    }
}

/// The child side: runs the case named in the environment, prints its error and peak memory.
#[test]
fn hostile_case_child() {
    let Ok(case) = std::env::var("HULLPOSE_HOSTILE_CASE") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let err = hostile_case(&case, dir.path());
    println!("ERROR: {err}");
    println!("PEAK_KB: {}", peak_kb());
}

#[test]
fn huge_claims_are_refused_within_100_mb() {
    for (case, expect) in [
        ("ply", "header's element counts"),
        ("png", "HULLPOSE_MAX_IMAGE_MEGAPIXELS"),
        ("yaml", "HULLPOSE_MAX_TEXT_MB"),
    ] {
        let out = std::process::Command::new(std::env::current_exe().unwrap())
            .args([
                "--exact",
                "hostile_input::hostile_case_child",
                "--nocapture",
                "--test-threads",
                "1",
            ])
            .env("HULLPOSE_HOSTILE_CASE", case)
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout).into_owned();
        assert!(
            out.status.success(),
            "{case}: {text}\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let err = text
            .lines()
            .find_map(|l| l.split_once("ERROR: ").map(|x| x.1))
            .unwrap_or_else(|| panic!("{case}: {text}"));
        assert!(err.contains(expect), "{case}: {err}");
        let peak: u64 = text
            .lines()
            .find_map(|l| l.split_once("PEAK_KB: ").map(|x| x.1))
            .and_then(|v| v.trim().parse().ok())
            .unwrap();
        eprintln!("{case}: refused ({err}); peak memory {} MB", peak / 1024);
        assert!(peak < 100 * 1024, "{case}: peak memory {peak} kB");
    }
}

/// Runs `pipeline ARGS` in `cwd`, killing it after 60 s: (exit success, stderr), or `None`
/// when it had to be killed.
fn run_cli_bounded(args: &[&str], cwd: &Path) -> Option<(bool, String)> {
    use std::io::Read;
    let mut child = std::process::Command::new(pipeline_bin())
        .args(args)
        .current_dir(cwd)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let started = std::time::Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            let mut err = String::new();
            child
                .stderr
                .take()
                .unwrap()
                .read_to_string(&mut err)
                .unwrap();
            return Some((status.success(), err));
        }
        if started.elapsed().as_secs() > 60 {
            let _ = child.kill();
            let _ = child.wait();
            return None;
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

/// A symlink to a device or a FIFO in place of an input is refused by name, at once, with
/// no memory blow-up (these read /dev/urandom until killed, or blocked forever).
#[test]
fn non_regular_inputs_are_refused_by_name() {
    let outer = tempfile::tempdir().unwrap();
    let run = outer.path().join("run");
    copy_sample(&run);
    let seq = run.join("data/tripod");
    let cases: [(&str, &str, &str); 3] = [
        ("skeleton.yaml", "/dev/urandom", "a device"),
        ("ground_truth/joints.csv", "/dev/zero", "a device"),
        ("frames/cam00/000002.png", "/dev/urandom", "a device"),
    ];
    for (file, target, kind) in cases {
        let path = seq.join(file);
        let saved = run.join("saved");
        std::fs::rename(&path, &saved).unwrap();
        std::os::unix::fs::symlink(target, &path).unwrap();
        let (ok, err) = run_cli_bounded(&["check", "pipeline.yaml"], &run)
            .unwrap_or_else(|| panic!("{file} -> {target}: check did not end within 60 s"));
        assert!(!ok, "{file} -> {target}: accepted");
        assert!(
            err.contains(file) && err.contains(kind) && err.contains("not a regular file"),
            "{file} -> {target}: {err}"
        );
        std::fs::remove_file(&path).unwrap();
        std::fs::rename(&saved, &path).unwrap();
    }
    // A FIFO as the pipeline file.
    let fifo = run.join("fifo.yaml");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap();
    assert!(made.success());
    let (ok, err) = run_cli_bounded(&["check", "fifo.yaml"], &run)
        .expect("a FIFO as the pipeline file: check did not end within 60 s");
    assert!(
        !ok && err.contains("fifo.yaml") && err.contains("FIFO"),
        "{err}"
    );
    // The untouched capture still checks clean.
    let (ok, err) = run_cli_bounded(&["check", "pipeline.yaml"], &run).unwrap();
    assert!(ok, "{err}");
}

/// Outputs that would land on the capture's inputs are refused before anything is written:
/// `output:` or `cache:` inside (or around) the sequence folder, or the root, and `render
/// --out` onto a frame or the calibration.
#[test]
fn outputs_over_inputs_are_refused() {
    let outer = tempfile::tempdir().unwrap();
    let run = outer.path().join("run");
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    copy_sample_capture(&run);
    let yaml = std::fs::read_to_string(repo.join("pipeline.yaml")).unwrap();
    let truth = run.join("data/tripod/ground_truth/joints.csv");
    let before = std::fs::read(&truth).unwrap();
    for (key, value) in [
        ("output", "data/tripod/ground_truth"),
        ("output", "./data/tripod/../tripod"),
        ("cache", "data/tripod/cache"),
        ("output", "data"),
        ("cache", "/"),
    ] {
        let text = yaml.replace(&format!("{key}: {key}"), &format!("{key}: {value}"));
        assert_ne!(text, yaml, "{key} not found in pipeline.yaml");
        std::fs::write(run.join("p.yaml"), text).unwrap();
        let (ok, _, err) = run_cli(&["run", "p.yaml"], &run);
        assert!(!ok, "{key}: {value}: accepted");
        assert!(
            err.contains(&format!("key '{key}'")),
            "{key}: {value}: {err}"
        );
    }
    assert_eq!(std::fs::read(&truth).unwrap(), before);
    std::fs::write(run.join("pipeline.yaml"), &yaml).unwrap();
    for out in ["data/tripod/frames/cam01/000000.png", "calib/cameras.yaml"] {
        let (ok, _, err) = run_cli(&["render", "pipeline.yaml", "--out", out], &run);
        assert!(
            !ok && err.contains("--out") && err.contains("overwrite"),
            "{out}: {err}"
        );
    }
    assert!(tree(&run)
        .iter()
        .all(|f| !f.contains("cache") && !f.contains("output")));
}

/// The sweep of dead runs' temporary files follows no symlink: a symlink loop in the cache
/// does not hang a run, and a dead run's temporary file behind a symlink to a folder outside
/// the cache survives, while the same file inside the cache is removed.
#[test]
fn the_temporary_sweep_stays_inside_the_cache() {
    let outer = tempfile::tempdir().unwrap();
    let run = outer.path().join("run");
    copy_sample(&run);
    let args = [
        "run",
        "pipeline.yaml",
        "--until",
        "silhouette",
        "--frames",
        "0..0",
    ];
    let (ok, err) = run_cli_bounded(&args, &run).unwrap();
    assert!(ok, "{err}");
    let mut child = std::process::Command::new("true").spawn().unwrap();
    let dead = child.id();
    child.wait().unwrap();
    let temp = format!(".x.tmp-{}-{dead}-0", hullpose::fsutil::host_name());
    let outside = outer.path().join("outside");
    std::fs::create_dir_all(&outside).unwrap();
    std::fs::write(outside.join(&temp), "keep").unwrap();
    let cache = run.join("cache");
    std::fs::write(cache.join("silhouette").join(&temp), "stale").unwrap();
    std::os::unix::fs::symlink(&outside, cache.join("silhouette/elsewhere")).unwrap();
    std::os::unix::fs::symlink(&cache, cache.join("loop")).unwrap();
    std::os::unix::fs::symlink("..", cache.join("silhouette/up")).unwrap();
    let (ok, err) = run_cli_bounded(&args, &run).expect("the run did not end within 60 s");
    assert!(ok, "{err}");
    assert!(
        outside.join(&temp).exists(),
        "a file outside the cache was removed"
    );
    assert!(!cache.join("silhouette").join(&temp).exists());
}

/// What `run` would refuse only after minutes of work, `check` refuses at once, and `run`
/// before its first stage: one camera, a reference frame outside the sequence, an overlay
/// camera that does not exist, images over the pixel cap, a camera name too long for a
/// file name.
#[test]
fn check_refuses_what_run_would_refuse_later() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let calib_text = std::fs::read_to_string(repo.join("calib/cameras.yaml")).unwrap();
    let second = calib_text.find("  - name: cam01").unwrap();
    let long_name = "c".repeat(251);
    type Edit = Box<dyn Fn(&Path)>;
    let cases: Vec<(&str, Edit, &str)> = vec![
        (
            "one camera",
            Box::new(move |run: &Path| {
                std::fs::write(run.join("calib/cameras.yaml"), &calib_text[..second]).unwrap()
            }),
            "at least two cameras",
        ),
        (
            "reference frame 99",
            Box::new(|run: &Path| {
                let path = run.join("data/tripod/skeleton.yaml");
                let text = std::fs::read_to_string(&path).unwrap();
                std::fs::write(
                    &path,
                    text.replace("reference_frame: 0", "reference_frame: 99"),
                )
                .unwrap()
            }),
            "reference_frame 99",
        ),
        (
            "overlay camera",
            Box::new(|run: &Path| {
                let path = run.join("pipeline.yaml");
                let text = std::fs::read_to_string(&path).unwrap();
                let text = text.replace("export:\n", "export:\n  overlay_cameras: [nope]\n");
                std::fs::write(&path, text).unwrap()
            }),
            "overlay_cameras",
        ),
        (
            "3600 megapixels",
            Box::new(|run: &Path| {
                let path = run.join("calib/cameras.yaml");
                let text = std::fs::read_to_string(&path).unwrap();
                let text = text.replacen(
                    "width: 256\n    height: 192",
                    "width: 60000\n    height: 60000",
                    1,
                );
                std::fs::write(&path, text).unwrap();
                for folder in ["frames", "masks"] {
                    let dir = run.join("data/tripod").join(folder).join("cam00");
                    for e in std::fs::read_dir(&dir).unwrap() {
                        std::fs::write(e.unwrap().path(), png_claiming(60000, 60000)).unwrap();
                    }
                }
                let plate = run.join("data/tripod/background/cam00.png");
                std::fs::write(plate, png_claiming(60000, 60000)).unwrap();
            }),
            "HULLPOSE_MAX_IMAGE_MEGAPIXELS",
        ),
        (
            "a 251-character camera name",
            Box::new(move |run: &Path| {
                let path = run.join("calib/cameras.yaml");
                let text = std::fs::read_to_string(&path).unwrap();
                std::fs::write(
                    &path,
                    text.replacen("name: cam00", &format!("name: {long_name}"), 1),
                )
                .unwrap();
                for folder in ["frames", "masks"] {
                    let dir = run.join("data/tripod").join(folder);
                    let _ = std::fs::rename(dir.join("cam00"), dir.join(&long_name));
                }
            }),
            "bytes long",
        ),
    ];
    for (what, edit, expect) in cases {
        let outer = tempfile::tempdir().unwrap();
        let run = outer.path().join("run");
        copy_sample(&run);
        edit(&run);
        for command in ["check", "run"] {
            let (ok, err) = run_cli_bounded(&[command, "pipeline.yaml"], &run).unwrap();
            assert!(!ok, "{what}: {command} accepted it");
            assert!(err.contains(expect), "{what}: {command}: {err}");
        }
        assert!(
            !run.join("cache").exists(),
            "{what}: run computed something"
        );
    }
}

/// Errors say what is wrong: a non-finite vertex (not "missing properties"), a calibration
/// path that is a folder, a cache path that is a file, an environment cap that is no
/// number, and a camera name with an escape character, never echoed raw.
#[test]
fn messages_say_what_is_wrong() {
    let outer = tempfile::tempdir().unwrap();
    for (value, text) in [("nan", "nan"), ("inf", "inf")] {
        let path = outer.path().join(format!("{value}.ply"));
        std::fs::write(
            &path,
            format!("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 {text}\n0 1 0\n3 0 1 2\n"),
        )
        .unwrap();
        let err = hullpose::geometry::ply::read_ply(&path)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("vertex 1 has a non-finite coordinate"),
            "{value}: {err}"
        );
    }
    let run = outer.path().join("run");
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    copy_sample_capture(&run);
    let yaml = std::fs::read_to_string(repo.join("pipeline.yaml")).unwrap();
    let check = |text: &str, env: Option<(&str, &str)>| -> String {
        std::fs::write(run.join("p.yaml"), text).unwrap();
        let mut command = std::process::Command::new(pipeline_bin());
        command
            .args(["run", "p.yaml", "--until", "silhouette"])
            .current_dir(&run);
        if let Some((k, v)) = env {
            command.env(k, v);
        }
        let out = command.output().unwrap();
        assert!(!out.status.success(), "{text}");
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let err = check(&yaml.replace("calib/cameras.yaml", "calib"), None);
    assert!(err.contains("is not a regular file"), "{err}");
    std::fs::write(run.join("cache"), "a file").unwrap();
    let err = check(&yaml, None);
    assert!(err.contains("is a file, but a folder is needed"), "{err}");
    std::fs::remove_file(run.join("cache")).unwrap();
    let err = check(&yaml, Some(("HULLPOSE_MAX_TEXT_MB", "lots")));
    assert!(
        err.contains("HULLPOSE_MAX_TEXT_MB") && err.contains("lots"),
        "{err}"
    );
    let calib = run.join("calib/cameras.yaml");
    let text = std::fs::read_to_string(&calib).unwrap();
    std::fs::write(
        &calib,
        text.replacen("name: cam00", "name: \"cam\\e[31m00\"", 1),
    )
    .unwrap();
    let err = check(&yaml, None);
    assert!(
        err.contains("control characters") && !err.contains('\u{1b}'),
        "{err:?}"
    );
}

/// YAML whose brackets nest 200,000 levels deep (400 KB) is refused by its depth, not
/// parsed (the parser took 86 s to reject it).
#[test]
fn deeply_nested_yaml_is_refused_by_its_depth() {
    let dir = tempfile::tempdir().unwrap();
    let text = format!(
        "calibration: x\nsequence: y\nfit: {}{}\n",
        "[".repeat(200_000),
        "]".repeat(200_000)
    );
    std::fs::write(dir.path().join("deep.yaml"), text).unwrap();
    let (ok, err) = run_cli_bounded(&["check", "deep.yaml"], dir.path())
        .expect("the check did not end within 60 s");
    assert!(!ok && err.contains("nest 200000 levels deep"), "{err}");
}
