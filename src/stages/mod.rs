//! The stages, and how the runner drives each: what a stage reads, how its cache key is
//! made, and how its per-frame artifact is computed and written.
//!
//! The algorithms live in one module per stage as plain functions on typed data; the
//! [`StageDef`] adapters here do the file handling around them.

pub mod fit;
pub mod model;

use crate::artifacts::{self, reconstruction, reconstruction::Surface};
use crate::cache::{Cache, KeyBuilder};
use crate::config::Config;
use crate::dataset::Sequence;
use crate::error::{Error, Result};
use crate::geometry::grid::GridSpec;
use crate::geometry::TriMesh;
use crate::photo::GreyImage;
use crate::recon::silhouette::{self, SilhouetteMethod};
use crate::recon::{graphcut, reliability, visual_hull};
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// Everything a stage may read for one run.
pub struct Context<'a> {
    pub config: &'a Config,
    pub sequence: &'a Sequence,
    pub cache: &'a Cache,
    /// Grey images of the frames being computed, decoded once and shared by a frame's
    /// stages (the graph cut and the reliability stage), when the runner asks for it; it
    /// drops a frame's images when the frame's last stage is done.
    frame_images: Option<FrameImages>,
}

/// Grey images kept per frame ([`Context::sharing_frame_images`]).
type FrameImages = Mutex<HashMap<u32, Arc<Vec<GreyImage>>>>;

impl<'a> Context<'a> {
    pub fn new(config: &'a Config, sequence: &'a Sequence, cache: &'a Cache) -> Context<'a> {
        Context {
            config,
            sequence,
            cache,
            frame_images: None,
        }
    }

    /// This context, keeping each frame's grey images until [`Context::forget_frame_images`].
    pub fn sharing_frame_images(self) -> Context<'a> {
        Context {
            frame_images: Some(Mutex::default()),
            ..self
        }
    }

    /// Drops the grey images kept for `frame`.
    pub fn forget_frame_images(&self, frame: u32) {
        if let Some(kept) = &self.frame_images {
            kept.lock()
                .unwrap_or_else(|e| e.into_inner())
                .remove(&frame);
        }
    }
}

/// Which frames a stage makes artifacts for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scope {
    /// One artifact per selected frame.
    PerFrame,
    /// One artifact for the sequence, made from the skeleton's reference frame t0 (the
    /// artifact is filed under that frame). Skipped when the sequence has no skeleton.yaml.
    Reference,
    /// One artifact per frame from t0 to the selected frames, computed in order from t0,
    /// each from its neighbour's (the fit). Skipped when the sequence has no skeleton.yaml.
    Tracked,
}

/// A stage as the runner sees it.
pub struct StageDef {
    pub name: &'static str,
    /// Which frames it makes artifacts for.
    pub scope: Scope,
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
    /// Computes and writes the artifact files of the frames.
    pub compute: Compute,
    /// After the stage: writes sequence-level outputs from the frames' artifacts (the
    /// frames in computation order); returns the files and warnings.
    pub finish: Option<FinishFn>,
}

/// How a stage computes its frames' artifacts.
#[derive(Clone, Copy)]
pub enum Compute {
    /// Each frame on its own (the runner computes frames side by side).
    Frame(fn(&Context, u32) -> Result<Output>),
    /// The frames in order, each from the one before ([`Scope::Tracked`]); the function
    /// hands each frame's output, and the seconds it took, to the callback (which commits it
    /// to the cache) as soon as the frame is done.
    Tracked(TrackedFn),
}

/// A [`Compute::Tracked`] stage's computation (given the frames, in computation order).
pub type TrackedFn =
    fn(&Context, &[u32], &mut dyn FnMut(u32, Output, f64) -> Result<()>) -> Result<()>;

/// A stage's sequence-level step (given the frames, in computation order).
pub type FinishFn = fn(&Context, &[u32]) -> Result<Finished>;

/// What a stage's sequence-level step wrote.
#[derive(Debug, Default)]
pub struct Finished {
    /// Files or folders written to the output folder, for the summary.
    pub outputs: Vec<std::path::PathBuf>,
    /// Number of files written.
    pub files: usize,
    /// Things the user should know.
    pub warnings: Vec<String>,
}

/// What a stage wrote for one frame.
#[derive(Debug, Default)]
pub struct Output {
    /// Files, relative to the stage folder.
    pub files: Vec<String>,
    /// Things the user should know (e.g. an empty frame).
    pub warnings: Vec<String>,
}

