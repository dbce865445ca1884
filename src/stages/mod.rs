//! The stages as the runner drives them. A stage is a function of what it reads:
//!
//! - its **settings**, a struct resolved from pipeline.yaml and the capture (the fit's holds
//!   the frame rate, the graph cut's whether the capture has frame images) — the runner
//!   computes the stage's cache key from exactly this struct, so a key cannot miss a
//!   parameter the stage reads;
//! - its **sources**, the raw files it reads (masks, frames, plates, the calibration),
//!   whose contents its key holds;
//! - the artifacts of the stages it declares as **inputs**, read through [`Inputs`], which
//!   refuses any other (their keys are in its key).
//!
//! It returns a typed artifact ([`crate::artifacts`]) and writes nothing: the runner writes
//! the artifact and records it in the cache.

pub mod fit;
pub mod graphcut;
pub mod model;
pub mod reliability;
pub mod silhouette;
pub mod surface;
pub mod visual_hull;

use crate::artifacts::reconstruction::{self, Surface};
use crate::artifacts::Artifact;
use crate::cache::{Cache, KeyBuilder};
use crate::config::Config;
use crate::dataset::Sequence;
use crate::error::{Error, Result};
use crate::geometry::grid::GridSpec;
use crate::geometry::TriMesh;
use crate::photo::GreyImage;
use crate::recon::silhouette::SilhouetteMethod;
use rayon::prelude::*;
use serde::Serialize;
use std::collections::HashMap;
use std::path::Path;
use std::sync::{Arc, Mutex};

/// A run's view of the capture, the configuration and the cache (for the runner, and for
/// the commands that read the cache).
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

    /// What `stage` may read besides its settings.
    pub fn inputs(&self, stage: &'static StageDef) -> Inputs<'_> {
        Inputs {
            sequence: self.sequence,
            config_path: &self.config.path,
            cache: self.cache,
            stage,
            frame_images: self.frame_images.as_ref(),
        }
    }
}

/// What a stage's computation may read besides its settings: the capture (cameras and raw
/// files, which its key's sources cover) and the artifacts of the stages it declares as
/// inputs. Reading any other stage's artifact is an error, so a stage's key cannot miss an
/// artifact it reads.
pub struct Inputs<'a> {
    pub sequence: &'a Sequence,
    /// pipeline.yaml, for naming it in errors (not a parameter: it is not in the key).
    pub config_path: &'a Path,
    cache: &'a Cache,
    stage: &'static StageDef,
    frame_images: Option<&'a FrameImages>,
}

