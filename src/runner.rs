//! The runner: the only orchestrator. It decides which stages and frames are stale, computes
//! them in parallel over frames, writes artifacts atomically with their manifests, shows
//! progress, and reports what it computed and reused.

use crate::cache::{ArtifactState, Cache, KeyBuilder, Manifest};
use crate::config::{Config, FrameRange};
use crate::dataset::Sequence;
use crate::error::{Error, Result};
use crate::stages::{self, Context, StageDef, STAGES};
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

    /// Cache keys of every stage for every selected frame.
    fn keys(&self) -> Result<HashMap<(&'static str, u32), String>> {
        let ctx = self.context();
        let mut keys: HashMap<(&'static str, u32), String> = HashMap::new();
        for stage in STAGES {
            let params = (stage.params)(&self.config);
            let per_frame: Vec<(u32, String)> = self
                .frames
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
    let keys = job.keys()?;
    let ctx = job.context();
    let mut reports = Vec::new();
    for (stage, forced) in plan {
        let start = Instant::now();
        let todo: Vec<u32> = job
            .frames
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
            reused: job.frames.len() - todo.len(),
            seconds: start.elapsed().as_secs_f64(),
            location: job.cache.stage_dir(stage.name),
            warnings: warnings.into_iter().flatten().collect(),
        });
    }
    Ok(reports)
}

/// How many selected frames of each stage are up to date, stale or missing.
pub fn status(job: &Job) -> Result<Vec<StageStatus>> {
    let keys = job.keys()?;
    Ok(STAGES
        .iter()
        .map(|s| {
            let mut st = StageStatus {
                stage: s.name,
                up_to_date: 0,
                stale: 0,
                missing: 0,
            };
            for &f in &job.frames {
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
