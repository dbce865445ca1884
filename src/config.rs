//! `pipeline.yaml`: what to process and where results go. Paths are relative to the YAML
//! file. Unknown keys and wrong types are errors naming the key and the line.

use crate::error::Refusal;
use crate::error::{Error, Result};
use crate::fit::FitParams;
use crate::geometry::axes::{RotationOrder, UpAxis};
use crate::recon::graphcut::{self, GraphcutParams};
use crate::recon::reliability::{self, ReliabilityParams};
use crate::recon::silhouette::SilhouetteParams;
use crate::recon::visual_hull::{self, VisualHullParams};
use crate::skeleton::model::{self, ModelParams};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// An inclusive range of frame indices.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameRange {
    pub first: u32,
    pub last: u32,
}

impl FrameRange {
    /// Parses `A..B` (inclusive at both ends) or a single frame `A`.
    pub fn parse(s: &str) -> std::result::Result<FrameRange, Refusal> {
        let err =
            || format!("'{s}' is not a frame range; write A..B (inclusive) or a single frame A");
        let (a, b) = match s.split_once("..") {
            Some((a, b)) => (a.trim(), b.trim()),
            None => (s.trim(), s.trim()),
        };
        let first: u32 = a.parse().map_err(|_| err())?;
        let last: u32 = b.parse().map_err(|_| err())?;
        if last < first {
            return Err(format!("frame range '{s}' ends before it starts").into());
        }
        Ok(FrameRange { first, last })
    }

    /// The range of one frame.
    pub fn single(f: u32) -> FrameRange {
        FrameRange { first: f, last: f }
    }

    pub fn contains(&self, f: u32) -> bool {
        (self.first..=self.last).contains(&f)
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PipelineFile {
    calibration: PathBuf,
    sequence: PathBuf,
    #[serde(default)]
    frames: Option<String>,
    #[serde(default = "default_cache")]
    cache: PathBuf,
    #[serde(default = "default_output")]
    output: PathBuf,
    #[serde(default)]
    silhouette: SilhouetteParams,
    #[serde(default)]
    visual_hull: VisualHullParams,
    #[serde(default)]
    graphcut: GraphcutParams,
    #[serde(default)]
    reliability: ReliabilityParams,
    #[serde(default)]
    model: ModelParams,
    #[serde(default)]
    fit: FitParams,
    #[serde(default)]
    export: ExportParams,
    #[serde(default)]
    sync: SyncParams,
    #[serde(default)]
    world: WorldParams,
    #[serde(default)]
    surface: crate::tracked_surface::SurfaceParams,
}

/// Facts of the capture's world frame (pipeline.yaml key `world`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WorldParams {
    /// The world's up direction: an axis (`+z`) or any vector (`[0.1, -0.4, 0.9]`, scaled
    /// to unit length). Unset: `export.up_axis` (its old spelling) if given, else found from
    /// the cameras ([`crate::geometry::up`]).
    pub up: Option<crate::geometry::axes::UpDirection>,
    /// The floor's height along the up direction, metres (the floor is the plane
    /// up . x = floor). Unset: the lowest point of the posed body model over the exported
    /// frames.
    pub floor: Option<f64>,
}

/// Checks the world's parameters against each other and `export.up_axis`.
fn validate_world(w: &WorldParams, export: &ExportParams) -> std::result::Result<(), Refusal> {
    if w.up.is_some() && export.up_axis.is_some() {
        return Err(
            "both world.up and export.up_axis give the world's up: keep world.up \
                    (export.up_axis is its old spelling) and remove export.up_axis"
                .into(),
        );
    }
    if let Some(f) = w.floor {
        if !(f.is_finite() && f.abs() <= 1000.0) {
            return Err(format!("key 'world.floor': {f} is not a height in metres").into());
        }
    }
    Ok(())
}

/// Synchronisation of cameras recorded as videos (pipeline.yaml key `sync`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SyncParams {
    /// Frames added to a camera's frame index to find its video frame, by camera name
    /// (`{cam03: 2}`: the capture's frame 0 is cam03's video frame 2, for a camera that
    /// started recording 2 frames early). Cameras not named: 0. Only for cameras given as
    /// videos (`frames/<camera>.<ext>`).
    pub offsets: std::collections::BTreeMap<String, i64>,
}

