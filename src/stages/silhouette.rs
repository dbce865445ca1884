//! Stage 1, silhouettes ([`crate::recon::silhouette`]): the given masks (cleaned when
//! asked), or background subtraction against the plates or one constant colour.

use super::{Inputs, PerFrame, Produced};
use crate::artifacts::silhouettes::Silhouettes;
use crate::cache::KeyBuilder;
use crate::config::Config;
use crate::dataset::Sequence;
use crate::error::{Error, Result};
use crate::recon::silhouette::{self, SilhouetteMethod, SilhouetteParams};
use serde::Serialize;

/// What the stage reads besides the capture's files.
#[derive(Debug, Clone, Serialize)]
pub struct Settings {
    /// The method `auto` resolved for this capture.
    pub method: SilhouetteMethod,
    pub params: SilhouetteParams,
}

/// The stage.
pub static STAGE: PerFrame<Settings> = PerFrame { resolve, compute };

fn resolve(config: &Config, sequence: &Sequence) -> Result<Settings> {
    Ok(Settings {
        method: resolve_method(config, sequence)?,
        params: config.silhouette.clone(),
    })
}

/// Which silhouette source a sequence uses under `silhouette.method`.
pub fn resolve_method(config: &Config, seq: &Sequence) -> Result<SilhouetteMethod> {
    let method = match config.silhouette.method {
        SilhouetteMethod::Auto if seq.has_masks => SilhouetteMethod::Masks,
        SilhouetteMethod::Auto => SilhouetteMethod::Background,
        m => m,
    };
    match method {
        SilhouetteMethod::Masks if !seq.has_masks => Err(Error::invalid(
            seq.dir.join("masks"),
            "silhouette.method is 'masks' but the sequence has no masks/ folder",
        )),
        SilhouetteMethod::Background | SilhouetteMethod::Constant if !seq.has_frames => {
            Err(Error::invalid(
                seq.dir.join("frames"),
                "a masks-only capture (no frames/) takes its silhouettes from masks/; \
                 set silhouette.method to 'masks' or 'auto'",
            ))
        }
        SilhouetteMethod::Background if !seq.has_backgrounds => Err(Error::invalid(
            seq.dir.join("background"),
            "background subtraction needs a plate background/<camera>.png for every camera \
             (or given masks in masks/<camera>/)",
        )),
        m => Ok(m),
    }
}

pub(super) fn sources(ctx: &super::Context, frame: u32, key: &mut KeyBuilder) -> Result<()> {
    let seq = ctx.sequence;
    let method = resolve_method(ctx.config, seq)?;
    for c in 0..seq.cameras.len() {
        key.add("camera", &seq.cameras[c].name);
        match method {
            SilhouetteMethod::Masks => key.add_file(&seq.mask_path(c, frame))?,
            SilhouetteMethod::Constant => key.add_file(&seq.frame_path(c, frame))?,
            _ => key
                .add_file(&seq.frame_path(c, frame))?
                .add_file(&seq.background_path(c))?,
        };
    }
    Ok(())
}

fn compute(s: &Settings, inputs: &Inputs, frame: u32) -> Result<Produced> {
    let seq = inputs.sequence;
    let p = &s.params;
    let mut masks = Vec::with_capacity(seq.cameras.len());
    for c in 0..seq.cameras.len() {
        let mask = match s.method {
            SilhouetteMethod::Masks => {
                let mask = seq.load_mask(c, frame)?.ok_or_else(|| {
                    Error::invalid(seq.mask_path(c, frame), "the mask is missing")
                })?;
                if p.clean_given {
                    silhouette::clean_given(&mask, p)
                } else {
                    mask
                }
            }
            SilhouetteMethod::Constant => {
                silhouette::subtract_constant(&seq.load_frame(c, frame)?, p)
            }
            _ => {
                let img = seq.load_frame(c, frame)?;
                let bg = seq.load_background(c)?.ok_or_else(|| {
                    Error::invalid(seq.background_path(c), "the background plate is missing")
                })?;
                silhouette::subtract_background(&img, &bg, p)
            }
        };
        masks.push(mask);
    }
    let cameras = seq.cameras.iter().map(|c| c.name.clone()).collect();
    Ok(Produced::new(Silhouettes { cameras, masks }, Vec::new()))
}
