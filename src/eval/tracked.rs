//! The posed model and the tracked surface, per frame, beside the graph cut's own surface:
//!
//! - against the true surface (synthetic captures): the distance within which 90% of the
//!   surface's vertices lie from the truth (d90), and the distance within which 90% of the
//!   truth lies from the surface (a part the surface lacks shows there), both metres;
//! - against the silhouettes (every capture): the worst camera's IoU of the surface
//!   projected at full resolution.

use super::{quantile, sample_surface, TruthSamples, SAMPLE_SPACING};
use crate::artifacts::reconstruction::Surface;
use crate::error::Result;
use crate::geometry::nearest::NearestTree;
use crate::geometry::TriMesh;
use crate::runner::Job;
use rayon::prelude::*;
use std::fmt::Write as _;

/// How far one surface lies from the truth, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceDistance {
    /// 90% of the surface's vertices lie this near the truth.
    pub d90: f64,
    /// 90% of the truth's samples lie this near the surface.
    pub truth_d90: f64,
}

/// [`SurfaceDistance`] of `mesh` against `truth`.
pub fn distance(mesh: &TriMesh, truth: &TruthSamples) -> SurfaceDistance {
    let mut d: Vec<f64> = (mesh.vertices.par_iter())
        .map(|v| truth.signed_distance(v).abs())
        .collect();
    d.sort_by(f64::total_cmp);
    let samples = sample_surface(mesh, SAMPLE_SPACING);
    let index = NearestTree::new(&samples);
    let mut back: Vec<f64> = (truth.points.par_iter())
        .map(|p| index.nearest(p).map_or(f64::INFINITY, |(_, d2)| d2.sqrt()))
        .collect();
    back.sort_by(f64::total_cmp);
    SurfaceDistance {
        d90: quantile(&d, 0.9),
        truth_d90: quantile(&back, 0.9),
    }
}

/// One frame's row: the graph cut's, the posed model's and the tracked surface's distances
/// (each `None` when not in the cache).
#[derive(Debug, Clone, PartialEq)]
pub struct TrackedRow {
    pub frame: u32,
    pub refined: Option<SurfaceDistance>,
    pub posed: Option<SurfaceDistance>,
    pub tracked: Option<SurfaceDistance>,
}

/// The rows of the job's frames that have a true mesh and a posed or tracked surface.
pub fn rows(job: &Job) -> Result<Vec<TrackedRow>> {
    let cache = &job.cache;
    let mut rows = Vec::new();
    for &frame in &job.frames {
        let has = |stage: &str| cache.manifest(stage, frame).is_some();
        let (fit, surface) = (
            crate::artifacts::fitted::STAGE,
            crate::artifacts::tracked_surface::STAGE,
        );
        if !has(fit) && !has(surface) {
            continue;
        }
        let Some(truth) = job.sequence.ground_truth_mesh(frame)? else {
            continue;
        };
        let truth = TruthSamples::new(&truth);
        let refined = Surface::Refined.stage();
        rows.push(TrackedRow {
            frame,
            refined: has(refined)
                .then(|| {
                    crate::artifacts::reconstruction::read_mesh(cache, Surface::Refined, frame)
                })
                .transpose()?
                .map(|m| distance(&m, &truth)),
            posed: has(fit)
                .then(|| crate::artifacts::fitted::read_mesh(cache, frame))
                .transpose()?
                .map(|m| distance(&m, &truth)),
            tracked: has(surface)
                .then(|| crate::artifacts::tracked_surface::read_mesh(cache, frame))
                .transpose()?
                .map(|m| distance(&m, &truth)),
        });
    }
    Ok(rows)
}

fn cells(d: Option<SurfaceDistance>) -> (String, String) {
    match d {
        Some(d) => (
            format!("{:.2}", d.d90 * 100.0),
            format!("{:.2}", d.truth_d90 * 100.0),
        ),
        None => ("-".into(), "-".into()),
    }
}

/// The printed table.
pub fn table(rows: &[TrackedRow]) -> String {
    let mut s = format!(
        "{:>6}  {:>16}  {:>16}  {:>16}\n",
        "frame", "graph cut cm", "posed model cm", "tracked cm"
    );
    for r in rows {
        let [g, p, t] = [r.refined, r.posed, r.tracked].map(cells);
        let _ = writeln!(
            s,
            "{:>6}  {:>7} / {:>6}  {:>7} / {:>6}  {:>7} / {:>6}",
            r.frame, g.0, g.1, p.0, p.1, t.0, t.1
        );
    }
    s.push_str(
        "each: d90 of the surface's vertices to the truth / d90 of the truth to the surface\n",
    );
    s
}

