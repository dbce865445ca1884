//! `pipeline report` on the bundled sample: the page is self-contained (no script, style or
//! data fetched from anywhere), and in a real browser (Debian's Chromium, headless, driven
//! by puppeteer-core through `tools/check_report.cjs`, opened from the file system) it logs
//! no error, draws the model where its vertices project, and follows the slider to frame 4
//! with the overlay and the pose; in Firefox ESR (headless here without WebGL) the page says
//! the 3D view is unavailable and the rest works. The browser checks are skipped with a note
//! when a browser or puppeteer-core is missing, and required with `HULLPOSE_EXTERNAL_CHECKS=1`
//! (as CI sets).
//!
//! The sample's first camera is renamed `c<!--#1?x%2e` and pipeline.yaml carries a comment
//! with `<!--`: the page's data stays valid JSON and the overlay link finds its file.

use crate::common;

use common::*;
use std::path::Path;
use std::process::Command;

/// A camera name that breaks a page whose data is escaped wrongly (`<!--` in a script
/// element) or whose links are joined as text (`#`, `?`, `%2e`).
const HOSTILE_CAMERA: &str = "c<!--#1?x%2e";

/// Renames camera `from` of the sample in `d` to `to`: the calibration, its frame and mask
/// folders and its background plate.
fn rename_camera(d: &Path, from: &str, to: &str) {
    let calib = d.join("calib/cameras.yaml");
    let text = std::fs::read_to_string(&calib).unwrap();
    let quoted = serde_json::to_string(to).unwrap();
    std::fs::write(
        &calib,
        text.replace(&format!("name: {from}\n"), &format!("name: {quoted}\n")),
    )
    .unwrap();
    let seq = d.join("data/tripod");
    for folder in ["frames", "masks"] {
        if seq.join(folder).join(from).exists() {
            std::fs::rename(seq.join(folder).join(from), seq.join(folder).join(to)).unwrap();
        }
    }
    let plate = seq.join(format!("background/{from}.png"));
    if plate.exists() {
        std::fs::rename(plate, seq.join(format!("background/{to}.png"))).unwrap();
    }
}

#[test]
fn the_report_opens_from_disk_draws_the_model_and_follows_the_slider() {
    let dir = process_tempdir();
    let d = dir.path();
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    copy_sample(d);
    rename_camera(d, "cam00", HOSTILE_CAMERA);
    let yaml = d.join("pipeline.yaml");
    let text = std::fs::read_to_string(&yaml).unwrap();
    std::fs::write(&yaml, format!("# old <!-- see wiki -->\n{text}")).unwrap();

    // Before a run there is nothing to show: one clear error, nothing written.
    let (ok, _, err) = run_cli(&["report", "pipeline.yaml"], d);
    assert!(!ok);
    assert!(err.contains("run `pipeline run"), "{err}");
    assert!(!d.join("output/report").exists());

    let (ok, _, err) = run_cli(&["run", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    let (ok, _, err) = run_cli(&["evaluate", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    let (ok, out, err) = run_cli(&["report", "pipeline.yaml"], d);
    assert!(ok, "{err}");
    assert!(
        out.contains("output/report/index.html (7 frames, surfaces of 7"),
        "{out}"
    );
    let page = std::fs::read_to_string(d.join("output/report/index.html")).unwrap();
    // Self-contained: every script inline, no stylesheet or module loaded from elsewhere.
    assert!(
        !page.contains("<script src") && !page.contains("<link"),
        "external resources"
    );
    assert!(!page.contains("type=\"module\""));
    // Every kept frame's refined surface, hull and tracked surface (the run made all three).
    for kind in ["graphcut", "hull", "tracked"] {
        assert_eq!(
            page.matches(&format!("id=\"surface-{kind}-")).count(),
            7,
            "{kind}"
        );
    }
    assert!(page.contains("Three.js Authors") && page.contains("SPDX-License-Identifier: MIT"));
    // The data element holds no `<` at all (every one escaped as \u003c) and parses as JSON.
    let start = page.find("id=\"report-data\"").expect("the data element");
    let body = &page[page[start..].find('>').unwrap() + start + 1..];
    let json = &body[..body.find("</script>").unwrap()];
    assert!(!json.contains('<'), "unescaped < in the page's data");
    let data: serde_json::Value = serde_json::from_str(json).expect("the page's data is JSON");
    assert_eq!(data["cameras"][0], HOSTILE_CAMERA);
    // The evaluation's tables and the fit's health are in it.
    assert!(page.contains("joint_error.csv") && page.contains("iou_worst"));

    let node = Command::new("node")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    let chromium = std::env::var("CHROMIUM").unwrap_or_else(|_| "/usr/bin/chromium".into());
    let puppeteer = repo.join("tools/node_modules/puppeteer-core").is_dir();
    let required = std::env::var("HULLPOSE_EXTERNAL_CHECKS").is_ok_and(|v| v == "1");
    if !(node && Path::new(&chromium).exists() && puppeteer) {
        assert!(
            !required,
            "node, {chromium} and tools/node_modules/puppeteer-core are required \
             (HULLPOSE_EXTERNAL_CHECKS=1): apt install chromium; npm ci --prefix tools"
        );
        eprintln!("browser check skipped: node, {chromium} or puppeteer-core missing");
        return;
    }
    let shots = d.join("shots");
    std::fs::create_dir_all(&shots).unwrap();
    let check = |browser: &str| {
        let out = Command::new("node")
            .arg(repo.join("tools/check_report.cjs"))
            .arg(d.join("output/report/index.html"))
            .arg(&shots)
            .env("NODE_PATH", repo.join("tools/node_modules"))
            .env("BROWSER", browser)
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        let stderr = String::from_utf8_lossy(&out.stderr);
        eprintln!("{stdout}");
        assert!(out.status.success(), "{browser}: {stderr}\n{stdout}");
        stdout
    };
    let chromium_figures = check("chromium");
    assert!(
        chromium_figures.contains("\"webgl\":true"),
        "{chromium_figures}"
    );
    for shot in [
        "report-frame0.png",
        "report-frame4.png",
        "report-frame4-surface.png",
    ] {
        let img = image::open(shots.join(shot)).unwrap();
        assert!(img.width() >= 1000, "{shot}");
    }
    // Firefox ESR when installed: the page works there too (with or without WebGL).
    let firefox = std::env::var("FIREFOX").unwrap_or_else(|_| "/usr/bin/firefox-esr".into());
    if Path::new(&firefox).exists() {
        check("firefox");
    } else {
        assert!(
            !required,
            "{firefox} is required (HULLPOSE_EXTERNAL_CHECKS=1): apt install firefox-esr"
        );
        eprintln!("Firefox check skipped: {firefox} missing");
    }
}
