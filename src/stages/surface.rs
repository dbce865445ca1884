//! Stage 7, the tracked surface ([`crate::tracked_surface`]): each fitted frame's posed
//! model deformed to the frame's observed surface and silhouettes, tracked from the
//! reference frame (each frame's target carries its previous frame's offsets, so its key
//! holds the previous frame's). Artifacts: [`crate::artifacts::tracked_surface`].

use super::{Context, Done, InOrder, Inputs, Produced};
use crate::artifacts::tracked_surface::{self, TrackedSurface};
use crate::cache::KeyBuilder;
use crate::config::Config;
use crate::dataset::Sequence;
use crate::error::Result;
use crate::fit::contact::ContactParams;
use crate::tracked_surface::silhouette_field::NearestInside;
use crate::tracked_surface::{Evidence, Previous, SurfaceParams, Tracker};
use nalgebra::Vector3;
use rayon::prelude::*;
use serde::Serialize;

pub(super) fn sources(_ctx: &Context, _frame: u32, _key: &mut KeyBuilder) -> Result<()> {
    Ok(())
}

/// What the stage reads besides its inputs' artifacts.
#[derive(Debug, Clone, Serialize)]
pub struct Settings {
    pub surface: SurfaceParams,
    /// rho_c's parameters, the fit's (`fit.contact`).
    pub contact: ContactParams,
}

/// The stage.
pub static STAGE: InOrder<Settings> = InOrder { resolve, compute };

pub fn resolve(config: &Config, _sequence: &Sequence) -> Result<Settings> {
    Ok(Settings {
        surface: config.surface,
        contact: config.fit.contact,
    })
}

fn compute(settings: &Settings, inputs: &Inputs, frames: &[u32], done: Done) -> Result<()> {
    let model = inputs.body_model()?;
    let seq = inputs.sequence;
    let tracker = Tracker::new(&model, settings.surface, settings.contact);
    // The health's silhouette measure, on the surfaces coarsened as the fit's health is.
    let coarse = crate::fit::health::CoarseModel::new(&model.mesh, super::fit::HEALTH_CELL);
    let worst_iou = |vertices: &[Vector3<f64>], masks: &[image::GrayImage]| -> f64 {
        crate::fit::health::silhouette_iou(&seq.cameras, masks, &coarse.at(vertices))
            .into_iter()
            .fold(1.0, f64::min)
    };
    let t0 = model.skeleton.reference_frame;
    // The frame just tracked (an earlier one is read back from the cache).
    let mut last: Option<(u32, crate::skeleton::Pose, Vec<Vector3<f64>>)> = None;
    for &frame in frames {
        let started = std::time::Instant::now();
        let pose = inputs.fitted_state(&model.skeleton, frame)?.pose;
        let previous = match seq.tracked_previous(frame, t0) {
            None => None,
            Some(p) => Some(match last.take() {
                Some((f, pose, vertices)) if f == p => (pose, vertices),
                _ => (
                    inputs.fitted_state(&model.skeleton, p)?.pose,
                    inputs.tracked_surface(p)?.vertices,
                ),
            }),
        };
        let observed = crate::stages::fit::as_observation(inputs.observation(frame)?);
        let masks = inputs.silhouettes(frame)?;
        let fields: Vec<NearestInside> = masks.par_iter().map(NearestInside::new).collect();
        let evidence = Evidence {
            observed: &observed,
            cameras: &seq.cameras,
            silhouettes: &fields,
        };
        let previous = previous.as_ref().map(|(pose, vertices)| Previous {
            pose,
            vertices: vertices.as_slice(),
        });
        let (mut mesh, posed, mut stats) = tracker.frame(&pose, previous.as_ref(), &evidence);
        mesh.vertices = tracked_surface::rounded(&mesh.vertices);
        stats.iou_worst = worst_iou(&mesh.vertices, &masks);
        stats.iou_worst_posed = worst_iou(&posed, &masks);
        let offset = (mesh.vertices.iter().zip(&posed))
            .map(|(x, p)| (x - p).norm() as f32)
            .collect();
        last = Some((frame, pose, mesh.vertices.clone()));
        let secs = started.elapsed().as_secs_f64();
        done(
            frame,
            Produced::new(
                TrackedSurface {
                    mesh,
                    offset,
                    stats,
                },
                Vec::new(),
            ),
            secs,
        )?;
    }
    Ok(())
}

/// `output/surface.csv`'s header: per frame, the worst camera's silhouette IoU of the
/// tracked surface and of the bare posed model (the health's measure), the share of the
/// vertices that followed the observed surface, and the median and largest distance of the
/// tracked surface from the bare posed model, metres.
pub const TABLE_HEADER: &str =
    "frame,iou_worst_tracked,iou_worst_posed,followed_share,median_offset_m,max_offset_m";

/// The tracked surface's IoU below the bare posed model's by more than this is reported.
const WORSE_THAN_POSED: f64 = 0.02;

/// After the stage: `output/surface.csv` ([`TABLE_HEADER`]) from the frames' statistics,
/// and a summary of the tracked surface's silhouette agreement beside the bare model's.
pub(super) fn finish(ctx: &Context, frames: &[u32]) -> Result<super::Finished> {
    let mut frames = frames.to_vec();
    frames.sort_unstable();
    let mut text = format!("{TABLE_HEADER}\n");
    let (mut tracked, mut posed, mut worse) = (Vec::new(), Vec::new(), Vec::new());
    for &f in &frames {
        let s = tracked_surface::read_stats(ctx.cache, f)?;
        text += &format!(
            "{f},{:.4},{:.4},{:.4},{:.5},{:.5}\n",
            s.iou_worst, s.iou_worst_posed, s.followed_share, s.median_offset, s.max_offset
        );
        tracked.push(s.iou_worst);
        posed.push(s.iou_worst_posed);
        if s.iou_worst < s.iou_worst_posed - WORSE_THAN_POSED {
            worse.push(f.to_string());
        }
    }
    let path = ctx.config.output.join("surface.csv");
    crate::fsutil::write_atomic(&path, text.as_bytes())?;
    let median = |v: &mut Vec<f64>| -> f64 {
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(0.0)
    };
    let mut warnings = Vec::new();
    if !frames.is_empty() {
        let lowest = tracked.iter().copied().fold(1.0, f64::min);
        println!(
            "tracked surface: worst-camera silhouette IoU median {:.3}, lowest {lowest:.3} (the \
             bare posed model's median {:.3}) over {} frames -> {}",
            median(&mut tracked),
            median(&mut posed),
            frames.len(),
            path.display()
        );
    }
    if !worse.is_empty() {
        warnings.push(format!(
            "the tracked surface explains the silhouettes worse than the bare posed model \
             (worst-camera IoU lower by over {WORSE_THAN_POSED}) on frame(s) {}: check \
             surface.* in pipeline.yaml, or the fit there",
            worse.join(", ")
        ));
    }
    Ok(super::Finished {
        outputs: vec![path],
        files: 1,
        warnings,
    })
}
