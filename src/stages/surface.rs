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
    let tracker = Tracker::new(&model, settings.surface, settings.contact);
    let t0 = model.skeleton.reference_frame;
    let seq = inputs.sequence;
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
        let (mut mesh, posed, stats) = tracker.frame(&pose, previous.as_ref(), &evidence);
        mesh.vertices = tracked_surface::rounded(&mesh.vertices);
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
