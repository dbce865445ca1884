//! Stage 6, robust articulated fitting ([`crate::fit`]), tracked from the reference frame.
//!
//! Artifacts per frame (in the stage folder): `NNNNNN.pose.csv` (the pose parameters, the
//! poses.csv schema), `NNNNNN.joints.csv` (joint positions, the joints.csv schema),
//! `NNNNNN.fit.csv` (diagnostics) and `NNNNNN.ply` (the posed model, coloured by part).
//! After the stage, the output folder gets the whole run's `joints.csv`, `poses.csv` and
//! `fit.csv`.

use super::{Context, Done, InOrder, Inputs, Produced};
use crate::artifacts::fitted::{self, FitState, FittedFrame};
use crate::cache::KeyBuilder;
use crate::config::Config;
use crate::dataset::Sequence;
use crate::error::{Error, Result};
use crate::fit::{
    FitDiagnostics, FitResult, FitStatus, Fitter, Neighbours, Observation, Probe, Tracker,
};
use crate::geometry::TriMesh;
use crate::joints::JointRow;
use crate::skeleton::model::BodyModel;
use crate::skeleton::{Pose, Skeleton};
use nalgebra::Vector3;
use serde::Serialize;
use std::path::Path;

/// Header of the diagnostics CSV.
pub const DIAGNOSTICS_HEADER: &str =
    "frame,status,iterations,lm_steps,energy,rms_m,downweighted_share,contact_share,observed,score";

/// The health columns that follow the diagnostics in the stage's CSVs
/// ([`crate::fit::health`]): the worst camera's silhouette IoU, that camera's name, the
/// median IoU over the cameras, the largest joint motion since the previous frame, the
/// reliable observed surface the fit left unexplained (cm^2), the recovery (empty: not
/// needed; `kept`: tried, the first fit kept; else the hypothesis that won), and the
/// health checks that failed after it (`fast_joint`, `iou_drop`, `iou_drift`, `unexplained`, joined by
/// `+`; empty when none).
pub const HEALTH_HEADER: &str =
    "iou_worst,iou_worst_camera,iou_median,joint_motion_m,unexplained_cm2,recovery,flags";

pub(super) fn sources(_ctx: &Context, _frame: u32, _key: &mut KeyBuilder) -> Result<()> {
    Ok(())
}

/// What the stage reads besides its inputs' artifacts.
#[derive(Debug, Clone, Serialize)]
pub struct Settings {
    pub fit: crate::fit::FitParams,
    /// Capture frame rate, frames per second (`export.frame_rate`), when known: the motion
    /// prior's weight and the joint-speed check (off when unknown).
    pub frame_rate: Option<f64>,
    /// Whether the capture has frame images (without, the fit weighs contacts only and
    /// leaves the unexplained-surface check out).
    pub photo: bool,
}

/// The stage.
pub static STAGE: InOrder<Settings> = InOrder { resolve, compute };

/// The fit's settings from pipeline.yaml and the capture.
pub fn resolve(config: &Config, sequence: &Sequence) -> Result<Settings> {
    Ok(Settings {
        fit: config.fit.clone(),
        frame_rate: config.export.frame_rate,
        photo: sequence.has_frames,
    })
}

/// One diagnostics row (no header).
pub fn diagnostics_row(frame: u32, d: &FitDiagnostics) -> String {
    format!(
        "{frame},{},{},{},{:e},{:.6},{:.4},{:.4},{},{:e}",
        d.status.name(),
        d.iterations,
        d.lm_steps,
        d.energy,
        d.rms,
        d.downweighted_share,
        d.contact_share,
        d.observed,
        d.score
    )
}

/// Joint rows of `pose` at `frame`.
pub fn joint_rows(skeleton: &Skeleton, frame: u32, pose: &Pose) -> Vec<JointRow> {
    crate::skeleton::pose::joints(skeleton, pose)
        .into_iter()
        .zip(&skeleton.bones)
        .map(|((head, tail), bone)| JointRow {
            frame,
            bone: bone.name.clone(),
            head,
            tail,
        })
        .collect()
}

