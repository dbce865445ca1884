//! `pipeline report`: one HTML page, `<output>/report/index.html`, to look at a run: the
//! fitted model playing its motion in a 3D view (three.js, vendored into the page), the
//! frame's refined surface, visual hull and tracked surface (where the surface stage ran) as
//! toggles, the skeleton over it, a frame slider
//! synchronised with a camera's overlay and the contact sheet, the fit's health as plots,
//! the run summary, the parameters, and `pipeline evaluate`'s tables when it has run.
//!
//! The page is self-contained: scripts and data are inline (a browser blocks ES modules and
//! `fetch` on `file://`), so it opens by double-click with no server and no network; only
//! the overlay pictures are linked, as images, from `<output>/export/overlays/`. The model
//! travels once, coarsened (vertex clustering at [`MODEL_CELL`]), with one 3x4 matrix per
//! bone and frame, skinned in the page; the surfaces are coarsened further, quantised to
//! millimetres, and kept for at most [`SURFACE_FRAMES`] frames (evenly spread), each
//! parsed only when shown, so a 1,000-frame run stays a few megabytes.

use crate::error::{Error, Result};
use crate::fit::health::{silhouette_iou, CoarseModel};
use crate::geometry::TriMesh;
use crate::runner::Job;
use crate::skeleton::PosedBones;
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// The model's coarsening cell in the page, metres.
const MODEL_CELL: f64 = 0.015;
/// The surfaces' coarsening cell in the page, metres.
const SURFACE_CELL: f64 = 0.03;
/// Frames whose surfaces the page carries, at most.
const SURFACE_FRAMES: usize = 60;

const THREE: &str = include_str!("../../assets/three/three.min.js");
const PAGE: &str = include_str!("../../assets/report/page.html");
const SCRIPT: &str = include_str!("../../assets/report/report.js");
const STYLE: &str = include_str!("../../assets/report/report.css");

/// What [`write`] made.
pub struct Written {
    pub path: PathBuf,
    pub frames: usize,
    /// Frames whose surfaces the page carries.
    pub surface_frames: usize,
    pub bytes: usize,
}

