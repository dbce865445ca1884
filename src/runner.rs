//! The runner: the only orchestrator. It decides which stages and frames are stale, computes
//! them in parallel over frames, writes artifacts atomically with their manifests, shows
//! progress, and reports what it computed and reused.

use crate::cache::{ArtifactState, Cache, KeyBuilder, Manifest};
use crate::config::{Config, FrameRange};
use crate::dataset::Sequence;
use crate::error::{Error, Result};
use crate::stages::{self, Compute, Context, Produced, Scope, StageDef, STAGES};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use std::collections::HashMap;
use std::time::Instant;

/// What `pipeline run` was asked to do.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Re-run this stage only (upstream artifacts are computed when missing or stale).
    pub only: Option<String>,
    /// Re-run this stage and everything downstream.
    pub from: Option<String>,
    /// Stop after this stage (stages after it are not run).
    pub until: Option<String>,
    /// Recompute even what the cache holds.
    pub force: bool,
}

/// What one stage did in a run.
#[derive(Debug, Clone)]
pub struct StageReport {
    pub stage: &'static str,
    pub computed: usize,
    pub reused: usize,
    pub seconds: f64,
    pub location: std::path::PathBuf,
    /// Warnings the stage raised (e.g. empty frames).
    pub warnings: Vec<String>,
    /// Sequence-level files written to the output folder after the stage.
    pub outputs: Vec<std::path::PathBuf>,
}

/// Per-stage status for `pipeline status`.
#[derive(Debug, Clone)]
pub struct StageStatus {
    pub stage: &'static str,
    pub up_to_date: usize,
    pub stale: usize,
    pub missing: usize,
}

/// A camera sees a surface point for the two-view stages when its direction lies within
/// this angle of the point's normal, degrees.
const SEEING_ANGLE_DEG: f64 = 60.0;

/// Below this share of the hull's surface seen by two cameras, `check` warns.
const MIN_SEEN_TWICE: f64 = 0.5;

/// The share of `mesh`'s surface (its vertices, which marching cubes spreads evenly) that two of
/// `cams` see: in front, inside the image, within [`SEEING_ANGLE_DEG`] of the normal.
/// Occlusion is not tested, so the share is an upper bound.
fn seen_twice_share(cams: &[crate::camera::Camera], mesh: &crate::geometry::TriMesh) -> f64 {
    let normals = mesh.vertex_normals();
    let cos = SEEING_ANGLE_DEG.to_radians().cos();
    let centres: Vec<_> = cams.iter().map(|c| c.centre()).collect();
    let seen = mesh
        .vertices
        .iter()
        .zip(&normals)
        .filter(|(v, n)| {
            cams.iter()
                .zip(&centres)
                .filter(|(cam, c)| {
                    let to_cam = (*c - *v).normalize();
                    n.dot(&to_cam) >= cos && cam.project(v).is_some_and(|px| cam.in_image(&px))
                })
                .count()
                >= 2
        })
        .count();
    seen as f64 / mesh.vertices.len().max(1) as f64
}

/// A loaded sequence with the frames selected for a run.
pub struct Job {
    pub config: Config,
    pub sequence: Sequence,
    pub frames: Vec<u32>,
    pub cache: Cache,
    /// Method `learned`: what learning the plates did (one line for the summary).
    pub learning: Option<String>,
    /// What a read-only load left uncomputed ([`Job::load_read_only`]): while any is
    /// left, no stage's key can be known.
    pub pending: Vec<String>,
}

impl Job {
    /// This job over `frames` only (the same capture, configuration and cache): the
    /// frames a run computes are the job's.
    pub fn with_frames(&self, frames: Vec<u32>) -> Job {
        Job {
            config: self.config.clone(),
            sequence: self.sequence.clone(),
            frames,
            cache: self.cache.clone(),
            learning: self.learning.clone(),
            pending: self.pending.clone(),
        }
    }

    /// Loads pipeline.yaml's capture and selects frames (`frames` overrides the file's),
    /// decoding the camera videos' frames it reads and learning background plates when
    /// the silhouettes need them.
    pub fn load(config: Config, frames: Option<FrameRange>) -> Result<Job> {
        Self::open(config, frames, true)
    }

    /// As [`Job::load`], but writing nothing to the cache (for `pipeline status`): video
    /// frames not decoded yet and plates not learned yet are left so, and named in
    /// [`Job::pending`].
    pub fn load_read_only(config: Config, frames: Option<FrameRange>) -> Result<Job> {
        Self::open(config, frames, false)
    }