/// A frame's observed surface as the fit reads it.
fn observation(inputs: &Inputs, frame: u32) -> Result<Observation> {
    Ok(as_observation(inputs.observation(frame)?))
}

/// A cached frame's observed surface as the fit reads it (for the benchmarks).
pub fn cached_observation(ctx: &Context, frame: u32) -> Result<Observation> {
    Ok(as_observation(crate::artifacts::observation::read(
        ctx.cache, frame,
    )?))
}

pub(crate) fn as_observation(o: crate::recon::reliability::Observed) -> Observation {
    Observation {
        vertices: o.vertices.iter().map(|v| v.cast()).collect(),
        normals: o.normals.iter().map(|v| v.cast()).collect(),
        rho_p: o.rho_p.iter().map(|&v| v as f64).collect(),
    }
}

/// Tracks `frames` (in computation order, as [`crate::runner::Job::tracked_frames`] gives
/// them: t0 first, or resuming after frames already cached) with `params`: the one path of
/// `pipeline run` and `pipeline bench track`. Each frame's fit starts from its neighbour's
/// pose in memory; a neighbour not among `frames` is read back from the cache. After each
/// frame, `done` gets its fit, its observed surface and the seconds the fit took (loading
/// excluded).
fn track(
    inputs: &Inputs,
    settings: &Settings,
    model: &BodyModel,
    checks: &HealthChecks,
    frames: &[u32],
    probe: &Probe,
    done: &mut dyn FnMut(u32, &FitResult, &Observation, f64) -> Result<()>,
) -> Result<()> {
    let t0 = model.skeleton.reference_frame;
    let seq = inputs.sequence;
    let params = &settings.fit;
    let mut fitter = Fitter::new(model, params.clone());
    let frame_rate = settings.frame_rate;
    fitter.max_joint_step = frame_rate.map(|f| params.health.max_joint_speed / f);
    // The motion prior belongs to the proposed method's energy; the baselines stay the
    // methods the paper compares.
    if params.method == crate::fit::Method::Proposed {
        fitter.motion_prior = crate::fit::params::motion_prior_weight(
            params.motion_prior_acceleration,
            frame_rate.unwrap_or(crate::fit::params::NOMINAL_FRAME_RATE),
        );
    }
    fitter.photo_consistent = settings.photo;
    let mut tracker = Tracker::new(fitter);
    for &frame in frames {
        let neighbours = if frame == t0 {
            None
        } else {
            let previous = seq.tracked_previous(frame, t0).ok_or_else(|| {
                Error::Usage(format!("fit: frame {frame} has no tracked neighbour"))
            })?;
            let before = seq.tracked_previous(previous, t0);
            for f in std::iter::once(previous).chain(before) {
                if !tracker.knows(f) {
                    let state = inputs.fitted_state(&model.skeleton, f)?;
                    tracker.know(f, state.pose, state.diagnostics);
                }
            }
            Some(Neighbours { previous, before })
        };
        let obs = observation(inputs, frame)?;
        let started = std::time::Instant::now();
        let judge = Silhouettes {
            inputs,
            model,
            checks,
            frame,
            observed: &obs.vertices,
            reach: params.health.surface_reach,
            masks: std::cell::OnceCell::new(),
        };
        let result = tracker.fit(frame, &obs, neighbours, Some(&judge), probe);
        done(frame, &result, &obs, started.elapsed().as_secs_f64())?;
    }
    Ok(())
}

