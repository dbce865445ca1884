//! Overlay pictures: the fitted skeleton projected on the input frames with the silhouette's
//! outline ([`crate::drawing::skeleton_on_frame`]), for the cameras `export.overlay_cameras`
//! names (default: the first) at every selected frame, and with `export.contact_sheet` one
//! sheet of all cameras per frame.

use crate::drawing::{contact_sheet, skeleton_on_frame};
use crate::error::Result;
use crate::skeleton::model::BodyModel;
use crate::skeleton::Pose;
use crate::stages::Context;
use image::RgbImage;
use rayon::prelude::*;
use std::path::Path;

/// The folder of the contact sheets, beside `overlays/` under the export folder (not in
/// it: a camera may be named anything, `contact` included).
pub const CONTACT_SHEETS: &str = "contact_sheets";

/// Width of one camera's tile in a contact sheet, pixels.
const TILE_WIDTH: u32 = 320;

/// The cameras whose overlays are written (`export.overlay_cameras`, default the first).
pub fn chosen_cameras(ctx: &Context) -> Result<Vec<usize>> {
    let p = &ctx.config.export;
    if p.overlay_cameras.is_empty() {
        return Ok(vec![0]);
    }
    p.overlay_cameras
        .iter()
        .map(|name| ctx.sequence.camera_index(&ctx.config.calibration, name))
        .collect()
}

/// Writes one frame's overlays of `pose` under `dir` (`<export>/overlays`; the contact
/// sheet beside it, [`CONTACT_SHEETS`]) (`images`: the frame's input images,
/// `chosen`: [`chosen_cameras`]); returns the number of files.
pub fn frame(
    ctx: &Context,
    model: &BodyModel,
    (frame, pose): (u32, &Pose),
    images: &[RgbImage],
    chosen: &[usize],
    dir: &Path,
) -> Result<usize> {
    let seq = ctx.sequence;
    let p = &ctx.config.export;
    let stem = crate::dataset::frame_stem(frame);
    let masks = crate::stages::load_silhouettes(ctx, frame)?;
    let joints = crate::skeleton::pose::joints(&model.skeleton, pose);
    let cameras: Vec<usize> = if p.contact_sheet {
        (0..seq.cameras.len()).collect()
    } else {
        chosen.to_vec()
    };
    let pictures: Vec<RgbImage> = cameras
        .par_iter()
        .map(|&c| skeleton_on_frame(&seq.cameras[c], &images[c], &masks[c], &joints))
        .collect();
    let mut files = 0;
    for (&c, picture) in cameras.iter().zip(&pictures) {
        if chosen.contains(&c) {
            let path = dir.join(&seq.cameras[c].name).join(format!("{stem}.png"));
            crate::imageio::write_rgb(&path, picture)?;
            files += 1;
        }
    }
    if p.contact_sheet {
        let labels: Vec<String> = cameras
            .iter()
            .map(|&c| format!("{} t{frame}", seq.cameras[c].name))
            .collect();
        let sheet = contact_sheet(&pictures, &labels, TILE_WIDTH);
        let sheets = dir.with_file_name(CONTACT_SHEETS);
        crate::imageio::write_rgb(&sheets.join(format!("{stem}.png")), &sheet)?;
        files += 1;
    }
    Ok(files)
}