    fn open(config: Config, frames: Option<FrameRange>, compute: bool) -> Result<Job> {
        // The frames this job reads: the selected ones, pipeline.yaml's (the learned plates
        // come from those) and the skeleton's reference frame (tracking starts there).
        let window = match frames.or(config.frames) {
            None => None,
            Some(r) => {
                let mut ends = vec![r.first, r.last];
                if let Some(c) = config.frames {
                    ends.extend([c.first, c.last]);
                }
                let skeleton = config.sequence.join("skeleton.yaml");
                if let Ok(t0) =
                    crate::skeleton::Skeleton::read(&skeleton).map(|s| s.reference_frame)
                {
                    ends.push(t0);
                }
                Some((*ends.iter().min().unwrap(), *ends.iter().max().unwrap()))
            }
        };
        let videos = crate::dataset::VideoOptions {
            decoded_root: config.cache.join("decoded"),
            offsets: config.sync.offsets.clone(),
            config_path: config.path.clone(),
            window,
            decode: compute,
        };
        let sequence = Sequence::open_with_videos(&config.calibration, &config.sequence, &videos)?;
        let range = frames.or(config.frames);
        let frames = match range {
            None => sequence.frames.clone(),
            Some(r) => {
                let (first, last) = (sequence.frames[0], *sequence.frames.last().unwrap());
                let selected: Vec<u32> = sequence
                    .frames
                    .iter()
                    .copied()
                    .filter(|&f| r.contains(f))
                    .collect();
                if selected.len() as u64 != (r.last - r.first) as u64 + 1 {
                    let videos = sequence.videos_ending_before(r.last);
                    return Err(Error::Usage(format!(
                        "frame range {}..{} is outside the sequence {} (frames {first}..{last}){}",
                        r.first,
                        r.last,
                        sequence.dir.display(),
                        if videos.is_empty() {
                            String::new()
                        } else {
                            format!("; {}", videos.join("; "))
                        }
                    )));
                }
                selected
            }
        };
        let cache = Cache::new(&config.cache);
        let mut sequence = sequence;
        // The learned plates come from pipeline.yaml's frames, whatever this job computes,
        // so that a shard or a single frame sees the plates a whole run sees.
        let mut pending: Vec<String> = sequence
            .undecoded
            .iter()
            .map(|c| {
                format!(
                    "camera {}'s video frames are not decoded yet (`pipeline run` decodes them)",
                    crate::text::quoted(c)
                )
            })
            .collect();
        let learning = if pending.is_empty() {
            crate::stages::silhouette::learn_plates(&config, &sequence, &cache, compute)?
        } else {
            None
        };
        if !compute
            && learning.is_none()
            && crate::stages::silhouette::resolve_method(&config, &sequence)?
                == crate::recon::silhouette::SilhouetteMethod::Learned
            && pending.is_empty()
        {
            pending.push(
                "the background plates are not learned yet (`pipeline run` learns them)".into(),
            );
        }
        sequence.learned_plates = learning.as_ref().map(|l| l.key.clone());
        Ok(Job {
            config,
            sequence,
            frames,
            cache,
            learning: learning
                .as_ref()
                .map(crate::stages::silhouette::learning_report),
            pending,
        })
    }

    /// This job without camera `name`, with its own cache and output under
    /// `holdout/<name>/` of the job's: the frames rebuilt and tracked as if the camera had
    /// not been there. The learned background is refused (its plates live in the job's own
    /// cache, learned with the camera).
    pub fn holding_out(&self, name: &str) -> Result<Job> {
        let sequence = self.sequence.without_camera(name)?;
        if crate::stages::silhouette::resolve_method(&self.config, &self.sequence)?
            == crate::recon::silhouette::SilhouetteMethod::Learned
        {
            return Err(Error::Usage(format!(
                "holding out camera {} needs silhouettes that do not come from plates \
                 learned with it (silhouette.method: learned); give masks or plates, or use \
                 the person model (silhouette.method: person)",
                crate::text::quoted(name)
            )));
        }
        let mut config = self.config.clone();
        config.cache = self.config.cache.join("holdout").join(name);
        config.output = self.config.output.join("holdout").join(name);
        config.export.overlay_cameras.retain(|c| c != name);
        let cache = Cache::new(&config.cache);
        Ok(Job {
            config,
            sequence,
            frames: self.frames.clone(),
            cache,
            learning: None,
            pending: self.pending.clone(),
        })
    }