/// All stages, in pipeline order.
pub const STAGES: &[StageDef] = &[
    StageDef {
        name: "silhouette",
        scope: Scope::PerFrame,
        about: "foreground masks: given masks, or background subtraction",
        inputs: &[],
        format_version: 1,
        params: |c| crate::yaml::to_string(&c.silhouette).unwrap_or_default(),
        sources: silhouette_sources,
        compute: Compute::Frame(silhouette_compute),
        finish: None,
    },
    StageDef {
        name: "visual_hull",
        scope: Scope::PerFrame,
        about: "conservative voxel carving and the hull's watertight mesh",
        inputs: &["silhouette"],
        format_version: 5,
        params: |c| crate::yaml::to_string(&c.visual_hull).unwrap_or_default(),
        sources: visual_hull_sources,
        compute: Compute::Frame(visual_hull_compute),
        finish: None,
    },
    StageDef {
        name: "graphcut",
        scope: Scope::PerFrame,
        about: "graph-cut multi-view stereo refinement of the hull",
        inputs: &["visual_hull"],
        format_version: 16,
        params: |c| crate::yaml::to_string(&c.graphcut).unwrap_or_default(),
        sources: graphcut_sources,
        compute: Compute::Frame(graphcut_compute),
        finish: None,
    },
    StageDef {
        name: "reliability",
        scope: Scope::PerFrame,
        about: "ZNCC photo-consistency and rho_p of every refined surface vertex",
        inputs: &["graphcut"],
        format_version: 2,
        params: |c| crate::yaml::to_string(&c.reliability).unwrap_or_default(),
        sources: graphcut_sources,
        compute: Compute::Frame(reliability_compute),
        finish: None,
    },
    StageDef {
        name: "model",
        scope: Scope::Reference,
        about: "skin-bone body model from the reference frame's surface and the skeleton",
        inputs: &["graphcut"],
        format_version: 2,
        // The mesh's content is in the key (`model::sources`), its path is not.
        params: |c| {
            let mesh = c.model.mesh.is_some().then(|| "given".into());
            crate::yaml::to_string(&crate::skeleton::model::ModelParams {
                mesh,
                ..c.model.clone()
            })
            .unwrap_or_default()
        },
        sources: model::sources,
        compute: Compute::Frame(model::compute),
        finish: None,
    },
    StageDef {
        name: "fit",
        scope: Scope::Tracked,
        about: "robust articulated fitting of the body model to every frame, tracked from t0",
        inputs: &["reliability", "model"],
        format_version: 11,
        // The fit reads the frame rate (the motion prior's weight, the joint-speed check).
        params: |c| {
            format!(
                "{}frame_rate: {:e}\n",
                crate::yaml::to_string(&c.fit).unwrap_or_default(),
                c.export.frame_rate
            )
        },
        sources: fit::sources,
        compute: Compute::Tracked(fit::compute),
        finish: Some(fit::finish),
    },
];

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