/// Writes `<output>/report/index.html` for the job's frames from the cache and outputs
/// (`pipeline run` must have run: the error says so otherwise).
pub fn write(job: &Job) -> Result<Written> {
    if job.sequence.skeleton()?.is_none() {
        return Err(Error::Usage(format!(
            "the report shows the fitted motion, and {} has no skeleton.yaml: make one with \
             `pipeline skeleton {}`, then `pipeline run`",
            job.sequence.dir.display(),
            job.config.path.display()
        )));
    }
    job.require_cached(&["silhouette", "visual_hull", "graphcut", "model", "fit"])?;
    let output = &job.config.output;
    let fit_csv = output.join("fit.csv");
    let health_rows = read_csv(&fit_csv)?;
    let cache = &job.cache;
    let cameras = &job.sequence.cameras;
    let frames = job.frames.clone();
    let ctx = job.context();
    let (model, poses) = crate::export::load_motion(&ctx, &frames)?;
    let coarse = CoarseModel::new(&model.mesh, MODEL_CELL);
    // The exports' frame: the world's up as +Y, its floor at Y = 0.
    let (frame, _) = crate::export::export_frame(&ctx, &model, &poses);
    let up = |v: &Vector3<f64>| frame.point(v);
    let lift = Vector3::y() * frame.floor;

    // Each frame's bone matrices [C R C^T | C (h - R h0)] (world turned Y-up), and the
    // per-camera silhouette IoU of the posed model.
    let per_frame: Vec<(Vec<f64>, Vec<f64>)> = frames
        .par_iter()
        .map(|&f| {
            let pose = &poses
                .iter()
                .find(|(g, _)| *g == f)
                .expect("a pose for every frame")
                .1;
            let bones = PosedBones::new(&model.skeleton, pose);
            let mut m = Vec::with_capacity(12 * bones.rotations.len());
            for b in 0..bones.rotations.len() {
                // World x -> R x + t becomes, in the export frame y = C x - f Y,
                // y -> R' y + C t + (R' - I) f Y with R' = C R Cᵀ.
                let turned = frame.turn(&bones.rotations[b]);
                let r: Matrix3<f64> = *turned.matrix();
                let t = frame.vector(&(bones.heads[b] - bones.rotations[b] * bones.rest_heads[b]))
                    + (turned * lift - lift);
                for row in 0..3 {
                    m.extend([r[(row, 0)], r[(row, 1)], r[(row, 2)], t[row]].map(round5));
                }
            }
            let masks = crate::artifacts::silhouettes::read(cache, f, cameras)?;
            // Measured as the fit's health measures it (fit.csv's IoU).
            let posed = crate::fit::surface_layer::follow(
                &coarse.posed(&model.pose(pose)),
                &crate::stages::fit::cached_observation(&ctx, f)?.vertices,
                job.config.fit.health.surface_reach,
            );
            let iou = silhouette_iou(cameras, &masks, &posed)
                .into_iter()
                .map(|x| (x * 1e4).round() / 1e4)
                .collect();
            Ok((m, iou))
        })
        .collect::<Result<_>>()?;

    // The coarse model at t0: positions, triangles, skin (up to 4 influences), colours.
    let mut positions = Vec::new();
    let mut skin = Vec::new();
    let mut colours = Vec::new();
    for &i in coarse.kept() {
        positions.extend(up(&model.mesh.vertices[i]).iter().map(|&x| round5(x)));
        let mut w: Vec<(usize, f64)> = model.weights[i].clone();
        w.sort_by(|a, b| b.1.total_cmp(&a.1));
        w.truncate(4);
        let sum: f64 = w.iter().map(|x| x.1).sum::<f64>().max(1e-12);
        for k in 0..4 {
            let (b, x) = w.get(k).copied().unwrap_or((0, 0.0));
            skin.push(json!([b, round5(x / sum)]));
        }
        let rgb = crate::skeleton::model::part_colour(model.labels[i]);
        colours.extend(rgb.map(|x| (x as f64 / 255.0 * 1000.0).round() / 1000.0));
    }
    let indices: Vec<u32> = coarse.triangles().iter().flatten().copied().collect();
    let bones: Vec<Value> = model
        .skeleton
        .bones
        .iter()
        .map(|b| {
            json!({
                "name": b.name,
                "parent": b.parent,
                "head": up(&b.head).iter().map(|&x| round5(x)).collect::<Vec<_>>(),
                "tail": up(&b.tail).iter().map(|&x| round5(x)).collect::<Vec<_>>(),
            })
        })
        .collect();

    // Surfaces for at most SURFACE_FRAMES frames, evenly spread.
    let stride = frames.len().div_ceil(SURFACE_FRAMES).max(1);
    let surface_frames: Vec<u32> = frames.iter().copied().step_by(stride).collect();
    // Each as (kind, JSON): the refined surface, the hull, and the tracked surface where the
    // surface stage has run.
    let surfaces: Vec<(u32, Vec<(&str, String)>)> = surface_frames
        .par_iter()
        .map(|&f| {
            let mesh = |s| -> Result<String> {
                let m = crate::artifacts::reconstruction::read_mesh(cache, s, f)?;
                Ok(coarse_surface(&m, &frame).to_string())
            };
            use crate::artifacts::reconstruction::Surface;
            let mut kinds = vec![
                ("graphcut", mesh(Surface::Refined)?),
                ("hull", mesh(Surface::Hull)?),
            ];
            if crate::artifacts::tracked_surface::ply_path(cache, f).is_file() {
                let m = crate::artifacts::tracked_surface::read_mesh(cache, f)?;
                kinds.push(("tracked", coarse_surface(&m, &frame).to_string()));
            }
            Ok((f, kinds))
        })
        .collect::<Result<_>>()?;

    let overlays = output.join("export").join("overlays");
    let overlay_cameras: Vec<&str> = cameras
        .iter()
        .map(|c| c.name.as_str())
        .filter(|n| overlays.join(n).is_dir())
        .collect();
    let evaluation = output.join("evaluation");
    let mut tables = Vec::new();
    for (file, title) in [
        (
            "joint_error.csv",
            "Joint error against the ground truth (pipeline evaluate)",
        ),
        (
            "reconstruction.csv",
            "Reconstruction accuracy and completeness (pipeline evaluate)",
        ),
    ] {
        let path = evaluation.join(file);
        if path.is_file() {
            let (header, rows) = read_csv_table(&path)?;
            tables.push(json!({"title": title, "file": file, "header": header, "rows": rows}));
        }
    }
    let params = crate::fsutil::read_to_string(&job.config.path)?;
    // Frames whose fit.csv row names something in `column`.
    let marked = |column: &str| {
        health_rows
            .iter()
            .filter(|r| {
                r.get(column)
                    .and_then(Value::as_str)
                    .is_some_and(|s| !s.is_empty())
            })
            .count()
    };
    let (flagged, recovered) = (marked("flags"), marked("recovery"));
    let data = json!({
        "sequence": job.sequence.name(),
        "frames": frames,
        "t0": model.skeleton.reference_frame,
        "cameras": cameras.iter().map(|c| c.name.clone()).collect::<Vec<_>>(),
        "overlayCameras": overlay_cameras,
        "contact": output
            .join("export")
            .join(crate::export::overlays::CONTACT_SHEETS)
            .is_dir(),
        "bones": bones,
        "model": {"positions": positions, "indices": indices, "skin": skin, "colours": colours},
        "motion": per_frame.iter().map(|x| &x.0).collect::<Vec<_>>(),
        "iou": per_frame.iter().map(|x| &x.1).collect::<Vec<_>>(),
        "health": health_rows,
        "surfaceFrames": surface_frames,
        "summary": {
            "frames": frames.len(),
            "cameras": cameras.len(),
            "flagged": flagged,
            "recovered": recovered,
            "pipeline": job.config.path.display().to_string(),
            "output": output.display().to_string(),
        },
        "params": params,
        "tables": tables,
    });
    let mut surface_blocks = String::new();
    for (f, kinds) in &surfaces {
        for (kind, text) in kinds {
            surface_blocks.push_str(&format!(
                "<script type=\"application/json\" id=\"surface-{kind}-{f}\">{}</script>\n",
                script_safe(text)
            ));
        }
    }
    let page = fill(
        PAGE,
        &[
            ("{{TITLE}}", &html_escape(&job.sequence.name())),
            ("/*{{STYLE}}*/", STYLE),
            ("{{TITLE}}", &html_escape(&job.sequence.name())),
            ("{{DATA}}", &script_safe(&data.to_string())),
            ("{{SURFACES}}", &surface_blocks),
            ("/*{{THREE}}*/", THREE),
            ("/*{{SCRIPT}}*/", SCRIPT),
        ],
    );
    let dir = output.join("report");
    crate::fsutil::create_dir_all(&dir)?;
    let path = dir.join("index.html");
    crate::fsutil::write_atomic(&path, page.as_bytes())?;
    Ok(Written {
        path,
        frames: frames.len(),
        surface_frames: surfaces.len(),
        bytes: page.len(),
    })
}

