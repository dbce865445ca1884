//! The stages, and how the runner drives each: what a stage reads, how its cache key is
//! made, and how its per-frame artifact is computed and written.
//!
//! The algorithms live in one module per stage as plain functions on typed data; the
//! [`StageDef`] adapters here do the file handling around them.

pub mod silhouette;

use crate::cache::{Cache, KeyBuilder};
use crate::config::Config;
use crate::dataset::{frame_stem, Sequence};
use crate::error::{Error, Result};
use silhouette::SilhouetteMethod;

/// Everything a stage may read for one run.
pub struct Context<'a> {
    pub config: &'a Config,
    pub sequence: &'a Sequence,
    pub cache: &'a Cache,
}

/// A stage as the runner sees it.
pub struct StageDef {
    pub name: &'static str,
    /// What it computes, for `--help` and the README.
    pub about: &'static str,
    /// Upstream stages whose artifacts it reads.
    pub inputs: &'static [&'static str],
    /// Bumped whenever the artifact's format or meaning changes (invalidates caches).
    pub format_version: u32,
    /// The stage's parameters as canonical text (part of the cache key).
    pub params: fn(&Config) -> String,
    /// Key material from the raw inputs the stage reads directly for a frame.
    pub sources: fn(&Context, u32, &mut KeyBuilder) -> Result<()>,
    /// Computes and writes the artifact files of a frame; returns them relative to the
    /// stage folder.
    pub compute: fn(&Context, u32) -> Result<Vec<String>>,
}

/// All stages, in pipeline order.
pub const STAGES: &[StageDef] = &[StageDef {
    name: "silhouette",
    about: "foreground masks: given masks, or background subtraction",
    inputs: &[],
    format_version: 1,
    params: |c| crate::yaml::to_string(&c.silhouette).unwrap_or_default(),
    sources: silhouette_sources,
    compute: silhouette_compute,
}];

/// The stage named `name`, or an error listing the stages.
pub fn find(name: &str) -> Result<&'static StageDef> {
    STAGES.iter().find(|s| s.name == name).ok_or_else(|| {
        let names: Vec<&str> = STAGES.iter().map(|s| s.name).collect();
        Error::Usage(format!(
            "there is no stage '{name}'; the stages are: {}",
            names.join(", ")
        ))
    })
}

/// Which silhouette source a sequence uses under `method`.
fn resolve_method(ctx: &Context) -> Result<SilhouetteMethod> {
    let seq = ctx.sequence;
    let method = match ctx.config.silhouette.method {
        SilhouetteMethod::Auto if seq.has_masks => SilhouetteMethod::Masks,
        SilhouetteMethod::Auto => SilhouetteMethod::Background,
        m => m,
    };
    match method {
        SilhouetteMethod::Masks if !seq.has_masks => Err(Error::invalid(
            seq.dir.join("masks"),
            "silhouette.method is 'masks' but the sequence has no masks/ folder",
        )),
        SilhouetteMethod::Background if !seq.has_backgrounds => Err(Error::invalid(
            seq.dir.join("background"),
            "background subtraction needs a plate background/<camera>.png for every camera \
             (or given masks in masks/<camera>/)",
        )),
        m => Ok(m),
    }
}

fn silhouette_sources(ctx: &Context, frame: u32, key: &mut KeyBuilder) -> Result<()> {
    let seq = ctx.sequence;
    let method = resolve_method(ctx)?;
    key.add("method", &format!("{method:?}"));
    for c in 0..seq.cameras.len() {
        key.add("camera", &seq.cameras[c].name);
        match method {
            SilhouetteMethod::Masks => key.add_file(&seq.mask_path(c, frame))?,
            _ => key
                .add_file(&seq.frame_path(c, frame))?
                .add_file(&seq.background_path(c))?,
        };
    }
    Ok(())
}

fn silhouette_compute(ctx: &Context, frame: u32) -> Result<Vec<String>> {
    let seq = ctx.sequence;
    let method = resolve_method(ctx)?;
    let dir = ctx.cache.stage_dir("silhouette");
    let mut files = Vec::new();
    for c in 0..seq.cameras.len() {
        let mask = match method {
            SilhouetteMethod::Masks => seq.load_mask(c, frame)?.expect("masks present"),
            _ => {
                let img = seq.load_frame(c, frame)?;
                let bg = seq.load_background(c)?.expect("plates present");
                silhouette::subtract_background(&img, &bg, &ctx.config.silhouette)
            }
        };
        let rel = format!("{}/{}.png", frame_stem(frame), seq.cameras[c].name);
        crate::imageio::write_gray(&dir.join(&rel), &mask)?;
        files.push(rel);
    }
    Ok(files)
}

/// Loads the silhouettes of a frame from the cache (for downstream stages and tests).
pub fn load_silhouettes(ctx: &Context, frame: u32) -> Result<Vec<image::GrayImage>> {
    let dir = ctx.cache.stage_dir("silhouette");
    ctx.sequence
        .cameras
        .iter()
        .map(|cam| {
            let path = dir
                .join(frame_stem(frame))
                .join(format!("{}.png", cam.name));
            Ok(image::open(&path)
                .map_err(|e| Error::invalid(&path, format!("cannot read the mask: {e}")))?
                .to_luma8())
        })
        .collect()
}
