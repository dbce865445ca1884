//! Stage 4, ZNCC photo-consistency and rho_p of every refined surface vertex
//! ([`crate::recon::reliability`]); on a masks-only capture rho_p is 1 everywhere.

use super::{Inputs, PerFrame, Produced, MASKS_ONLY_RELIABILITY};
use crate::artifacts::observation::Observation;
use crate::artifacts::reconstruction::Surface;
use crate::config::Config;
use crate::dataset::Sequence;
use crate::error::Result;
use crate::recon::reliability::{self, Observed, ReliabilityParams};
use serde::Serialize;

/// What the stage reads besides the capture's files.
#[derive(Debug, Clone, Serialize)]
pub struct Settings {
    pub params: ReliabilityParams,
    /// Whether the capture has frame images to measure photo-consistency on.
    pub photo: bool,
}

/// The stage (its sources are the graph cut's: the calibration and the frame's images).
pub static STAGE: PerFrame<Settings> = PerFrame { resolve, compute };

fn resolve(config: &Config, sequence: &Sequence) -> Result<Settings> {
    Ok(Settings {
        params: config.reliability.clone(),
        photo: sequence.has_frames,
    })
}

fn compute(s: &Settings, inputs: &Inputs, frame: u32) -> Result<Produced> {
    let p = &s.params;
    let grid = inputs.grid_spec(Surface::Refined, frame)?;
    let mesh = inputs.mesh(Surface::Refined, frame)?;
    let mut warnings = Vec::new();
    let observed = if mesh.vertices.is_empty() {
        warnings.push(format!("frame {frame}: the refined surface is empty"));
        Observed::default()
    } else if !s.photo {
        warnings.push(format!("reliability: {MASKS_ONLY_RELIABILITY}"));
        Observed::unweighted(&mesh)
    } else {
        let images = inputs.grey_frames(frame)?;
        reliability::observe(&inputs.sequence.cameras, &images, &mesh, grid.voxel, p)
    };
    let colours = observed.colours(p);
    let artifact = Observation {
        mesh,
        observed,
        colours,
    };
    Ok(Produced::new(artifact, warnings))
}