/// `template` with each marker replaced by its value, the markers taken in the order given
/// (their order in the template): one pass, so nothing inserted is ever scanned again.
fn fill(template: &str, parts: &[(&str, &str)]) -> String {
    let mut out =
        String::with_capacity(template.len() + parts.iter().map(|p| p.1.len()).sum::<usize>());
    let mut rest = template;
    for (marker, value) in parts {
        let at = rest
            .find(marker)
            .expect("the page template holds every marker in order");
        out.push_str(&rest[..at]);
        out.push_str(value);
        rest = &rest[at + marker.len()..];
    }
    out.push_str(rest);
    out
}

fn round5(x: f64) -> f64 {
    (x * 1e5).round() / 1e5
}

/// A surface coarsened and turned Y-up: `{"v": [mm...], "t": [...]}`.
fn coarse_surface(mesh: &TriMesh, frame: &crate::geometry::axes::ExportFrame) -> Value {
    let coarse = CoarseModel::new(mesh, SURFACE_CELL).posed(mesh);
    let v: Vec<i64> = coarse
        .vertices
        .iter()
        .flat_map(|p| {
            let q = frame.point(p);
            [q.x, q.y, q.z].map(|x| (x * 1000.0).round() as i64)
        })
        .collect();
    let t: Vec<u32> = coarse.triangles.iter().flatten().copied().collect();
    json!({"v": v, "t": t})
}

/// JSON made safe inside `<script>`: every `<`, `>` and `&` written as its JSON escape
/// (`\u003c`...), so that nothing in a name can close the element or open a comment, and
/// the text stays valid JSON (U+2028 and U+2029 too, for older script parsers).
fn script_safe(json: &str) -> String {
    let mut out = String::with_capacity(json.len());
    for c in json.chars() {
        match c {
            '<' => out.push_str("\\u003c"),
            '>' => out.push_str("\\u003e"),
            '&' => out.push_str("\\u0026"),
            '\u{2028}' => out.push_str("\\u2028"),
            '\u{2029}' => out.push_str("\\u2029"),
            c => out.push(c),
        }
    }
    out
}

fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// A CSV with a header as rows of name -> text.
fn read_csv(path: &Path) -> Result<Vec<serde_json::Map<String, Value>>> {
    let (header, rows) = read_csv_table(path)?;
    Ok(rows
        .into_iter()
        .map(|r| {
            header
                .iter()
                .cloned()
                .zip(r.into_iter().map(Value::String))
                .collect()
        })
        .collect())
}

/// A CSV's header and rows (fields split at commas; the project's CSVs quote nothing).
fn read_csv_table(path: &Path) -> Result<(Vec<String>, Vec<Vec<String>>)> {
    if !path.is_file() {
        return Err(Error::invalid(
            path,
            "missing: run `pipeline run` (and `pipeline evaluate` for its tables) first",
        ));
    }
    let text = crate::fsutil::read_to_string(path)?;
    let mut lines = text.lines();
    let header: Vec<String> = lines
        .next()
        .unwrap_or("")
        .split(',')
        .map(str::to_string)
        .collect();
    let rows = lines
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect();
    Ok((header, rows))
}