/// Tracks `frames` in memory (no cache writes) for benchmarks and the ablation: every
/// frame's fit, its seconds, and what the probe measured.
pub fn track_in_memory(
    ctx: &Context,
    frames: &[u32],
    params: &crate::fit::FitParams,
    progress: &dyn Fn(u32),
) -> Result<Tracked> {
    let fit = super::find(fitted::STAGE)?;
    let inputs = ctx.inputs(fit);
    let settings = Settings {
        fit: params.clone(),
        ..resolve(ctx.config, ctx.sequence)?
    };
    let model = inputs.body_model()?;
    let checks = HealthChecks::new(&model);
    let probe = Probe::default();
    let mut out = Vec::with_capacity(frames.len());
    let mut seconds = Vec::with_capacity(frames.len());
    let mut rounds = Vec::new();
    track(
        &inputs,
        &settings,
        &model,
        &checks,
        frames,
        &probe,
        &mut |frame, result, _, secs| {
            seconds.push((frame, secs));
            rounds.extend(probe.take_rounds().into_iter().map(|r| (frame, r)));
            out.push((frame, result.clone()));
            progress(frame);
            Ok(())
        },
    )?;
    out.sort_by_key(|x| x.0);
    Ok(Tracked {
        results: out,
        seconds,
        steps: probe.timings(),
        reused: probe.reused_shares(),
        rounds,
    })
}

/// What [`track_in_memory`] computed, and how long it took.
pub struct Tracked {
    /// Every frame's fit, in frame order.
    pub results: Vec<(u32, FitResult)>,
    /// Seconds each frame's fit took (loading excluded), in computation order.
    pub seconds: Vec<(u32, f64)>,
    /// Seconds spent in each step of the rounds, summed over all frames.
    pub steps: Vec<(&'static str, f64)>,
    /// The shares of answers reused from an earlier round ([`crate::fit::Probe::reused_shares`]).
    pub reused: [f64; 3],
    /// Every round of every frame's fits, in computation order.
    pub rounds: Vec<(u32, crate::fit::RoundRecord)>,
}

/// The stage's computation: tracks `frames` ([`track`]), handing each frame's artifact
/// to `done` as soon as the frame is fitted.
fn compute(settings: &Settings, inputs: &Inputs, frames: &[u32], done: Done) -> Result<()> {
    let model = inputs.body_model()?;
    let probe = Probe::default();
    let checks = HealthChecks::new(&model);
    // The states of the frames fitted in this run (earlier frames are read from the cache):
    // a frame's health is judged against its previous tracked frames, wherever they were
    // computed, so a resumed run flags what a fresh one flags.
    let mut states: std::collections::HashMap<u32, FitState> = Default::default();
    let t0 = model.skeleton.reference_frame;
    let seq = inputs.sequence;
    track(
        inputs,
        settings,
        &model,
        &checks,
        frames,
        &probe,
        &mut |frame, result, obs, secs| {
            // The run keeps no round log: dropped frame by frame, so it never grows.
            probe.take_rounds();
            // The previous tracked frames, nearest first.
            let mut previous = Vec::new();
            let mut at = frame;
            while previous.len() < crate::fit::health::RECENT_FRAMES {
                let Some(p) = seq.tracked_previous(at, t0) else {
                    break;
                };
                let state = match states.get(&p) {
                    Some(s) => s.clone(),
                    None => inputs.fitted_state(&model.skeleton, p)?,
                };
                previous.push(state);
                at = p;
            }
            // The larger eq. 4 of the two previous tracked frames: a frame near the
            // reference pose, which the model fits almost exactly, is a poor yardstick (as
            // for the restarts, `Tracker::fit`).
            let previous_energy = previous
                .iter()
                .take(2)
                .map(|s| s.diagnostics.energy)
                .reduce(f64::max);
            // Oldest first, as the health checks take them.
            let recent: Vec<f64> = previous.iter().rev().map(|s| s.iou_worst).collect();
            let previous_pose = previous.first().map(|s| s.pose.clone());
            // The reference frame's level, for the drift check (none at t0 itself).
            let reference_iou = if frame == t0 {
                None
            } else {
                Some(match states.get(&t0) {
                    Some(s) => s.iou_worst,
                    None => inputs.fitted_state(&model.skeleton, t0)?.iou_worst,
                })
            };
            let produced = fitted_frame(
                inputs,
                settings,
                &model,
                &checks,
                &recent,
                reference_iou,
                previous_pose.as_ref(),
                previous_energy,
                frame,
                result,
                obs,
            )?;
            states.insert(frame, produced.1);
            // Only the last few frames and t0 are read again (others come from the cache).
            if states.len() > 4 * crate::fit::health::RECENT_FRAMES {
                states.retain(|&f, _| {
                    f == t0 || f.abs_diff(frame) <= crate::fit::health::RECENT_FRAMES as u32 + 1
                });
            }
            done(frame, produced.0, secs)
        },
    )
}

/// Cell of the coarse model the fit's health is measured with, metres.
pub(crate) const HEALTH_CELL: f64 = 0.02;

/// What the health checks measure a fitted pose with: the model coarsened for the
/// silhouettes, and its parts as capsules.
struct HealthChecks {
    coarse: crate::fit::health::CoarseModel,
    capsules: crate::fit::interpenetration::Capsules,
}

impl HealthChecks {
    fn new(model: &BodyModel) -> HealthChecks {
        HealthChecks {
            coarse: crate::fit::health::CoarseModel::new(&model.mesh, HEALTH_CELL),
            capsules: crate::fit::interpenetration::Capsules::new(model),
        }
    }