/// Every parameter of pipeline.yaml's sections with its default, by dotted key
/// (`graphcut.window`), sorted within each section: the one place the defaults
/// are declared is each section's `Default`; the README's table is checked against this.
/// A nested table (`fit.health`) is flattened; a list is one value.
pub fn default_values() -> Result<Vec<(String, serde_json::Value)>> {
    fn flatten(prefix: &str, v: serde_json::Value, out: &mut Vec<(String, serde_json::Value)>) {
        match v {
            serde_json::Value::Object(map) => {
                for (k, v) in map {
                    flatten(&format!("{prefix}.{k}"), v, out);
                }
            }
            v => out.push((prefix.to_string(), v)),
        }
    }
    let sections = [
        (
            "silhouette",
            serde_json::to_value(SilhouetteParams::default()),
        ),
        (
            "visual_hull",
            serde_json::to_value(VisualHullParams::default()),
        ),
        ("graphcut", serde_json::to_value(GraphcutParams::default())),
        (
            "reliability",
            serde_json::to_value(ReliabilityParams::default()),
        ),
        ("model", serde_json::to_value(ModelParams::default())),
        ("fit", serde_json::to_value(FitParams::default())),
        ("export", serde_json::to_value(ExportParams::default())),
        ("sync", serde_json::to_value(SyncParams::default())),
        ("world", serde_json::to_value(WorldParams::default())),
        (
            "surface",
            serde_json::to_value(crate::tracked_surface::SurfaceParams::default()),
        ),
    ];
    let mut out = Vec::new();
    for (name, value) in sections {
        let value = value
            .map_err(|e| Error::Usage(format!("cannot encode the defaults of '{name}': {e}")))?;
        flatten(name, value, &mut out);
    }
    Ok(out)
}

fn default_cache() -> PathBuf {
    PathBuf::from("cache")
}

fn default_output() -> PathBuf {
    PathBuf::from("output")
}

/// A loaded pipeline configuration with paths resolved against the YAML file's folder.
#[derive(Debug, Clone)]
pub struct Config {
    /// The pipeline.yaml file.
    pub path: PathBuf,
    /// calib/cameras.yaml.
    pub calibration: PathBuf,
    /// data/<sequence>.
    pub sequence: PathBuf,
    /// Frames to process; `None` for every frame of the sequence.
    pub frames: Option<FrameRange>,
    /// Cache folder.
    pub cache: PathBuf,
    /// Output folder.
    pub output: PathBuf,
    /// Stage 1 parameters.
    pub silhouette: SilhouetteParams,
    /// Stage 2 parameters.
    pub visual_hull: VisualHullParams,
    /// Stage 3 parameters.
    pub graphcut: GraphcutParams,
    /// Stage 4 parameters.
    pub reliability: ReliabilityParams,
    /// Stage 5 parameters (`mesh` resolved against the pipeline file's folder).
    pub model: ModelParams,
    /// Stage 6 parameters.
    pub fit: FitParams,
    /// Export parameters.
    pub export: ExportParams,
    /// Video synchronisation.
    pub sync: SyncParams,
    /// The world's up and floor.
    pub world: WorldParams,
    /// Stage 7 parameters: the tracked surface.
    pub surface: crate::tracked_surface::SurfaceParams,
}

impl Config {
    /// The world's up as pipeline.yaml gives it (`world.up`, else the old
    /// `export.up_axis`), unit length; `None` when the capture's own up is to be found.
    pub fn given_up(&self) -> Option<nalgebra::Vector3<f64>> {
        match (&self.world.up, self.export.up_axis) {
            (Some(u), _) => Some(u.vector()),
            (None, Some(axis)) => Some(crate::geometry::axes::up_vector(axis)),
            (None, None) => None,
        }
    }

