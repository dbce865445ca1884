//! Overlay pictures: the fitted skeleton projected on the input frames with the silhouette's
//! outline ([`crate::overlay::skeleton_on_frame`]), for the cameras `export.overlay_cameras`
//! names (default: the first) at every selected frame, and with `export.contact_sheet` one
//! sheet of all cameras per frame.

use crate::error::Result;
use crate::overlay::{camera_index, contact_sheet, skeleton_on_frame};
use crate::skeleton::model::BodyModel;
use crate::skeleton::Pose;
use crate::stages::Context;
use rayon::prelude::*;
use std::path::Path;

/// Width of one camera's tile in a contact sheet, pixels.
const TILE_WIDTH: u32 = 320;

/// Writes the overlays of `poses` ((frame, pose)) under `dir`; returns the number of files.
pub fn write(ctx: &Context, model: &BodyModel, poses: &[(u32, Pose)], dir: &Path) -> Result<usize> {
    let seq = ctx.sequence;
    let p = &ctx.config.export;
    let chosen: Vec<usize> = if p.overlay_cameras.is_empty() {
        vec![0]
    } else {
        p.overlay_cameras
            .iter()
            .map(|name| camera_index(seq, &ctx.config.calibration, name))
            .collect::<Result<_>>()?
    };
    let counts: Vec<usize> = poses
        .par_iter()
        .map(|(frame, pose)| -> Result<usize> {
            let stem = crate::dataset::frame_stem(*frame);
            let masks = crate::stages::load_silhouettes(ctx, *frame)?;
            let joints = crate::skeleton::pose::joints(&model.skeleton, pose);
            let cameras: Vec<usize> = if p.contact_sheet {
                (0..seq.cameras.len()).collect()
            } else {
                chosen.clone()
            };
            let mut pictures = Vec::with_capacity(cameras.len());
            let mut files = 0;
            for &c in &cameras {
                let img = skeleton_on_frame(
                    &seq.cameras[c],
                    &seq.load_frame(c, *frame)?,
                    &masks[c],
                    &joints,
                );
                if chosen.contains(&c) {
                    let path = dir.join(&seq.cameras[c].name).join(format!("{stem}.png"));
                    crate::imageio::write_rgb(&path, &img)?;
                    files += 1;
                }
                pictures.push(img);
            }
            if p.contact_sheet {
                let labels: Vec<String> = cameras
                    .iter()
                    .map(|&c| format!("{} t{frame}", seq.cameras[c].name))
                    .collect();
                let sheet = contact_sheet(&pictures, &labels, TILE_WIDTH);
                crate::imageio::write_rgb(
                    &dir.join("contact").join(format!("{stem}.png")),
                    &sheet,
                )?;
                files += 1;
            }
            Ok(files)
        })
        .collect::<Result<_>>()?;
    Ok(counts.iter().sum())
}