    /// The silhouette IoU per camera of the posed model `mesh`, coarse, and moved onto the
    /// frame's `observed` surface where that lies within `reach` metres (the health measure).
    fn ious(
        &self,
        mesh: &TriMesh,
        observed: &[Vector3<f64>],
        reach: f64,
        cameras: &[crate::camera::Camera],
        masks: &[image::GrayImage],
    ) -> Vec<f64> {
        let measured = crate::fit::surface_layer::follow(&self.coarse.posed(mesh), observed, reach);
        crate::fit::health::silhouette_iou(cameras, masks, &measured)
    }
}

/// One frame's silhouettes as the judge of recovery's fits ([`crate::fit::SilhouetteScore`]),
/// with the health check's measure; the masks are read when first needed.
struct Silhouettes<'a> {
    inputs: &'a Inputs<'a>,
    model: &'a BodyModel,
    checks: &'a HealthChecks,
    frame: u32,
    observed: &'a [Vector3<f64>],
    /// `fit.health.surface_reach`, metres.
    reach: f64,
    masks: std::cell::OnceCell<Option<Vec<image::GrayImage>>>,
}

impl crate::fit::SilhouetteScore for Silhouettes<'_> {
    fn worst_iou(&self, pose: &Pose) -> Option<f64> {
        let masks = self
            .masks
            .get_or_init(|| self.inputs.silhouettes(self.frame).ok())
            .as_ref()?;
        let iou = self.checks.ious(
            &self.model.pose(pose),
            self.observed,
            self.reach,
            &self.inputs.sequence.cameras,
            masks,
        );
        Some(crate::fit::health::summarize(&iou, 0.0).iou_worst)
    }
}

/// One fitted frame's silhouettes with everything the health check measures a pose by,
/// loaded from the cache (`pipeline pose-search`): the same worst-camera IoU as
/// fit.csv's `iou_worst` for the frame's fitted pose.
pub struct FrameSilhouettes {
    pub model: BodyModel,
    /// The frame's fitted pose.
    pub fitted: Pose,
    checks: HealthChecks,
    observed: Vec<Vector3<f64>>,
    masks: Vec<image::GrayImage>,
    cameras: Vec<crate::camera::Camera>,
    /// `fit.health.surface_reach`, metres.
    reach: f64,
}

