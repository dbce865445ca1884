//! The runner: the only orchestrator. It decides which stages and frames are stale, computes
//! them in parallel over frames, writes artifacts atomically with their manifests, shows
//! progress, and reports what it computed and reused.

use crate::cache::{ArtifactState, Cache, KeyBuilder, Manifest};
use crate::config::{Config, FrameRange};
use crate::dataset::Sequence;
use crate::error::{Error, Result};
use crate::stages::{self, Context, Scope, StageDef, STAGES};
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
    /// Frames to process (overrides pipeline.yaml).
    pub frames: Option<FrameRange>,
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
}

/// Per-stage status for `pipeline status`.
#[derive(Debug, Clone)]
pub struct StageStatus {
    pub stage: &'static str,
    pub up_to_date: usize,
    pub stale: usize,
    pub missing: usize,
}

/// A loaded sequence with the frames selected for a run.
pub struct Job {
    pub config: Config,
    pub sequence: Sequence,
    pub frames: Vec<u32>,
    pub cache: Cache,
}

impl Job {
    /// Loads pipeline.yaml's capture and selects frames (`frames` overrides the file's).
    pub fn load(config: Config, frames: Option<FrameRange>) -> Result<Job> {
        let sequence = Sequence::open_with_calibration(&config.calibration, &config.sequence)?;
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
                    return Err(Error::Usage(format!(
                        "frame range {}..{} is outside the sequence {} (frames {first}..{last})",
                        r.first,
                        r.last,
                        sequence.dir.display()
                    )));
                }
                selected
            }
        };
        let cache = Cache::new(&config.cache);
        Ok(Job {
            config,
            sequence,
            frames,
            cache,
        })
    }

    fn context(&self) -> Context<'_> {
        Context::new(&self.config, &self.sequence, &self.cache)
    }

    /// The reference frame t0 of the sequence's skeleton, if it has one.
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

    /// The frames a stage makes artifacts for in this job: the selected frames (and t0 when
    /// a reference stage needs it), or t0 alone for a reference stage; none when the
    /// sequence has no skeleton.
    fn stage_frames(&self, stage: &StageDef, reference: Option<u32>) -> Vec<u32> {
        match stage.scope {
            Scope::Reference => reference.into_iter().collect(),
            Scope::PerFrame => {
                let mut frames = self.frames.clone();
                if let Some(t0) = reference.filter(|t| !frames.contains(t)) {
                    frames.push(t0);
                    frames.sort_unstable();
                }
                frames
            }
        }
    }

    /// Cache keys of every stage for every frame it makes artifacts for.
    fn keys(&self, reference: Option<u32>) -> Result<HashMap<(&'static str, u32), String>> {
        let ctx = self.context();
        let mut keys: HashMap<(&'static str, u32), String> = HashMap::new();
        for stage in STAGES {
            let params = (stage.params)(&self.config);
            let per_frame: Vec<(u32, String)> = self
                .stage_frames(stage, reference)
                .par_iter()
                .map(|&f| -> Result<(u32, String)> {
                    let mut k = KeyBuilder::new();
                    k.add("stage", stage.name)
                        .add("format", &stage.format_version.to_string())
                        .add("params", &params);
                    for input in stage.inputs {
                        let upstream: &String = &keys[&(*input, f)];
                        k.add(input, upstream);
                    }
                    (stage.sources)(&ctx, f, &mut k)?;
                    Ok((f, k.finish()))
                })
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

fn bar(len: usize, stage: &str) -> ProgressBar {
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
    let _lock = job.cache.lock()?;
    job.cache.sweep_temporaries();
    let wants_reference = plan.iter().any(|(s, _)| s.scope == Scope::Reference);
    let reference = if wants_reference {
        job.reference_frame()?
    } else {
        None
    };
    let keys = job.keys(reference)?;
    let ctx = job.context();
    let mut reports = Vec::new();
    for (stage, forced) in plan {
        let start = Instant::now();
        let frames = job.stage_frames(stage, reference);
        if stage.scope == Scope::Reference && frames.is_empty() {
            reports.push(StageReport {
                stage: stage.name,
                computed: 0,
                reused: 0,
                seconds: 0.0,
                location: job.cache.stage_dir(stage.name),
                warnings: vec![format!(
                    "{}: the sequence has no skeleton.yaml, so there is no body model or motion",
                    stage.name
                )],
            });
            continue;
        }
        let todo: Vec<u32> = frames
            .iter()
            .copied()
            .filter(|&f| {
                forced
                    || job.cache.state(stage.name, f, &keys[&(stage.name, f)])
                        != ArtifactState::UpToDate
            })
            .collect();
        let progress = bar(todo.len(), stage.name);
        let warnings: Vec<Vec<String>> = todo
            .par_iter()
            .map(|&f| -> Result<Vec<String>> {
                let t = Instant::now();
                let out = (stage.compute)(&ctx, f)?;
                job.cache.commit(&Manifest {
                    stage: stage.name.to_string(),
                    frame: f,
                    key: keys[&(stage.name, f)].clone(),
                    format_version: stage.format_version,
                    files: out.files,
                    seconds: t.elapsed().as_secs_f64(),
                })?;
                progress.inc(1);
                Ok(out.warnings)
            })
            .collect::<Result<_>>()?;
        progress.finish_and_clear();
        reports.push(StageReport {
            stage: stage.name,
            computed: todo.len(),
            reused: frames.len() - todo.len(),
            seconds: start.elapsed().as_secs_f64(),
            location: job.cache.stage_dir(stage.name),
            warnings: warnings.into_iter().flatten().collect(),
        });
    }
    Ok(reports)
}

/// How many selected frames of each stage are up to date, stale or missing.
pub fn status(job: &Job) -> Result<Vec<StageStatus>> {
    let reference = job.reference_frame()?;
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
                    ArtifactState::Missing => st.missing += 1,
                }
            }
            st
        })
        .collect())
}