impl Inputs<'_> {
    /// Refuses to read `input`'s artifacts unless the stage declares it (or is it).
    fn declared(&self, input: &str) -> Result<()> {
        if self.stage.name == input || self.stage.inputs.contains(&input) {
            Ok(())
        } else {
            Err(Error::Usage(format!(
                "stage '{}' reads the '{input}' artifacts without declaring them as an input, \
                 so its cache key would miss them (a defect of hullpose, please report it)",
                self.stage.name
            )))
        }
    }

    /// A frame's silhouettes, one per camera.
    pub fn silhouettes(&self, frame: u32) -> Result<Vec<image::GrayImage>> {
        self.declared(crate::artifacts::silhouettes::STAGE)?;
        crate::artifacts::silhouettes::read(self.cache, frame, &self.sequence.cameras)
    }

    /// A frame's person evidence (silhouette method `person`), `None` for other methods.
    pub fn person(&self, frame: u32) -> Result<Option<crate::artifacts::person::PersonFrame>> {
        self.declared(crate::artifacts::silhouettes::STAGE)?;
        crate::artifacts::person::read(self.cache, frame)
    }

    /// Camera `cam`'s learned background, from the plates with `key` (the silhouette
    /// stage's settings hold it, so its key covers them).
    pub fn learned_plate(
        &self,
        key: &str,
        cam: usize,
    ) -> Result<crate::recon::learned_background::Learned> {
        crate::artifacts::learned_background::read(self.cache, key, &self.sequence.cameras[cam])
    }

    /// A frame's reconstructed mesh.
    pub fn mesh(&self, surface: Surface, frame: u32) -> Result<TriMesh> {
        self.declared(surface.stage())?;
        reconstruction::read_mesh(self.cache, surface, frame)
    }

    /// A frame's grid and signed distance.
    pub fn grid(&self, surface: Surface, frame: u32) -> Result<(GridSpec, Vec<f32>)> {
        self.declared(surface.stage())?;
        reconstruction::read_grid(self.cache, surface, frame)
    }

    /// A frame's grid, without its signed distance.
    pub fn grid_spec(&self, surface: Surface, frame: u32) -> Result<GridSpec> {
        self.declared(surface.stage())?;
        reconstruction::read_grid_spec(self.cache, surface, frame)
    }

    /// The hull's solid on the cones of a frame, given its signed distance `sdf`.
    pub fn hull_on_cones(&self, frame: u32, sdf: &[f32]) -> Result<Vec<f32>> {
        self.declared(Surface::Hull.stage())?;
        reconstruction::read_hull_on_cones(self.cache, frame, sdf)
    }

    /// A frame's observed surface with its reliability.
    pub fn observation(&self, frame: u32) -> Result<crate::recon::reliability::Observed> {
        self.declared(crate::artifacts::observation::STAGE)?;
        crate::artifacts::observation::read(self.cache, frame)
    }

    /// The body model.
    pub fn body_model(&self) -> Result<crate::skeleton::model::BodyModel> {
        self.declared(crate::artifacts::body_model::STAGE)?;
        crate::artifacts::body_model::read(self.cache)
    }

    /// A fitted frame's state (the fit reads its earlier frames).
    pub fn fitted_state(
        &self,
        skeleton: &crate::skeleton::Skeleton,
        frame: u32,
    ) -> Result<crate::artifacts::fitted::FitState> {
        self.declared(crate::artifacts::fitted::STAGE)?;
        crate::artifacts::fitted::read_state(self.cache, skeleton, frame)
    }

    /// A tracked frame's mesh (the surface stage reads its previous frame's).
    pub fn tracked_surface(&self, frame: u32) -> Result<TriMesh> {
        self.declared(crate::artifacts::tracked_surface::STAGE)?;
        crate::artifacts::tracked_surface::read_mesh(self.cache, frame)
    }

    /// The frame's images as grey: decoded, or kept from an earlier stage of the frame
    /// ([`Context::sharing_frame_images`]).
    pub fn grey_frames(&self, frame: u32) -> Result<Arc<Vec<GreyImage>>> {
        fn kept(m: &FrameImages) -> std::sync::MutexGuard<'_, HashMap<u32, Arc<Vec<GreyImage>>>> {
            m.lock().unwrap_or_else(|e| e.into_inner())
        }
        if let Some(grey) = self.frame_images.and_then(|m| kept(m).get(&frame).cloned()) {
            return Ok(grey);
        }
        let frames: Vec<image::RgbImage> = (0..self.sequence.cameras.len())
            .into_par_iter()
            .map(|c| self.sequence.load_frame(c, frame))
            .collect::<Result<_>>()?;
        let grey = Arc::new(crate::photo::grey(&frames));
        if let Some(m) = self.frame_images {
            kept(m).insert(frame, grey.clone());
        }
        Ok(grey)
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
    /// Upstream stages whose artifacts it reads (through [`Inputs`], which refuses others).
    pub inputs: &'static [&'static str],
    /// Bumped whenever the artifact's format or meaning changes (invalidates caches).
    pub format_version: u32,
    /// Key material from the raw inputs the stage reads directly for a frame.
    pub sources: fn(&Context, u32, &mut KeyBuilder) -> Result<()>,
    /// Its settings and its computation.
    pub compute: Compute,
    /// After the stage: writes sequence-level outputs from the frames' artifacts (the
    /// frames in computation order); returns the files and warnings.
    pub finish: Option<FinishFn>,
}

impl StageDef {
    /// The stage's resolved settings as canonical text: the key's parameters.
    pub fn settings_text(&self, config: &Config, sequence: &Sequence) -> Result<String> {
        match self.compute {
            Compute::Frame(s) => s.settings_text(config, sequence),
            Compute::Tracked(s) => s.settings_text(config, sequence),
        }
    }
}

