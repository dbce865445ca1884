//! `pipeline evaluate FILE --holdout CAM`: a fair measure on a capture without truth. The
//! job's frames are rebuilt, fitted and tracked without camera CAM (a job of its own, cache
//! and output under `holdout/CAM/` of the job's, [`crate::runner::Job::holding_out`]); then
//! each surface of that run is drawn in CAM, which none of them saw, and scored by its
//! silhouette IoU there at full resolution: the tracked surface beside the graph cut it was
//! fitted to and the bare posed model. Where the full rig's tracked surface is cached, its
//! IoU in CAM (a camera it did see) stands beside them.

use crate::artifacts::reconstruction::{self, Surface};
use crate::artifacts::{fitted, tracked_surface};
use crate::error::{Error, Result};
use crate::geometry::mesh::TriMesh;
use crate::runner::{Job, RunOptions};
use std::fmt::Write;

/// One frame's silhouette IoU in the held-out camera (`None`: not cached).
#[derive(Debug, Clone, PartialEq)]
pub struct HoldoutRow {
    pub frame: u32,
    /// The graph cut's surface rebuilt without the camera.
    pub refined: Option<f64>,
    /// The bare posed model fitted without the camera.
    pub posed: Option<f64>,
    /// The tracked surface made without the camera.
    pub tracked: Option<f64>,
    /// The full rig's tracked surface (the camera among its evidence).
    pub tracked_with_camera: Option<f64>,
}

/// Runs the job without `camera` through the tracked surface (reusing what its own cache
/// holds) and scores every frame in that camera. The job's own silhouettes must be cached
/// (the held-out camera's masks are the reference).
pub fn evaluate(job: &Job, camera: &str) -> Result<Vec<HoldoutRow>> {
    job.require_cached(&["silhouette"])?;
    let held = job.holding_out(camera)?;
    if held.sequence.cameras.len() < 2 {
        return Err(Error::Usage(format!(
            "holding out {camera} leaves fewer than two cameras to reconstruct with"
        )));
    }
    let c = job
        .sequence
        .cameras
        .iter()
        .position(|cam| cam.name == camera)
        .expect("holding_out checked the name");
    println!(
        "holding out {camera}: rebuilding frames with the other {} cameras into {}",
        held.sequence.cameras.len(),
        held.cache.root.display()
    );
    let opts = RunOptions {
        until: Some(tracked_surface::STAGE.into()),
        ..RunOptions::default()
    };
    for r in crate::runner::run(&held, &opts)? {
        println!(
            "{:>12}: {} computed, {} reused, {:.1} s",
            r.stage, r.computed, r.reused, r.seconds
        );
    }
    let cam = &job.sequence.cameras[c];
    let rays = crate::geometry::raster::PixelRays::new(cam);
    let ctx = job.context();
    let mut rows = Vec::new();
    for &frame in &job.frames {
        let mask = &crate::stages::load_silhouettes(&ctx, frame)?[c];
        let iou = |mesh: Option<TriMesh>| mesh.map(|m| super::agreement(cam, &rays, mask, &m).iou);
        let cached = |job: &Job, stage: &str| job.cache.manifest(stage, frame).is_some();
        let refined = Surface::Refined;
        rows.push(HoldoutRow {
            frame,
            refined: iou(cached(&held, refined.stage())
                .then(|| reconstruction::read_mesh(&held.cache, refined, frame))
                .transpose()?),
            posed: iou(cached(&held, fitted::STAGE)
                .then(|| fitted::read_mesh(&held.cache, frame))
                .transpose()?),
            tracked: iou(cached(&held, tracked_surface::STAGE)
                .then(|| tracked_surface::read_mesh(&held.cache, frame))
                .transpose()?),
            tracked_with_camera: iou(cached(job, tracked_surface::STAGE)
                .then(|| tracked_surface::read_mesh(&job.cache, frame))
                .transpose()?),
        });
    }
    Ok(rows)
}

/// A column of the table: its name and its value in a row.
type Column = (&'static str, fn(&HoldoutRow) -> Option<f64>);

fn cell(x: Option<f64>) -> String {
    x.map_or("-".into(), |v| format!("{v:.3}"))
}

/// The median of the present values.
fn median(values: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let mut v: Vec<f64> = values.flatten().collect();
    v.sort_by(f64::total_cmp);
    (!v.is_empty()).then(|| v[v.len() / 2])
}

/// The printed table of `rows` for `camera`, with each column's median and minimum, and how
/// many frames' tracked surface falls below 0.95 times the graph cut's IoU there.
pub fn table(camera: &str, rows: &[HoldoutRow]) -> String {
    let mut s = format!(
        "silhouette IoU in {camera}, which the surfaces below never saw (full resolution)\n\
         {:>6}  {:>9}  {:>11}  {:>8}  {:>19}\n",
        "frame", "graph cut", "posed model", "tracked", "tracked, all cams"
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{:>6}  {:>9}  {:>11}  {:>8}  {:>19}",
            r.frame,
            cell(r.refined),
            cell(r.posed),
            cell(r.tracked),
            cell(r.tracked_with_camera)
        );
    }
    let columns: [Column; 4] = [
        ("graph cut", |r| r.refined),
        ("posed model", |r| r.posed),
        ("tracked", |r| r.tracked),
        ("tracked, all cams", |r| r.tracked_with_camera),
    ];
    for (name, get) in columns {
        let min = rows.iter().filter_map(get).min_by(f64::total_cmp);
        let _ = writeln!(
            s,
            "{name:>19}: median {}, lowest {}",
            cell(median(rows.iter().map(get))),
            cell(min)
        );
    }
    let below: Vec<String> = rows
        .iter()
        .filter(|r| matches!((r.tracked, r.refined), (Some(t), Some(g)) if t < 0.95 * g))
        .map(|r| r.frame.to_string())
        .collect();
    let _ = writeln!(
        s,
        "tracked below 0.95 x the graph cut's in {camera} on {} of {} frames{}",
        below.len(),
        rows.len(),
        super::tracked::listed(&below)
    );
    s
}

/// The CSV of `rows`.
pub fn to_csv(rows: &[HoldoutRow]) -> String {
    let opt = |x: Option<f64>| x.map_or(String::new(), |v| format!("{v:.6}"));
    let mut s = String::from("frame,refined_iou,posed_iou,tracked_iou,tracked_all_cameras_iou\n");
    for r in rows {
        let _ = writeln!(
            s,
            "{},{},{},{},{}",
            r.frame,
            opt(r.refined),
            opt(r.posed),
            opt(r.tracked),
            opt(r.tracked_with_camera)
        );
    }
    s
}