impl FrameSilhouettes {
    /// Frame `frame`'s silhouettes, observed surface and fitted pose from the cache; an
    /// error naming what is missing when the frame was not fitted.
    pub fn load(ctx: &Context, frame: u32) -> Result<FrameSilhouettes> {
        let model = crate::artifacts::body_model::read(ctx.cache)?;
        let fitted = fitted::read_state(ctx.cache, &model.skeleton, frame)
            .map_err(|e| {
                Error::Usage(format!(
                    "frame {frame} has no cached fit ({e}); run the pipeline through the fit \
                     stage for that frame first"
                ))
            })?
            .pose;
        let observed = cached_observation(ctx, frame)?.vertices;
        let cameras = ctx.sequence.cameras.clone();
        let masks = crate::artifacts::silhouettes::read(ctx.cache, frame, &cameras)?;
        Ok(FrameSilhouettes {
            checks: HealthChecks::new(&model),
            model,
            fitted,
            observed,
            masks,
            cameras,
            reach: ctx.config.fit.health.surface_reach,
        })
    }

    /// The silhouette IoU of the model posed at `pose`, per camera (the health measure).
    pub fn ious(&self, pose: &Pose) -> Vec<f64> {
        self.checks.ious(
            &self.model.pose(pose),
            &self.observed,
            self.reach,
            &self.cameras,
            &self.masks,
        )
    }

    /// The cameras' names, in the order of [`Self::ious`].
    pub fn camera_names(&self) -> Vec<&str> {
        self.cameras.iter().map(|c| c.name.as_str()).collect()
    }
}

/// A frame's artifact with the frame's state; `recent` holds the worst silhouette IoU of
/// the previous tracked frames (oldest first; its health checks compare against them),
/// `reference_iou` the reference frame's, `previous_pose` the previous tracked frame's pose
/// (both none at the reference frame) and `previous_energy` the larger eq. 4 of the two
/// previous tracked frames.
#[allow(clippy::too_many_arguments)]
fn fitted_frame(
    inputs: &Inputs,
    settings: &Settings,
    model: &BodyModel,
    checks: &HealthChecks,
    recent: &[f64],
    reference_iou: Option<f64>,
    previous_pose: Option<&Pose>,
    previous_energy: Option<f64>,
    frame: u32,
    result: &FitResult,
    observed: &Observation,
) -> Result<(Produced, FitState)> {
    let skeleton = &model.skeleton;
    let poses_csv = crate::poses::to_csv(skeleton, &[(frame, result.pose.clone())]);
    let joints_csv = crate::joints::to_csv(&joint_rows(skeleton, frame, &result.pose));
    let mesh = model.pose(&result.pose);
    let iou = checks.ious(
        &mesh,
        &observed.vertices,
        settings.fit.health.surface_reach,
        &inputs.sequence.cameras,
        &inputs.silhouettes(frame)?,
    );
    let motion = previous_pose.map_or(0.0, |before| {
        crate::fit::joint_motion(model, before, &result.pose)
    });
    let mut health = crate::fit::health::summarize(&iou, motion);
    health.interpenetration = checks
        .capsules
        .deepest(model, &result.pose)
        .map_or(0.0, |x| x.2);
    health.end_bend_deg = crate::fit::health::sharpest_end_bend(skeleton, &result.pose);
    health.trunk_twist_deg = crate::fit::health::trunk_twist_deg(skeleton, &result.pose);
    health.energy_ratio = previous_energy
        .filter(|&e| e > 0.0)
        .map_or(0.0, |e| result.diagnostics.energy / e);
    health.ambiguous = result.diagnostics.ambiguous;
    health.unexplained_cm2 = settings
        .photo
        .then(|| crate::fit::unexplained_cm2(&result.diagnostics, settings.fit.sample_spacing));
    let worst_camera = &inputs.sequence.cameras[health.iou_worst_camera].name;
    let flags = crate::fit::health::flags(
        &health,
        recent,
        reference_iou,
        &settings.fit.health,
        settings.frame_rate,
    );
    let diagnostics_csv = format!(
        "{DIAGNOSTICS_HEADER},{HEALTH_HEADER}\n{},{:.4},{worst_camera},{:.4},{:.4},{},{},{}\n",
        diagnostics_row(frame, &result.diagnostics),
        health.iou_worst,
        health.iou_median,
        health.joint_motion,
        health
            .unexplained_cm2
            .map_or(String::new(), |a| format!("{a:.0}")),
        result.diagnostics.recovery.as_deref().unwrap_or(""),
        flags.join("+"),
    );
    let colours: Vec<[u8; 3]> = model
        .labels
        .iter()
        .map(|&l| crate::skeleton::model::part_colour(l))
        .collect();
    let mut warnings = Vec::new();
    if result.diagnostics.status == FitStatus::NoObservation {
        warnings.push(format!(
            "fit: frame {frame} has too little observed surface ({} vertices); it keeps the previous pose",
            result.diagnostics.observed
        ));
    }
    let state = FitState {
        pose: result.pose.clone(),
        diagnostics: result.diagnostics.clone(),
        iou_worst: health.iou_worst,
    };
    let artifact = FittedFrame {
        poses_csv,
        joints_csv,
        diagnostics_csv,
        mesh,
        colours,
        state: state.clone(),
    };
    Ok((Produced::new(artifact, warnings), state))
}