/// How a stage computes its frames' artifacts.
#[derive(Clone, Copy)]
pub enum Compute {
    /// Each frame on its own (the runner computes frames side by side).
    Frame(&'static dyn FrameStage),
    /// The frames in order, each from the one before ([`Scope::Tracked`]).
    Tracked(&'static dyn TrackedStage),
}

/// A frame's computed artifact and the things the user should know about it.
pub struct Produced {
    pub artifact: Box<dyn Artifact>,
    pub warnings: Vec<String>,
}

impl Produced {
    pub fn new(artifact: impl Artifact + 'static, warnings: Vec<String>) -> Produced {
        Produced {
            artifact: Box::new(artifact),
            warnings,
        }
    }
}

/// A stage that computes each frame on its own.
pub trait FrameStage: Sync {
    /// The settings as canonical text (the key's parameters).
    fn settings_text(&self, config: &Config, sequence: &Sequence) -> Result<String>;
    /// Resolves the settings and computes `frame`'s artifact from them and `inputs` alone.
    fn compute(&self, config: &Config, inputs: &Inputs, frame: u32) -> Result<Produced>;
}

/// A tracked stage's callback: a frame's artifact and the seconds it took.
pub type Done<'a> = &'a mut dyn FnMut(u32, Produced, f64) -> Result<()>;

/// A stage that computes its frames in order, each from the one before.
pub trait TrackedStage: Sync {
    /// The settings as canonical text (the key's parameters).
    fn settings_text(&self, config: &Config, sequence: &Sequence) -> Result<String>;
    /// Resolves the settings and computes `frames` in order from them and `inputs` alone,
    /// handing each frame's artifact to `done` as soon as it is computed.
    fn compute(&self, config: &Config, inputs: &Inputs, frames: &[u32], done: Done) -> Result<()>;
}

/// A per-frame stage made of its settings' resolution and a computation that sees only
/// them and its inputs.
pub struct PerFrame<S> {
    pub resolve: fn(&Config, &Sequence) -> Result<S>,
    pub compute: fn(&S, &Inputs, u32) -> Result<Produced>,
}

impl<S: Serialize + Sync> FrameStage for PerFrame<S> {
    fn settings_text(&self, config: &Config, sequence: &Sequence) -> Result<String> {
        canonical(&config.path, &(self.resolve)(config, sequence)?)
    }
    fn compute(&self, config: &Config, inputs: &Inputs, frame: u32) -> Result<Produced> {
        (self.compute)(&(self.resolve)(config, inputs.sequence)?, inputs, frame)
    }
}

/// A tracked stage made of its settings' resolution and a computation that sees only them
/// and its inputs.
pub struct InOrder<S> {
    pub resolve: fn(&Config, &Sequence) -> Result<S>,
    pub compute: fn(&S, &Inputs, &[u32], Done) -> Result<()>,
}

impl<S: Serialize + Sync> TrackedStage for InOrder<S> {
    fn settings_text(&self, config: &Config, sequence: &Sequence) -> Result<String> {
        canonical(&config.path, &(self.resolve)(config, sequence)?)
    }
    fn compute(&self, config: &Config, inputs: &Inputs, frames: &[u32], done: Done) -> Result<()> {
        (self.compute)(
            &(self.resolve)(config, inputs.sequence)?,
            inputs,
            frames,
            done,
        )
    }
}

/// Settings as canonical text (YAML of the struct, fields in declaration order).
fn canonical(config_path: &Path, settings: &impl Serialize) -> Result<String> {
    crate::yaml::to_string(settings).map_err(|e| {
        Error::invalid(
            config_path,
            format!("cannot encode a stage's settings for its cache key: {e}"),
        )
    })
}

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

/// All stages, in pipeline order.
pub const STAGES: &[StageDef] = &[
    StageDef {
        name: crate::artifacts::silhouettes::STAGE,
        scope: Scope::PerFrame,
        about: "foreground masks: given masks, or background subtraction",
        inputs: &[],
        // 2: the person model's keypoints put right where a view swaps a left/right pair
        // (they bound the consistency carving).
        format_version: 2,
        sources: silhouette::sources,
        compute: Compute::Frame(&silhouette::STAGE),
        finish: Some(silhouette::finish),
    },
    StageDef {
        name: Surface::Hull.stage(),
        scope: Scope::PerFrame,
        about: "conservative voxel carving and the hull's watertight mesh",
        inputs: &["silhouette"],
        // 6: the keypoints' carving box from the swap-corrected triangulation.
        format_version: 6,
        sources: visual_hull::sources,
        compute: Compute::Frame(&visual_hull::STAGE),
        finish: None,
    },
    StageDef {
        name: Surface::Refined.stage(),
        scope: Scope::PerFrame,
        about: "graph-cut multi-view stereo refinement of the hull",
        inputs: &["silhouette", "visual_hull"],
        format_version: 17,
        sources: graphcut::sources,
        compute: Compute::Frame(&graphcut::STAGE),
        finish: None,
    },
    StageDef {
        name: crate::artifacts::observation::STAGE,
        scope: Scope::PerFrame,
        about: "ZNCC photo-consistency and rho_p of every refined surface vertex",
        inputs: &["graphcut"],
        format_version: 2,
        sources: graphcut::sources,
        compute: Compute::Frame(&reliability::STAGE),
        finish: None,
    },
    StageDef {
        name: crate::artifacts::body_model::STAGE,
        scope: Scope::Reference,
        about: "skin-bone body model from the reference frame's surface and the skeleton",
        inputs: &["silhouette", "graphcut"],
        format_version: 2,
        sources: model::sources,
        compute: Compute::Frame(&model::STAGE),
        finish: None,
    },
    StageDef {
        name: crate::artifacts::fitted::STAGE,
        scope: Scope::Tracked,
        about: "robust articulated fitting of the body model to every frame, tracked from t0",
        inputs: &["silhouette", "reliability", "model"],
        format_version: 14,
        sources: fit::sources,
        compute: Compute::Tracked(&fit::STAGE),
        finish: Some(fit::finish),
    },
    StageDef {
        name: crate::artifacts::tracked_surface::STAGE,
        scope: Scope::Tracked,
        about: "the posed model deformed to each frame's observed surface and silhouettes",
        inputs: &["silhouette", "reliability", "model", "fit"],
        format_version: crate::artifacts::tracked_surface::FORMAT,
        sources: surface::sources,
        compute: Compute::Tracked(&surface::STAGE),
        finish: Some(surface::finish),
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

/// Why a frame's hull is empty, from its silhouettes `masks` as read (for the model's and
/// the skeleton's errors, which meet the empty surface later).
pub fn why_hull_is_empty(
    cameras: &[crate::camera::Camera],
    masks: Result<Vec<image::GrayImage>>,
) -> String {
    match masks {
        Ok(masks) => crate::recon::silhouette::Coverage::of(cameras, &masks).why_empty(),
        Err(e) => format!("its silhouettes cannot be read ({e})"),
    }
}

/// Loads the silhouettes of a frame from the cache (for the commands and tests).
pub fn load_silhouettes(ctx: &Context, frame: u32) -> Result<Vec<image::GrayImage>> {
    crate::artifacts::silhouettes::read(ctx.cache, frame, &ctx.sequence.cameras)
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
    let silhouette = match silhouette::resolve_method(ctx.config, seq)? {
        SilhouetteMethod::Masks if ctx.config.silhouette.clean_given => {
            "the given masks (masks/), cleaned (silhouette.clean_given)"
        }
        SilhouetteMethod::Masks => "the given masks (masks/)",
        SilhouetteMethod::Constant => "subtraction of one constant background colour",
        SilhouetteMethod::Learned => {
            "subtraction of background plates learned from the frames (no plates given)"
        }
        SilhouetteMethod::Person if ctx.config.silhouette.method == SilhouetteMethod::Auto => {
            "the person model's masks, made consistent across cameras (no masks and no plates \
             given, and the person model is set up)"
        }
        SilhouetteMethod::Person => "the person model's masks, made consistent across cameras",
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