    /// Reads and checks pipeline.yaml (paths must exist where they are inputs).
    pub fn load(path: &Path) -> Result<Config> {
        let file: PipelineFile = crate::yaml::read(path)?;
        let base = path.parent().unwrap_or(Path::new("."));
        let frames = file
            .frames
            .as_deref()
            .filter(|s| s.trim() != "all")
            .map(FrameRange::parse)
            .transpose()
            .map_err(|m| Error::invalid(path, format!("key 'frames': {m}")))?;
        let config = Config {
            path: path.to_path_buf(),
            calibration: base.join(&file.calibration),
            sequence: base.join(&file.sequence),
            frames,
            cache: base.join(&file.cache),
            output: base.join(&file.output),
            silhouette: file.silhouette,
            visual_hull: file.visual_hull,
            graphcut: file.graphcut,
            reliability: file.reliability,
            model: ModelParams {
                mesh: file.model.mesh.as_ref().map(|m| base.join(m)),
                ..file.model
            },
            fit: file.fit,
            export: file.export,
            sync: file.sync,
            world: file.world,
            surface: file.surface,
        };
        crate::recon::silhouette::validate(&config.silhouette)
            .map_err(|m| Error::invalid(path, m))?;
        graphcut::validate(&config.graphcut).map_err(|m| Error::invalid(path, m))?;
        reliability::validate(&config.reliability).map_err(|m| Error::invalid(path, m))?;
        model::validate(&config.model).map_err(|m| Error::invalid(path, m))?;
        crate::fit::validate(&config.fit).map_err(|m| Error::invalid(path, m))?;
        validate_export(&config.export).map_err(|m| Error::invalid(path, m))?;
        validate_world(&config.world, &config.export).map_err(|m| Error::invalid(path, m))?;
        crate::tracked_surface::validate(&config.surface).map_err(|m| Error::invalid(path, m))?;
        if let Some(mesh) = config.model.mesh.as_ref().filter(|m| !m.is_file()) {
            return Err(Error::invalid(
                path,
                format!(
                    "key 'model.mesh': {} {}",
                    mesh.display(),
                    if std::fs::symlink_metadata(mesh).is_ok() {
                        "is not a regular file (a device, FIFO, folder or broken link); give a PLY or OBJ file"
                    } else {
                        "does not exist (paths are relative to the pipeline file)"
                    }
                ),
            ));
        }
        visual_hull::validate(&config.visual_hull).map_err(|m| Error::invalid(path, m))?;
        for (key, p, dir) in [
            ("calibration", &config.calibration, false),
            ("sequence", &config.sequence, true),
        ] {
            let ok = if dir { p.is_dir() } else { p.is_file() };
            if !ok {
                let problem = match (p.exists(), dir) {
                    (false, _) => "does not exist (paths are relative to the pipeline file)",
                    (true, true) => "is not a folder; give the sequence's folder",
                    (true, false) => "is not a regular file; give the calibration file's path",
                };
                return Err(Error::invalid(
                    path,
                    format!("key '{key}': {} {problem}", p.display()),
                ));
            }
        }
        // The sequence folder holds the capture's inputs (frames, masks, ground truth).
        for (key, place) in [("output", &config.output), ("cache", &config.cache)] {
            let what = format!("{}: key '{key}'", path.display());
            crate::fsutil::check_writable_place(&what, place, &[&config.sequence])?;
            crate::fsutil::refuse_links_into(
                &what,
                place,
                3,
                &[&config.sequence, &config.calibration, &config.path],
            )?;
        }
        Ok(config)
    }

    /// Refuses a file the pipeline is asked to write (`flag` names the option) over the
    /// pipeline file or the calibration, inside the capture's sequence folder, or over
    /// something that is not a regular file ([`crate::fsutil::check_output_target`]); an
    /// existing regular file elsewhere is replaced.
    pub fn check_output_file(&self, flag: &str, file: &Path) -> Result<()> {
        crate::fsutil::check_output_target(
            flag,
            file,
            &[&self.path, &self.calibration, &self.sequence],
            true,
        )
    }
}

/// The pipeline.yaml text for a capture at `calibration` and `sequence` (relative paths).
pub fn default_yaml(calibration: &str, sequence: &str) -> String {
    format!(
        "# hullpose pipeline: paths are relative to this file.\n\
         calibration: {calibration}\n\
         sequence: {sequence}\n\
         # frames to process: A..B (inclusive) or all\n\
         frames: all\n\
         cache: cache\n\
         output: output\n"
    )
}