fn silhouette_sources(ctx: &Context, frame: u32, key: &mut KeyBuilder) -> Result<()> {
    let seq = ctx.sequence;
    let method = resolve_method(ctx)?;
    key.add("method", &format!("{method:?}"));
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

fn silhouette_compute(ctx: &Context, frame: u32) -> Result<Output> {
    let seq = ctx.sequence;
    let method = resolve_method(ctx)?;
    let mut masks = Vec::with_capacity(seq.cameras.len());
    for c in 0..seq.cameras.len() {
        let mask = match method {
            SilhouetteMethod::Masks => {
                let mask = seq.load_mask(c, frame)?.expect("masks present");
                let p = &ctx.config.silhouette;
                if p.clean_given {
                    silhouette::clean_given(&mask, p)
                } else {
                    mask
                }
            }
            SilhouetteMethod::Constant => {
                silhouette::subtract_constant(&seq.load_frame(c, frame)?, &ctx.config.silhouette)
            }
            _ => {
                let img = seq.load_frame(c, frame)?;
                let bg = seq.load_background(c)?.expect("plates present");
                silhouette::subtract_background(&img, &bg, &ctx.config.silhouette)
            }
        };
        masks.push(mask);
    }
    let dir = ctx.cache.stage_dir(artifacts::silhouettes::STAGE);
    Ok(Output {
        files: artifacts::silhouettes::write(&dir, frame, &seq.cameras, &masks)?,
        warnings: Vec::new(),
    })
}

fn visual_hull_sources(ctx: &Context, _frame: u32, key: &mut KeyBuilder) -> Result<()> {
    key.add_file(&ctx.config.calibration)?;
    Ok(())
}

fn visual_hull_compute(ctx: &Context, frame: u32) -> Result<Output> {
    let masks = load_silhouettes(ctx, frame)?;
    let p = &ctx.config.visual_hull;
    let mut warnings = Vec::new();
    let coverage = silhouette::Coverage::of(&ctx.sequence.cameras, &masks);
    let full = coverage.full_problem(frame, p.all_but, ctx.sequence.cameras.len());
    warnings.extend(full.map_err(|m| Error::invalid(&ctx.sequence.dir, m))?);
    let hull = visual_hull::reconstruct(&ctx.sequence.cameras, &masks, p).map_err(|m| {
        Error::invalid(&ctx.config.path, format!("visual_hull, frame {frame}: {m}"))
    })?;
    let dir = ctx.cache.stage_dir(Surface::Hull.stage());
    let mut files = match &hull {
        Some(h) => {
            let mut files = reconstruction::write(&dir, frame, &h.mesh, &h.grid, &h.sdf)?;
            files.push(reconstruction::write_band(&dir, frame, &h.on_cones)?);
            files
        }
        None => {
            warnings.push(format!(
                "frame {frame}: the hull is empty: {}",
                coverage.why_empty()
            ));
            let grid = GridSpec {
                origin: nalgebra::Vector3::zeros(),
                voxel: p.voxel_size,
                dims: [0, 0, 0],
            };
            let mut files = reconstruction::write(&dir, frame, &TriMesh::default(), &grid, &[])?;
            files.push(reconstruction::write_band(
                &dir,
                frame,
                &Default::default(),
            )?);
            files
        }
    };
    files.sort();
    Ok(Output { files, warnings })
}

/// Why `frame`'s hull is empty, from its silhouettes (for the model's and the skeleton's
/// errors, which meet the empty surface later).
pub fn why_hull_is_empty(ctx: &Context, frame: u32) -> String {
    match load_silhouettes(ctx, frame) {
        Ok(masks) => silhouette::Coverage::of(&ctx.sequence.cameras, &masks).why_empty(),
        Err(e) => format!("its silhouettes cannot be read ({e})"),
    }
}

/// Loads the silhouettes of a frame from the cache (for downstream stages and tests).
pub fn load_silhouettes(ctx: &Context, frame: u32) -> Result<Vec<image::GrayImage>> {
    artifacts::silhouettes::read(ctx.cache, frame, &ctx.sequence.cameras)
}

fn graphcut_sources(ctx: &Context, frame: u32, key: &mut KeyBuilder) -> Result<()> {
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

/// What the graph cut does on a masks-only capture.
pub const MASKS_ONLY_GRAPHCUT: &str =
    "the capture has masks and no frames/, so there is no photo-consistency: the hull passes \
     through as the observed surface";

/// What the reliability stage does on a masks-only capture.
pub const MASKS_ONLY_RELIABILITY: &str =
    "the capture has masks and no frames/: rho_p is 1 on every vertex, so the fit weighs \
     contacts only (the rho_c method)";

/// What each stage will do on this capture and why, one line per stage (`pipeline check`).
pub fn plan_notes(ctx: &Context) -> Result<Vec<String>> {
    let seq = ctx.sequence;
    let silhouette = match resolve_method(ctx)? {
        SilhouetteMethod::Masks if ctx.config.silhouette.clean_given => {
            "the given masks (masks/), cleaned (silhouette.clean_given)"
        }
        SilhouetteMethod::Masks => "the given masks (masks/)",
        SilhouetteMethod::Constant => "subtraction of one constant background colour",
        _ => "background subtraction against the plates (background/)",
    };
    let photo = seq.has_frames;
    let skeleton = seq.skeleton()?.is_some();
    let fit = if skeleton {
        "from skeleton.yaml at the reference frame"
    } else {
        "skipped: no skeleton.yaml (make one with `pipeline skeleton`)"
    };
    Ok(vec![
        format!("silhouette: {silhouette}"),
        format!(
            "visual_hull: voxel carving at {} m",
            ctx.config.visual_hull.voxel_size
        ),
        format!(
            "graphcut: {}",
            if photo {
                "refines the hull by multi-view photo-consistency"
            } else {
                MASKS_ONLY_GRAPHCUT
            }
        ),
        format!(
            "reliability: {}",
            if photo {
                "ZNCC and rho_p of every surface vertex"
            } else {
                MASKS_ONLY_RELIABILITY
            }
        ),
        format!("model, fit: {fit}"),
        format!(
            "export: {}",
            if skeleton {
                "meshes, motion (glb, bvh) and overlays"
            } else {
                "meshes only (no motion without a skeleton)"
            }
        ),
    ])
}

/// The frame's images as grey: decoded, or kept from an earlier stage of the frame
/// ([`Context::sharing_frame_images`]).
fn grey_frames(ctx: &Context, frame: u32) -> Result<Arc<Vec<GreyImage>>> {
    fn kept(m: &FrameImages) -> std::sync::MutexGuard<'_, HashMap<u32, Arc<Vec<GreyImage>>>> {
        m.lock().unwrap_or_else(|e| e.into_inner())
    }
    if let Some(grey) = ctx
        .frame_images
        .as_ref()
        .and_then(|m| kept(m).get(&frame).cloned())
    {
        return Ok(grey);
    }
    let frames: Vec<image::RgbImage> = (0..ctx.sequence.cameras.len())
        .into_par_iter()
        .map(|c| ctx.sequence.load_frame(c, frame))
        .collect::<Result<_>>()?;
    let grey = Arc::new(crate::photo::grey(&frames));
    if let Some(m) = &ctx.frame_images {
        kept(m).insert(frame, grey.clone());
    }
    Ok(grey)
}

fn reliability_compute(ctx: &Context, frame: u32) -> Result<Output> {
    let p = &ctx.config.reliability;
    let grid = reconstruction::read_grid_spec(ctx.cache, Surface::Refined, frame)?;
    let mesh = reconstruction::read_mesh(ctx.cache, Surface::Refined, frame)?;
    let mut warnings = Vec::new();
    let observed = if mesh.vertices.is_empty() {
        warnings.push(format!("frame {frame}: the refined surface is empty"));
        reliability::Observed::default()
    } else if !ctx.sequence.has_frames {
        warnings.push(format!("reliability: {MASKS_ONLY_RELIABILITY}"));
        reliability::Observed::unweighted(&mesh)
    } else {
        let images = grey_frames(ctx, frame)?;
        reliability::observe(&ctx.sequence.cameras, &images, &mesh, grid.voxel, p)
    };
    let dir = ctx.cache.stage_dir(artifacts::observation::STAGE);
    let files = artifacts::observation::write(&dir, frame, &mesh, &observed, p)?;
    Ok(Output { files, warnings })
}

fn graphcut_compute(ctx: &Context, frame: u32) -> Result<Output> {
    let p = &ctx.config.graphcut;
    let (grid, sdf) = reconstruction::read_grid(ctx.cache, Surface::Hull, frame)?;
    let dir = ctx.cache.stage_dir(Surface::Refined.stage());
    let occupied: Vec<bool> = sdf.iter().map(|&v| v < 0.0).collect();
    if !occupied.iter().any(|&o| o) {
        // An empty hull stays empty.
        let warning = format!("frame {frame}: the hull is empty");
        return Ok(Output {
            files: reconstruction::write(&dir, frame, &TriMesh::default(), &grid, &sdf)?,
            warnings: vec![warning],
        });
    }
    if !ctx.sequence.has_frames {
        // Nothing to refine with: the hull passes through unchanged.
        let mesh = reconstruction::read_mesh(ctx.cache, Surface::Hull, frame)?;
        return Ok(Output {
            files: reconstruction::write(&dir, frame, &mesh, &grid, &sdf)?,
            warnings: vec![format!("graphcut: {MASKS_ONLY_GRAPHCUT}")],
        });
    }
    let hull = reconstruction::read_mesh(ctx.cache, Surface::Hull, frame)?;
    let cams = &ctx.sequence.cameras;
    let depth = crate::photo::depth_maps(cams, &hull);
    let images = grey_frames(ctx, frame)?;
    // Long cuts report their progress (drawn only when stderr is a terminal).
    let spinner = indicatif::ProgressBar::new_spinner();
    let mut report = |flow: f64, augmentations: u64| {
        spinner.set_message(format!(
            "frame {frame}: max-flow {flow:.3e} after {augmentations} augmentations"
        ));
        spinner.tick();
    };
    // The silhouettes pin the rims; nothing else in the cut reads them.
    let masks = if p.pin_rims {
        load_silhouettes(ctx, frame)?
    } else {
        Vec::new()
    };
    let refined = graphcut::refine(
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
    let hull_on_cones = reconstruction::read_hull_on_cones(ctx.cache, frame, &sdf)?;
    let (refined_sdf, mut mesh) =
        graphcut::mesh(&grid, &refined, &hull_on_cones, p.smoothing_iterations);
    if p.photo_refine > 0.0 {
        use crate::photo::refine::{refine_along_normals, RefineSettings};
        let settings = RefineSettings::with_search(p.photo_refine);
        let smoothed: Vec<GreyImage> = images
            .par_iter()
            .map(|g| g.blurred(settings.image_sigma))
            .collect();
        refine_along_normals(cams, &smoothed, &mut mesh, grid.voxel, &settings);
    }
    Ok(Output {
        files: reconstruction::write(&dir, frame, &mesh, &grid, &refined_sdf)?,
        warnings: Vec::new(),
    })
}
