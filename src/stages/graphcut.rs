//! Stage 3, the graph-cut multi-view stereo refinement of the hull
//! ([`crate::recon::graphcut`]); on a masks-only capture the hull passes through.

use super::{Inputs, PerFrame, Produced, MASKS_ONLY_GRAPHCUT};
use crate::artifacts::reconstruction::{Reconstruction, Surface};
use crate::cache::KeyBuilder;
use crate::config::Config;
use crate::dataset::Sequence;
use crate::error::Result;
use crate::geometry::TriMesh;
use crate::photo::GreyImage;
use crate::recon::graphcut::{self, GraphcutParams};
use rayon::prelude::*;
use serde::Serialize;

/// What the stage reads besides the capture's files.
#[derive(Debug, Clone, Serialize)]
pub struct Settings {
    pub params: GraphcutParams,
    /// Whether the capture has frame images to be photo-consistent with.
    pub photo: bool,
}

/// The stage.
pub static STAGE: PerFrame<Settings> = PerFrame { resolve, compute };

fn resolve(config: &Config, sequence: &Sequence) -> Result<Settings> {
    Ok(Settings {
        params: config.graphcut.clone(),
        photo: sequence.has_frames,
    })
}

/// The calibration and a frame's images (the graph cut's and the reliability stage's).
pub(super) fn sources(ctx: &super::Context, frame: u32, key: &mut KeyBuilder) -> Result<()> {
    key.add_file(&ctx.config.calibration)?;
    if !ctx.sequence.has_frames {
        key.add("frames", "none (masks only)");
        return Ok(());
    }
    for c in 0..ctx.sequence.cameras.len() {
        key.add_file(&ctx.sequence.frame_path(c, frame))?;
    }
    Ok(())
}

fn compute(s: &Settings, inputs: &Inputs, frame: u32) -> Result<Produced> {
    let p = &s.params;
    let (grid, sdf) = inputs.grid(Surface::Hull, frame)?;
    let refined = |mesh: TriMesh, sdf: Vec<f32>| Reconstruction {
        mesh,
        grid,
        sdf,
        band: None,
    };
    let occupied: Vec<bool> = sdf.iter().map(|&v| v < 0.0).collect();
    if !occupied.iter().any(|&o| o) {
        // An empty hull stays empty.
        let warning = format!("frame {frame}: the hull is empty");
        return Ok(Produced::new(
            refined(TriMesh::default(), sdf),
            vec![warning],
        ));
    }
    let hull = inputs.mesh(Surface::Hull, frame)?;
    if !s.photo {
        // Nothing to refine with: the hull passes through unchanged.
        let note = format!("graphcut: {MASKS_ONLY_GRAPHCUT}");
        return Ok(Produced::new(refined(hull, sdf), vec![note]));
    }
    let cams = &inputs.sequence.cameras;
    let depth = crate::photo::depth_maps(cams, &hull);
    let images = inputs.grey_frames(frame)?;
    // Long cuts report their progress (drawn only when stderr is a terminal).
    let spinner = indicatif::ProgressBar::new_spinner();
    let mut report = |flow: f64, augmentations: u64| {
        spinner.set_message(format!(
            "frame {frame}: max-flow {flow:.3e} after {augmentations} augmentations"
        ));
        spinner.tick();
    };
    // The silhouettes pin the rims (`pin_rims`) or keep the limbs they confirm.
    let masks = inputs.silhouettes(frame)?;
    let labels = graphcut::min_cut_occupancy(
        &grid,
        &occupied,
        &sdf,
        cams,
        &images,
        &depth,
        &masks,
        p,
        &mut report,
    );
    spinner.finish_and_clear();
    let hull_on_cones = inputs.hull_on_cones(frame, &sdf)?;
    let (refined_sdf, mut mesh) =
        graphcut::mesh(&grid, &labels, &hull_on_cones, p.smoothing_iterations);
    if p.photo_refine > 0.0 {
        use crate::photo::refine::{refine_along_normals, RefineSettings};
        let settings = RefineSettings::with_search(p.photo_refine);
        let smoothed: Vec<GreyImage> = images
            .par_iter()
            .map(|g| g.blurred(settings.image_sigma))
            .collect();
        refine_along_normals(cams, &smoothed, &mut mesh, grid.voxel, &settings);
    }
    Ok(Produced::new(refined(mesh, refined_sdf), Vec::new()))
}