    pub fn context(&self) -> Context<'_> {
        Context::new(&self.config, &self.sequence, &self.cache)
    }

    /// The reference frame t0 of the sequence's skeleton, if it has one.
    /// Everything about the capture and pipeline.yaml that a run would otherwise find only
    /// after minutes of work, checked at once: `pipeline run` checks it before its first
    /// stage and `pipeline check` checks the same. The carving needs at least two cameras;
    /// every camera's image fits the image cap; the skeleton's reference frame is a frame of
    /// the sequence; `export.overlay_cameras` names calibrated cameras.
    pub fn validate(&self) -> Result<()> {
        let calibration = &self.config.calibration;
        let cameras = &self.sequence.cameras;
        if cameras.len() < 2 {
            return Err(Error::invalid(
                calibration,
                format!(
                    "holds {} camera; the visual hull carves with at least two cameras (a ring of eight or more gives a useful hull)",
                    cameras.len()
                ),
            ));
        }
        for cam in cameras {
            crate::limits::check_image(calibration, cam.width, cam.height)
                .map_err(|e| Error::Usage(format!("camera '{}': {e}", cam.name)))?;
        }
        crate::camera::check_cameras_look_at_the_scene(cameras)
            .map_err(|m| Error::invalid(calibration, m))?;
        crate::recon::visual_hull::validate_for_cameras(&self.config.visual_hull, cameras.len())
            .map_err(|m| Error::invalid(&self.config.path, m))?;
        self.reference_frame()?;
        for name in &self.config.export.overlay_cameras {
            self.sequence.camera_index(calibration, name).map_err(|e| {
                Error::invalid(&self.config.path, format!("export.overlay_cameras: {e}"))
            })?;
        }
        Ok(())
    }

    /// What the first selected frame's silhouettes (computed as the silhouette stage
    /// would, written nowhere) say before any stage runs (for `pipeline check`): cameras
    /// whose silhouette is empty or covers the whole image, and the box the visual hull
    /// would carve. Refused as `run` would refuse them: every camera's silhouette covering
    /// the whole image (the hull would be the whole box), a carving grid over the memory
    /// cap. Warned: a box far larger than a person.
    pub fn inspect_first_frame(&self) -> Result<Vec<String>> {
        let seq = &self.sequence;
        let Some(&frame) = self.frames.first() else {
            return Ok(Vec::new());
        };
        let (masks, person) =
            crate::stages::silhouette::frame_masks(&self.config, seq, &self.cache, frame)?;
        let mut p = self.config.visual_hull.clone();
        let mut standing = None;
        if let Some(person) = &person {
            let points = crate::person::triangulate::triangulate_frame(&seq.cameras, person);
            standing = crate::person::triangulate::standing_axis(&points);
            println!(
                "person: found in {} of {} cameras at frame {frame}; {}",
                person.views.iter().filter(|v| v.found).count(),
                person.views.len(),
                crate::person::triangulate::summary(std::slice::from_ref(&points))
            );
            if p.bbox.is_none() {
                p.bbox = crate::person::triangulate::body_box(&points);
            }
        }
        let p = &p;
        let up_warnings = self.report_up(standing);
        let cov = crate::recon::silhouette::Coverage::of(&seq.cameras, &masks);
        let full = cov.full_problem(frame, p.all_but, seq.cameras.len());
        let mut out: Vec<String> = full
            .map_err(|m| Error::invalid(&seq.dir, m))?
            .into_iter()
            .collect();
        out.extend(up_warnings);
        if let Some(person) = &person {
            out.extend(crate::stages::silhouette::person_warnings(person));
        }
        if !cov.empty.is_empty() {
            out.push(format!(
                "silhouettes of frame {frame}: camera(s) {} hold no subject pixel, so that \
                 frame's hull will be empty (masks are 255 or 1 on the subject, 0 elsewhere)",
                cov.empty.join(", ")
            ));
            return Ok(out);
        }
        use crate::geometry::grid::GridSpec;
        use crate::recon::visual_hull::{self, MaskCounts};
        let counts: Vec<MaskCounts> = masks
            .iter()
            .zip(&seq.cameras)
            .map(|(m, c)| MaskCounts::new(m, c))
            .collect();
        if let Some((lo, hi)) = visual_hull::carving_box(&seq.cameras, &counts, p) {
            let grid = GridSpec::covering(lo, hi, p.voxel_size);
            visual_hull::check_memory(&grid, p).map_err(|m| {
                Error::invalid(
                    &self.config.path,
                    format!("frame {frame}'s box {:.2?} m: {m}", (hi - lo).as_slice()),
                )
            })?;
            if let Some(line) = self.surface_coverage(frame, &masks, p)? {
                out.push(line);
            }
            if p.bbox.is_none() {
                let size = hi - lo;
                out.extend(cov.box_problem(frame, [size.x, size.y, size.z]));
            }
        }
        Ok(out)
    }

    /// The world's up as the capture shows it (the cameras, and the subject's `standing`
    /// axis where the person model saw it), on stdout; warnings when its cues disagree, or
    /// when the up pipeline.yaml gives (`world.up`, or the old `export.up_axis`) lies far
    /// from it.
    fn report_up(&self, standing: Option<nalgebra::Vector3<f64>>) -> Vec<String> {
        use crate::geometry::up;
        let Some(e) = up::estimate(&self.sequence.cameras, standing) else {
            return Vec::new();
        };
        let mut out = Vec::new();
        match self.config.given_up() {
            None => {
                println!("{}", e.describe());
                if e.spread_deg() > up::DISAGREEMENT_DEG {
                    out.push(format!(
                        "the cues for the world's up disagree by {:.0} degrees (a rig on one \
                         side of the subject, tilted cameras): if the skeleton or the exports \
                         stand askew, set world.up",
                        e.spread_deg()
                    ));
                }
            }
            Some(given) => {
                let off = up::angle_deg(&given, &e.up);
                let v =
                    |u: &nalgebra::Vector3<f64>| format!("({:+.3}, {:+.3}, {:+.3})", u.x, u.y, u.z);
                println!(
                    "up: the given up {} is {off:.1} degrees from the up the capture shows",
                    v(&given)
                );
                if off > 30.0 && e.spread_deg() <= up::DISAGREEMENT_DEG {
                    out.push(format!(
                        "the given up {} lies {off:.0} degrees from the capture's up {} \
                         (nearest axis {}): is world.up (or export.up_axis) right?",
                        v(&given),
                        v(&e.up),
                        up::nearest_axis(&e.up)
                    ));
                }
            }
        }
        out
    }

    /// How much of frame `frame`'s hull surface (carved from `masks` at 2 cm or the
    /// configured voxel, whichever is coarser) at least two cameras see within
    /// [`SEEING_ANGLE_DEG`] of its normal: a warning, with what it means for the stages,
    /// when that is below [`MIN_SEEN_TWICE`]; always one line on stdout.
    fn surface_coverage(
        &self,
        frame: u32,
        masks: &[image::GrayImage],
        p: &crate::recon::visual_hull::VisualHullParams,
    ) -> Result<Option<String>> {
        let cams = &self.sequence.cameras;
        let mut p = p.clone();
        p.voxel_size = p.voxel_size.max(0.02);
        let hull = crate::recon::visual_hull::reconstruct(cams, masks, &p)
            .map_err(|m| Error::invalid(&self.config.path, format!("frame {frame}: {m}")))?;
        let Some(hull) = hull else {
            return Ok(None);
        };
        if let Some(up) = self
            .config
            .given_up()
            .or_else(|| crate::geometry::up::estimate(cams, None).map(|e| e.up))
        {
            let floor = hull
                .mesh
                .vertices
                .iter()
                .map(|v| up.dot(v))
                .fold(f64::INFINITY, f64::min);
            if floor.is_finite() {
                let exports = match self.config.world.floor {
                    Some(f) => format!("world.floor {f:.3} m is what the exports put at Y = 0"),
                    None => "the exports put the posed model's lowest point over the frames at \
                             Y = 0 (world.floor sets it)"
                        .into(),
                };
                println!(
                    "floor: {floor:.3} m along the up (the lowest point of frame {frame}'s \
                     hull); {exports}"
                );
            }
        }
        let share = seen_twice_share(cams, &hull.mesh);
        println!(
            "coverage: {:.0}% of frame {frame}'s hull surface is seen by two or more of the {} \
             cameras (within {SEEING_ANGLE_DEG:.0} degrees of its normal)",
            100.0 * share,
            cams.len()
        );
        Ok((share < MIN_SEEN_TWICE).then(|| {
            format!(
                "only {:.0}% of frame {frame}'s hull surface is seen by two or more cameras \
                 (within {SEEING_ANGLE_DEG:.0} degrees of its normal): elsewhere the graph cut \
                 and the reliability have one view or none, so the surface there is the hull's \
                 (phantom volumes stay) and the fit leans on the silhouettes; the method wants \
                 8 or more cameras around the subject (README, \"How many cameras\")",
                100.0 * share
            )
        }))
    }

    pub fn reference_frame(&self) -> Result<Option<u32>> {
        let Some(skeleton) = self.sequence.skeleton()? else {
            return Ok(None);
        };
        let t0 = skeleton.reference_frame;
        if !self.sequence.frames.contains(&t0) {
            return Err(Error::invalid(
                self.sequence.dir.join("skeleton.yaml"),
                format!(
                    "reference_frame {t0} is not a frame of the sequence (frames {}..{})",
                    self.sequence.frames[0],
                    self.sequence.frames.last().unwrap()
                ),
            ));
        }
        Ok(Some(t0))
    }

    /// The frames a stage makes artifacts for in this job, in the order they are computed.
    ///
    /// With a reference frame t0 (a skeleton, and a reference or tracked stage planned):
    /// a reference stage makes one artifact, at t0; a tracked stage makes every frame of
    /// the sequence from t0 to the selected frames, t0 first, then forwards and backwards
    /// from it (each frame starts from its neighbour nearer to t0); a per-frame stage makes
    /// the selected frames plus those. Without a reference frame: the selected frames, and
    /// nothing for reference and tracked stages.
    fn stage_frames(&self, stage: &StageDef, reference: Option<u32>) -> Vec<u32> {
        let Some(t0) = reference else {
            return match stage.scope {
                Scope::PerFrame => self.frames.clone(),
                _ => Vec::new(),
            };
        };
        let first = self.frames.first().map_or(t0, |&f| f.min(t0));
        let last = self.frames.last().map_or(t0, |&f| f.max(t0));
        let tracked = || -> Vec<u32> {
            let after = self
                .sequence
                .frames
                .iter()
                .copied()
                .filter(|&f| f >= t0 && f <= last);
            let before = self
                .sequence
                .frames
                .iter()
                .rev()
                .copied()
                .filter(|&f| f < t0 && f >= first);
            after.chain(before).collect()
        };
        match stage.scope {
            Scope::Reference => vec![t0],
            Scope::Tracked => tracked(),
            Scope::PerFrame => {
                let mut frames = self.frames.clone();
                frames.extend(tracked());
                frames.sort_unstable();
                frames.dedup();
                frames
            }
        }
    }

    /// The frames a tracked stage (the fit) covers in this job, in computation order; none
    /// without a skeleton.
    pub fn tracked_frames(&self) -> Result<Vec<u32>> {
        let reference = self.reference_frame()?;
        Ok(self.stage_frames(stages::find("fit")?, reference))
    }

    /// Checks that the cache holds up-to-date artifacts of `stages` for the selected frames
    /// (a reference stage: t0), as re-exports need; the error says what to run.
    pub fn require_cached(&self, stages: &[&str]) -> Result<()> {
        let reference = self.reference_frame()?;
        let keys = self.keys(reference)?;
        for name in stages {
            let stage = stages::find(name)?;
            let frames = match stage.scope {
                Scope::Reference => reference.into_iter().collect(),
                Scope::Tracked if reference.is_none() => Vec::new(),
                _ => self.frames.clone(),
            };
            for f in frames {
                let state = self.cache.state(stage.name, f, &keys[&(stage.name, f)]);
                if state != ArtifactState::UpToDate {
                    let what = match state {
                        ArtifactState::Stale => "is stale",
                        ArtifactState::Damaged => "is damaged (its files changed since written)",
                        _ => "is missing",
                    };
                    return Err(Error::Usage(format!(
                        "the cached {} result of frame {f} {what}; run `pipeline run {}` first",
                        stage.name,
                        self.config.path.display()
                    )));
                }
            }
        }
        Ok(())
    }

    /// Cache keys of every stage for every frame it makes artifacts for. A frame's key
    /// covers the stage, its format and parameters, its upstream artifacts' keys (a
    /// reference stage's at t0), its raw inputs, and for a tracked stage the key of the
    /// frame it starts from.
    fn keys(&self, reference: Option<u32>) -> Result<HashMap<(&'static str, u32), String>> {
        let ctx = self.context();
        let mut keys: HashMap<(&'static str, u32), String> = HashMap::new();
        for stage in STAGES {
            let params = stage.settings_text(&self.config, &self.sequence)?;
            let frames = self.stage_frames(stage, reference);
            let key_of = |f: u32, keys: &HashMap<(&'static str, u32), String>| -> Result<String> {
                let mut k = KeyBuilder::new();
                k.add("stage", stage.name)
                    .add("format", &stage.format_version.to_string())
                    .add("params", &params);
                for input in stage.inputs {
                    let scope = stages::find(input)?.scope;
                    let at = if scope == Scope::Reference {
                        reference.unwrap_or(f)
                    } else {
                        f
                    };
                    let upstream = keys.get(&(*input, at)).ok_or_else(|| {
                        Error::Usage(format!(
                            "{}: no {input} artifact for frame {at}",
                            stage.name
                        ))
                    })?;
                    k.add(input, upstream);
                }
                (stage.sources)(&ctx, f, &mut k)?;
                Ok(k.finish())
            };
            if stage.scope == Scope::Tracked {
                for &f in &frames {
                    let mut key = key_of(f, &keys)?;
                    if let Some(prev) =
                        reference.and_then(|t0| self.sequence.tracked_previous(f, t0))
                    {
                        let mut k = KeyBuilder::new();
                        k.add("own", &key)
                            .add("previous", &keys[&(stage.name, prev)]);
                        key = k.finish();
                    }
                    keys.insert((stage.name, f), key);
                }
                continue;
            }
            let per_frame: Vec<(u32, String)> = frames
                .par_iter()
                .map(|&f| Ok((f, key_of(f, &keys)?)))
                .collect::<Result<_>>()?;
            for (f, key) in per_frame {
                keys.insert((stage.name, f), key);
            }
        }
        Ok(keys)
    }
}

