//! Stage 2, the voxel visual hull ([`crate::recon::visual_hull`]) of a frame's
//! silhouettes, with its watertight mesh and its solid on the cones.

use super::{Inputs, PerFrame, Produced};
use crate::artifacts::reconstruction::Reconstruction;
use crate::cache::KeyBuilder;
use crate::config::Config;
use crate::dataset::Sequence;
use crate::error::{Error, Result};
use crate::geometry::grid::GridSpec;
use crate::geometry::TriMesh;
use crate::recon::silhouette::Coverage;
use crate::recon::visual_hull::{self, VisualHullParams};

/// The stage: its settings are `visual_hull` of pipeline.yaml.
pub static STAGE: PerFrame<VisualHullParams> = PerFrame { resolve, compute };

fn resolve(config: &Config, _sequence: &Sequence) -> Result<VisualHullParams> {
    Ok(config.visual_hull.clone())
}

pub(super) fn sources(ctx: &super::Context, _frame: u32, key: &mut KeyBuilder) -> Result<()> {
    key.add_file(&ctx.config.calibration)?;
    Ok(())
}

fn compute(p: &VisualHullParams, inputs: &Inputs, frame: u32) -> Result<Produced> {
    let cameras = &inputs.sequence.cameras;
    let masks = inputs.silhouettes(frame)?;
    let mut warnings = Vec::new();
    // A person's triangulated keypoints bound the box far better than few cameras' cones.
    let mut with_box;
    let p = match (&p.bbox, inputs.person(frame)?) {
        (None, Some(person)) => {
            let points = crate::person::triangulate::triangulate_frame(cameras, &person);
            with_box = p.clone();
            with_box.bbox = crate::person::triangulate::body_box(&points);
            &with_box
        }
        _ => p,
    };
    let coverage = Coverage::of(cameras, &masks);
    let full = coverage.full_problem(frame, p.all_but, cameras.len());
    warnings.extend(full.map_err(|m| Error::invalid(&inputs.sequence.dir, m))?);
    let hull = visual_hull::reconstruct(cameras, &masks, p).map_err(|m| {
        Error::invalid(
            inputs.config_path,
            format!("visual_hull, frame {frame}: {m}"),
        )
    })?;
    if let (Some(h), None) = (&hull, &p.bbox) {
        let size = h.grid.dims.map(|d| d as f64 * h.grid.voxel);
        warnings.extend(coverage.box_problem(frame, size));
    }
    let artifact = match hull {
        Some(h) => Reconstruction {
            mesh: h.mesh,
            grid: h.grid,
            sdf: h.sdf,
            band: Some(h.on_cones),
        },
        None => {
            warnings.push(format!(
                "frame {frame}: the hull is empty: {}",
                coverage.why_empty()
            ));
            Reconstruction {
                mesh: TriMesh::default(),
                grid: GridSpec {
                    origin: nalgebra::Vector3::zeros(),
                    voxel: p.voxel_size,
                    dims: [0, 0, 0],
                },
                sdf: Vec::new(),
                band: Some(Default::default()),
            }
        }
    };
    Ok(Produced::new(artifact, warnings))
}