/// Concatenates the frames' artifacts into the output folder: joints.csv, poses.csv and
/// fit.csv, in frame order.
pub(super) fn finish(ctx: &Context, frames: &[u32]) -> Result<super::Finished> {
    let mut frames = frames.to_vec();
    frames.sort_unstable();
    let out = &ctx.config.output;
    let mut joints = String::new();
    let mut poses = String::new();
    let mut diag = format!("{DIAGNOSTICS_HEADER},{HEALTH_HEADER}\n");
    for &f in &frames {
        let rows = fitted::read_rows(ctx.cache, f)?;
        poses += &rows.poses;
        joints += &rows.joints;
        diag += &rows.diagnostics;
    }
    let written = [
        (
            out.join("joints.csv"),
            format!("{}\n{joints}", crate::joints::HEADER),
        ),
        (
            out.join("poses.csv"),
            format!("{}\n{poses}", crate::poses::HEADER),
        ),
        (out.join("fit.csv"), diag),
    ];
    for (path, text) in &written {
        crate::fsutil::write_atomic(path, text.as_bytes())?;
    }
    let health = parse_health(&written[2].0, &written[2].1)?;
    Ok(super::Finished {
        outputs: written.into_iter().map(|x| x.0).collect(),
        files: 3,
        warnings: health_summary(&health),
    })
}

/// The run summary's lines on the fit's health: the frames that needed recovery (and which
/// hypothesis won), and the frames still flagged after it.
fn health_summary(rows: &[HealthRow]) -> Vec<String> {
    let list = |rows: Vec<String>| -> String {
        const SHOWN: usize = 12;
        let more = rows.len().saturating_sub(SHOWN);
        let mut s = rows.into_iter().take(SHOWN).collect::<Vec<_>>().join(", ");
        if more > 0 {
            s += &format!(" and {more} more");
        }
        s
    };
    let mut out = Vec::new();
    let recovered: Vec<&HealthRow> = rows.iter().filter(|r| !r.recovery.is_empty()).collect();
    if !recovered.is_empty() {
        let won = recovered.iter().filter(|r| r.recovery != "kept").count();
        out.push(format!(
            "fit: {} frame(s) needed recovery, {won} recovered by another start: {}",
            recovered.len(),
            list(
                recovered
                    .iter()
                    .map(|r| format!("{} ({})", r.frame, r.recovery))
                    .collect()
            )
        ));
    }
    let flagged: Vec<&HealthRow> = rows.iter().filter(|r| !r.flags.is_empty()).collect();
    if !flagged.is_empty() {
        out.push(format!(
            "fit: {} frame(s) still look implausible: {}; see fit.csv, `pipeline evaluate` and \
             README \"Reading the fit's health\"",
            flagged.len(),
            list(
                flagged
                    .iter()
                    .map(|r| format!("{} ({})", r.frame, r.flags.replace('+', ", ")))
                    .collect()
            )
        ));
    }
    out
}