/// Stages to consider and whether each is forced, in pipeline order.
fn plan(opts: &RunOptions) -> Result<Vec<(&'static StageDef, bool)>> {
    if opts.only.is_some() && opts.from.is_some() {
        return Err(Error::Usage("use --only or --from, not both".into()));
    }
    let position = |name: &str| -> Result<usize> {
        let stage = stages::find(name)?;
        Ok(STAGES.iter().position(|s| s.name == stage.name).unwrap())
    };
    let mut plan: Vec<(&'static StageDef, bool)> = match (&opts.only, &opts.from) {
        (Some(only), _) => {
            let p = position(only)?;
            STAGES[..=p]
                .iter()
                .enumerate()
                .map(|(i, s)| (s, i == p || opts.force))
                .collect()
        }
        (_, Some(from)) => {
            let p = position(from)?;
            STAGES
                .iter()
                .enumerate()
                .map(|(i, s)| (s, i >= p || opts.force))
                .collect()
        }
        _ => STAGES.iter().map(|s| (s, opts.force)).collect(),
    };
    if let Some(until) = &opts.until {
        let p = position(until)?;
        plan.truncate(p + 1);
    }
    Ok(plan)
}

/// A progress bar over `len` frames labelled `stage` (drawn on stderr, hidden when that is
/// not a terminal).
pub fn bar(len: usize, stage: &str) -> ProgressBar {
    let bar = ProgressBar::new(len as u64);
    bar.set_style(
        ProgressStyle::with_template("{msg:>12} [{bar:30}] {pos}/{len} frames ({eta})")
            .expect("valid template")
            .progress_chars("=> "),
    );
    bar.set_message(stage.to_string());
    bar
}