/// One export format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// glTF 2.0 binary: the skinned body model with the fitted motion as an animation.
    Glb,
    /// BVH: the skeleton hierarchy and the fitted motion.
    Bvh,
    /// Binary PLY of every reconstruction's meshes (normals, colours, quality).
    Ply,
    /// Wavefront OBJ of every reconstruction's meshes (normals, vertex colours).
    Obj,
    /// PNG overlays of the fitted skeleton and the silhouette outline on the input frames,
    /// and a contact sheet of all cameras per frame.
    Overlay,
    /// TRC (OpenSim's marker file): every joint per frame, millimetres, +Y up.
    Trc,
    /// C3D: every joint per frame as a 3D point, millimetres, +Y up.
    C3d,
    /// The tracked surface as one animated mesh: the rest mesh (OBJ) with its point caches
    /// (PC2, MDD) and the same sequence as a glb of morph targets, +Y up.
    Surface,
}

impl Format {
    pub const ALL: [Format; 8] = [
        Format::Glb,
        Format::Bvh,
        Format::Ply,
        Format::Obj,
        Format::Overlay,
        Format::Trc,
        Format::C3d,
        Format::Surface,
    ];

    /// Whether the format needs the fitted motion (a skeleton).
    pub fn needs_motion(self) -> bool {
        matches!(
            self,
            Format::Glb
                | Format::Bvh
                | Format::Overlay
                | Format::Trc
                | Format::C3d
                | Format::Surface
        )
    }

    /// Whether the format times the motion (needs `export.frame_rate`).
    pub fn is_timed(self) -> bool {
        matches!(
            self,
            Format::Glb | Format::Bvh | Format::Trc | Format::C3d | Format::Surface
        )
    }
}

/// Parameters of the exports (pipeline.yaml key `export`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExportParams {
    /// What `pipeline run` exports after the fit (default: every format but OBJ, which
    /// holds the same meshes as the PLY files at three times their size).
    pub formats: Vec<Format>,
    /// Capture frame rate, frames per second, when known: the animation's timing (glb,
    /// bvh) and the fit's joint-speed check and motion prior. Unset: the animations are
    /// timed at [`ANIMATION_RATE`] (with a note), the joint-speed check is off, and the
    /// motion prior takes its spread from the tracked motion alone.
    pub frame_rate: Option<f64>,
    /// The world's up direction (`+x`, `-x`, `+y`, `-y`, `+z`, `-z`), when known: glb and
    /// bvh are turned so that it becomes +Y, as both formats expect. Unset: the world axes
    /// are written unchanged.
    pub up_axis: Option<UpAxis>,
    /// Euler rotation order of the BVH channels (`ZXY`, `XYZ`, ...): the rotation is
    /// R = R_first R_second R_third, angles in degrees.
    pub bvh_rotation_order: String,
    /// Cameras whose views get skeleton overlays (empty: the first camera).
    pub overlay_cameras: Vec<String>,
    /// Whether a contact sheet of all cameras is drawn per frame.
    pub contact_sheet: bool,
}

impl Default for ExportParams {
    fn default() -> Self {
        ExportParams {
            formats: vec![
                Format::Glb,
                Format::Bvh,
                Format::Ply,
                Format::Overlay,
                Format::Surface,
            ],
            frame_rate: None,
            up_axis: None,
            bvh_rotation_order: "ZXY".into(),
            overlay_cameras: Vec::new(),
            contact_sheet: true,
        }
    }
}

/// The animations' timing when `export.frame_rate` is unset, frames per second.
pub const ANIMATION_RATE: f64 = 25.0;

/// The frame rates `export.frame_rate` accepts, frames per second: outside, the exports'
/// times print as 0 or as hundreds of digits.
pub const MIN_FRAME_RATE: f64 = 0.01;
pub const MAX_FRAME_RATE: f64 = 10_000.0;

/// Checks the parameters; the message names the key.
pub fn validate_export(p: &ExportParams) -> std::result::Result<(), Refusal> {
    if let Some(rate) = p.frame_rate {
        if !(rate.is_finite() && (MIN_FRAME_RATE..=MAX_FRAME_RATE).contains(&rate)) {
            return Err(format!(
                "key 'export.frame_rate': {rate} is not a number of frames per second from \
                 {MIN_FRAME_RATE} to {MAX_FRAME_RATE} (leave it out when the capture's rate is \
                 unknown)"
            )
            .into());
        }
    }
    RotationOrder::parse(&p.bvh_rotation_order)
        .map_err(|m| format!("key 'export.bvh_rotation_order': {m}"))?;
    Ok(())
}