/// Parses a diagnostics CSV (the per-frame file or fit.csv): (frame, diagnostics) per row.
pub fn parse_diagnostics(path: &Path, text: &str) -> Result<Vec<(u32, FitDiagnostics)>> {
    let mut lines = text.lines();
    let with_health = format!("{DIAGNOSTICS_HEADER},{HEALTH_HEADER}");
    let header = lines.next();
    if header != Some(DIAGNOSTICS_HEADER) && header != Some(with_health.as_str()) {
        return Err(Error::invalid(
            path,
            format!(
                "the first line must be '{DIAGNOSTICS_HEADER}' (a cache from an older \
                 version: run the fit stage again with --force)"
            ),
        ));
    }
    let mut out = Vec::new();
    for (i, line) in lines.enumerate() {
        let bad = || {
            Error::invalid(
                path,
                format!(
                    "line {}: not a diagnostics row ({DIAGNOSTICS_HEADER})",
                    i + 2
                ),
            )
        };
        let parts: Vec<&str> = line.split(',').collect();
        // The health columns, when present, are read by [`parse_health`].
        let [frame, status, iterations, lm_steps, energy, rms, downweighted, contact, observed, score, ..] =
            parts[..]
        else {
            return Err(bad());
        };
        let int = |x: &str| x.parse::<usize>().map_err(|_| bad());
        let real = |x: &str| {
            x.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(bad)
        };
        let frame: u32 = frame.parse().map_err(|_| bad())?;
        let diagnostics = FitDiagnostics {
            status: FitStatus::parse(status).ok_or_else(bad)?,
            iterations: int(iterations)?,
            lm_steps: int(lm_steps)?,
            energy: real(energy)?,
            rms: real(rms)?,
            downweighted_share: real(downweighted)?,
            contact_share: real(contact)?,
            observed: int(observed)?,
            score: real(score)?,
            unexplained: Default::default(),
            recovery: None,
            ambiguous: None,
        };
        out.push((frame, diagnostics));
    }
    Ok(out)
}

/// One frame's health as fit.csv records it.
#[derive(Debug, Clone, PartialEq)]
pub struct HealthRow {
    pub frame: u32,
    pub status: String,
    pub iterations: usize,
    pub iou_worst: f64,
    pub iou_worst_camera: String,
    pub iou_median: f64,
    pub joint_motion: f64,
    /// `None`: not measured (a masks-only capture).
    pub unexplained_cm2: Option<f64>,
    /// The recovery: empty (not needed), `kept`, or the hypothesis that won.
    pub recovery: String,
    /// The failed health checks, `+`-joined (empty: none).
    pub flags: String,
}

/// The health rows of a fit.csv (`path` names it in errors); empty when it predates the
/// health columns.
pub fn parse_health(path: &Path, text: &str) -> Result<Vec<HealthRow>> {
    let mut lines = text.lines();
    if lines.next() != Some(format!("{DIAGNOSTICS_HEADER},{HEALTH_HEADER}").as_str()) {
        return Ok(Vec::new());
    }
    lines
        .enumerate()
        .map(|(i, line)| {
            let bad = || Error::invalid(path, format!("line {}: not a fit.csv row", i + 2));
            let parts: Vec<&str> = line.split(',').collect();
            let [frame, status, iterations, .., iou_worst, camera, iou_median, motion, unexplained, recovery, flags] =
                parts[..]
            else {
                return Err(bad());
            };
            let real = |x: &str| x.parse::<f64>().map_err(|_| bad());
            Ok(HealthRow {
                frame: frame.parse().map_err(|_| bad())?,
                status: status.to_string(),
                iterations: iterations.parse().map_err(|_| bad())?,
                iou_worst: real(iou_worst)?,
                iou_worst_camera: camera.to_string(),
                iou_median: real(iou_median)?,
                joint_motion: real(motion)?,
                unexplained_cm2: match unexplained {
                    "" => None,
                    a => Some(real(a)?),
                },
                recovery: recovery.to_string(),
                flags: flags.to_string(),
            })
        })
        .collect()
}