/// Runs the pipeline: computes what is stale (or forced), reuses the rest.
pub fn run(job: &Job, opts: &RunOptions) -> Result<Vec<StageReport>> {
    let plan = plan(opts)?;
    job.validate()?;
    let wants_reference = plan
        .iter()
        .any(|(s, _)| matches!(s.scope, Scope::Reference | Scope::Tracked));
    let reference = if wants_reference {
        job.reference_frame()?
    } else {
        None
    };
    // Lock every frame this run may write; shards over disjoint frames run side by side.
    let mut touched: Vec<u32> = plan
        .iter()
        .flat_map(|(s, _)| job.stage_frames(s, reference))
        .collect();
    touched.extend(reference);
    let _lock = job.cache.lock_frames(&touched)?;
    job.cache.sweep_temporaries();
    let keys = job.keys(reference)?;
    let ctx = job.context().sharing_frame_images();
    let run = StageRun {
        job,
        ctx: &ctx,
        keys: &keys,
        reference,
    };
    let mut reports = Vec::new();
    let mut i = 0;
    while i < plan.len() {
        if is_per_frame(plan[i].0) {
            // Consecutive per-frame stages run frame by frame.
            let end = (i..plan.len())
                .find(|&j| !is_per_frame(plan[j].0))
                .unwrap_or(plan.len());
            reports.extend(run.per_frame(&plan[i..end])?);
            i = end;
        } else {
            reports.push(run.stage(plan[i].0, plan[i].1)?);
            i += 1;
        }
    }
    Ok(reports)
}