/// The CSV (metres).
pub fn to_csv(rows: &[TrackedRow]) -> String {
    let mut s = String::from(
        "frame,refined_d90_m,refined_truth_d90_m,posed_d90_m,posed_truth_d90_m,tracked_d90_m,tracked_truth_d90_m\n",
    );
    let cell = |d: Option<SurfaceDistance>| match d {
        Some(d) => (format!("{:.6}", d.d90), format!("{:.6}", d.truth_d90)),
        None => (String::new(), String::new()),
    };
    for r in rows {
        let [g, p, t] = [r.refined, r.posed, r.tracked].map(cell);
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{}",
            r.frame, g.0, g.1, p.0, p.1, t.0, t.1
        );
    }
    s
}

/// One frame's worst-camera silhouette IoU of each surface in the cache (`None`: not
/// cached), with that camera's name.
#[derive(Debug, Clone, PartialEq)]
pub struct SilhouetteRow {
    pub frame: u32,
    pub refined: Option<(f64, String)>,
    pub posed: Option<(f64, String)>,
    pub tracked: Option<(f64, String)>,
}

/// The rows of the job's frames whose tracked surface is cached.
pub fn silhouette_rows(job: &Job) -> Result<Vec<SilhouetteRow>> {
    let cache = &job.cache;
    let rays = super::pixel_tables(job);
    let worst = |mesh: TriMesh, frame: u32| -> Result<(f64, String)> {
        let agreement = super::coverage_of(job, &rays, &mesh, frame)?;
        Ok(agreement
            .into_iter()
            .map(|a| (a.iou, a.camera))
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .unwrap_or((0.0, String::new())))
    };
    let mut rows = Vec::new();
    for &frame in &job.frames {
        let has = |stage: &str| cache.manifest(stage, frame).is_some();
        if !has(crate::artifacts::tracked_surface::STAGE) {
            continue;
        }
        let refined = Surface::Refined;
        rows.push(SilhouetteRow {
            frame,
            refined: has(refined.stage())
                .then(|| crate::artifacts::reconstruction::read_mesh(cache, refined, frame))
                .transpose()?
                .map(|m| worst(m, frame))
                .transpose()?,
            posed: has(crate::artifacts::fitted::STAGE)
                .then(|| crate::artifacts::fitted::read_mesh(cache, frame))
                .transpose()?
                .map(|m| worst(m, frame))
                .transpose()?,
            tracked: Some(worst(
                crate::artifacts::tracked_surface::read_mesh(cache, frame)?,
                frame,
            )?),
        });
    }
    Ok(rows)
}

/// The printed table of [`silhouette_rows`], and how many frames' tracked surface falls
/// below 0.95 times the graph cut's worst IoU.
pub fn silhouette_table(rows: &[SilhouetteRow]) -> String {
    let cell = |x: &Option<(f64, String)>| match x {
        Some((iou, cam)) => format!("{iou:.3} {cam}"),
        None => "-".into(),
    };
    let mut s = format!(
        "{:>6}  {:>20}  {:>20}  {:>20}\n",
        "frame", "graph cut", "posed model", "tracked"
    );
    let mut below = Vec::new();
    for r in rows {
        let _ = writeln!(
            s,
            "{:>6}  {:>20}  {:>20}  {:>20}",
            r.frame,
            cell(&r.refined),
            cell(&r.posed),
            cell(&r.tracked)
        );
        if let (Some(g), Some(t)) = (&r.refined, &r.tracked) {
            if t.0 < 0.95 * g.0 {
                below.push(r.frame.to_string());
            }
        }
    }
    let _ = writeln!(
        s,
        "each: the worst camera's silhouette IoU and that camera; tracked below 0.95 x the \
         graph cut's on {} of {} frames{}",
        below.len(),
        rows.len(),
        listed(&below)
    );
    s
}

/// The frames `frames` as " (a, b, c)" after a count, or nothing when there are none.
pub(crate) fn listed(frames: &[String]) -> String {
    if frames.is_empty() {
        String::new()
    } else {
        format!(" ({})", frames.join(", "))
    }
}

/// The CSV of [`silhouette_rows`].
pub fn silhouette_csv(rows: &[SilhouetteRow]) -> String {
    let mut s = String::from(
        "frame,refined_iou_worst,refined_camera,posed_iou_worst,posed_camera,tracked_iou_worst,tracked_camera\n",
    );
    let cell = |x: &Option<(f64, String)>| match x {
        Some((iou, cam)) => (format!("{iou:.6}"), cam.clone()),
        None => (String::new(), String::new()),
    };
    for r in rows {
        let [g, p, t] = [&r.refined, &r.posed, &r.tracked].map(cell);
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{}",
            r.frame, g.0, g.1, p.0, p.1, t.0, t.1
        );
    }
    s
}