/// Whether a stage makes one artifact per frame, each from that frame alone (its
/// sequence-level step, if any, runs once all frames are done).
fn is_per_frame(stage: &StageDef) -> bool {
    stage.scope == Scope::PerFrame && matches!(stage.compute, Compute::Frame(_))
}

/// A frame's artifact computed by a stage: its warnings and the seconds it took.
type Computed = (Vec<String>, f64);

/// What every stage of a run shares.
struct StageRun<'a> {
    job: &'a Job,
    ctx: &'a Context<'a>,
    keys: &'a HashMap<(&'static str, u32), String>,
    reference: Option<u32>,
}

/// A stage's frames in a run, and which of them it computes.
struct Pending {
    frames: Vec<u32>,
    todo: Vec<u32>,
    /// Notes on artifacts found damaged (they are recomputed).
    damaged: Vec<String>,
}

impl StageRun<'_> {
    fn pending(&self, stage: &StageDef, forced: bool) -> Pending {
        let frames = self.job.stage_frames(stage, self.reference);
        let states: Vec<ArtifactState> = if forced {
            vec![ArtifactState::Stale; frames.len()]
        } else {
            frames
                .iter()
                .map(|&f| {
                    self.job
                        .cache
                        .state(stage.name, f, &self.keys[&(stage.name, f)])
                })
                .collect()
        };
        let todo = frames
            .iter()
            .zip(&states)
            .filter(|(_, &s)| s != ArtifactState::UpToDate)
            .map(|(&f, _)| f)
            .collect();
        let damaged = frames
            .iter()
            .zip(&states)
            .filter(|(_, &s)| s == ArtifactState::Damaged)
            .map(|(f, _)| format!(
                "{}: the cached artifact of frame {f} was damaged (its files changed since they were written); recomputed",
                stage.name
            ))
            .collect();
        Pending {
            frames,
            todo,
            damaged,
        }
    }

    /// Writes a frame's computed artifact into the stage's folder and records it in the
    /// cache; returns its warnings.
    fn write(
        &self,
        stage: &StageDef,
        f: u32,
        produced: Produced,
        seconds: f64,
    ) -> Result<Vec<String>> {
        let dir = self.job.cache.stage_dir(stage.name);
        let files = produced.artifact.write(&dir, f)?;
        self.commit(stage, f, files, seconds)?;
        Ok(produced.warnings)
    }

    /// Records a computed artifact in the cache.
    fn commit(&self, stage: &StageDef, f: u32, files: Vec<String>, seconds: f64) -> Result<()> {
        self.job.cache.commit(&Manifest {
            stage: stage.name.to_string(),
            frame: f,
            key: self.keys[&(stage.name, f)].clone(),
            format_version: stage.format_version,
            files,
            seconds,
            digests: Vec::new(),
        })
    }

    /// The report of a stage that computed `pending.todo` in `seconds`.
    fn report(
        &self,
        stage: &StageDef,
        pending: Pending,
        seconds: f64,
        warnings: Vec<Vec<String>>,
        outputs: Vec<std::path::PathBuf>,
    ) -> StageReport {
        // A note every frame gives alike is said once.
        let mut seen = std::collections::HashSet::new();
        StageReport {
            stage: stage.name,
            computed: pending.todo.len(),
            reused: pending.frames.len() - pending.todo.len(),
            seconds,
            location: self.job.cache.stage_dir(stage.name),
            warnings: std::iter::once(pending.damaged)
                .chain(warnings)
                .flatten()
                .filter(|w| seen.insert(w.clone()))
                .collect(),
            outputs,
        }
    }

    /// Runs consecutive per-frame stages frame by frame: a frame's stages in pipeline
    /// order, frames in parallel. A frame's stages share its decoded images, which are
    /// dropped when its last stage is done, so each frame is decoded once. A stage's
    /// seconds are the group's wall time shared in proportion to its compute time.
    fn per_frame(&self, group: &[(&'static StageDef, bool)]) -> Result<Vec<StageReport>> {
        let start = Instant::now();
        let pending: Vec<Pending> = group
            .iter()
            .map(|&(stage, forced)| self.pending(stage, forced))
            .collect();
        let mut frames: Vec<u32> = pending.iter().flat_map(|p| p.todo.clone()).collect();
        frames.sort_unstable();
        frames.dedup();
        let bars = indicatif::MultiProgress::new();
        let bars: Vec<ProgressBar> = group
            .iter()
            .zip(&pending)
            .map(|(&(stage, _), p)| bars.add(bar(p.todo.len(), stage.name)))
            .collect();
        // Per frame, per stage: the warnings and the compute seconds (None: not computed).
        let done: Vec<Vec<Option<Computed>>> = frames
            .par_iter()
            .map(|&f| {
                let stages = || -> Result<Vec<Option<Computed>>> {
                    let mut out = Vec::with_capacity(group.len());
                    for (k, &(stage, _)) in group.iter().enumerate() {
                        if pending[k].todo.binary_search(&f).is_err() {
                            out.push(None);
                            continue;
                        }
                        let Compute::Frame(compute) = stage.compute else {
                            unreachable!("a per-frame stage computes frames")
                        };
                        let t = Instant::now();
                        let o = compute.compute(self.ctx.config, &self.ctx.inputs(stage), f)?;
                        let seconds = t.elapsed().as_secs_f64();
                        let warnings = self.write(stage, f, o, seconds)?;
                        out.push(Some((warnings, seconds)));
                        bars[k].inc(1);
                    }
                    Ok(out)
                };
                let out = stages();
                self.ctx.forget_frame_images(f);
                out
            })
            .collect::<Result<_>>()?;
        bars.iter().for_each(ProgressBar::finish_and_clear);
        let wall = start.elapsed().as_secs_f64();
        let compute: Vec<f64> = (0..group.len())
            .map(|k| {
                let times = done.iter().filter_map(|d| d[k].as_ref()).map(|d| d.1);
                times.fold(0.0, |a, b| a + b) // (an empty f64 sum is -0.0)
            })
            .collect();
        let total: f64 = compute.iter().sum();
        let mut done = done;
        group
            .iter()
            .zip(pending)
            .enumerate()
            .map(|(k, (&(stage, _), p))| {
                let mut warnings: Vec<Vec<String>> = done
                    .iter_mut()
                    .filter_map(|d| d[k].take())
                    .map(|d| d.0)
                    .collect();
                let share = if total > 0.0 { compute[k] / total } else { 0.0 };
                let mut outputs = Vec::new();
                if let Some(finish) = stage.finish {
                    let finished = finish(self.ctx, &self.job.stage_frames(stage, self.reference))?;
                    outputs = finished.outputs;
                    warnings.push(finished.warnings);
                }
                Ok(self.report(stage, p, wall * share, warnings, outputs))
            })
            .collect()
    }

    /// Runs one stage over its frames: the reference stage on t0,
    /// the tracked stage in order from t0.
    fn stage(&self, stage: &'static StageDef, forced: bool) -> Result<StageReport> {
        let start = Instant::now();
        let ctx = self.ctx;
        let frames = self.job.stage_frames(stage, self.reference);
        if stage.scope != Scope::PerFrame && frames.is_empty() {
            return Ok(StageReport {
                stage: stage.name,
                computed: 0,
                reused: 0,
                seconds: 0.0,
                location: self.job.cache.stage_dir(stage.name),
                warnings: vec![format!(
                    "{}: the sequence has no skeleton.yaml, so there is no body model or motion \
                     (make one with `pipeline skeleton FILE`)",
                    stage.name
                )],
                outputs: Vec::new(),
            });
        }
        let pending = self.pending(stage, forced);
        let progress = bar(pending.todo.len(), stage.name);
        let inputs = ctx.inputs(stage);
        let mut warnings: Vec<Vec<String>> = match stage.compute {
            Compute::Frame(compute) => pending
                .todo
                .par_iter()
                .map(|&f| {
                    let t = Instant::now();
                    let out = compute.compute(ctx.config, &inputs, f)?;
                    let warnings = self.write(stage, f, out, t.elapsed().as_secs_f64())?;
                    progress.inc(1);
                    Ok(warnings)
                })
                .collect::<Result<_>>()?,
            // Tracked frames depend on each other: in order, one at a time.
            Compute::Tracked(compute) => {
                let mut warnings = Vec::new();
                compute.compute(
                    ctx.config,
                    &inputs,
                    &pending.todo,
                    &mut |f, out, seconds| {
                        warnings.push(self.write(stage, f, out, seconds)?);
                        progress.inc(1);
                        Ok(())
                    },
                )?;
                warnings
            }
        };
        progress.finish_and_clear();
        let mut outputs = Vec::new();
        if let Some(finish) = stage.finish {
            let finished = finish(ctx, &frames)?;
            outputs = finished.outputs;
            warnings.push(finished.warnings);
        }
        Ok(self.report(
            stage,
            pending,
            start.elapsed().as_secs_f64(),
            warnings,
            outputs,
        ))
    }
}

/// How many selected frames of each stage are up to date, stale or missing.
pub fn status(job: &Job) -> Result<Vec<StageStatus>> {
    let reference = job.reference_frame()?;
    if !job.pending.is_empty() {
        // Nothing computed from frames not decoded (or plates not learned) can be current.
        return Ok(STAGES
            .iter()
            .map(|s| StageStatus {
                stage: s.name,
                up_to_date: 0,
                stale: 0,
                missing: job.stage_frames(s, reference).len(),
            })
            .collect());
    }
    let keys = job.keys(reference)?;
    Ok(STAGES
        .iter()
        .map(|s| {
            let mut st = StageStatus {
                stage: s.name,
                up_to_date: 0,
                stale: 0,
                missing: 0,
            };
            for f in job.stage_frames(s, reference) {
                match job.cache.state(s.name, f, &keys[&(s.name, f)]) {
                    ArtifactState::UpToDate => st.up_to_date += 1,
                    ArtifactState::Stale => st.stale += 1,
                    ArtifactState::Missing | ArtifactState::Damaged => st.missing += 1,
                }
            }
            st
        })
        .collect())
}
