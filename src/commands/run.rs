//! `pipeline run`: the cached stages (through [`crate::runner::run`]), then the exports
//! `export.formats` names, written from the cache for the job's frames.
//!
//! `export` is a step of this command, not a stage: it has no cache of its own. It may be
//! named in `--only`, `--from` and `--until` like a stage, after the last stage (`fit`).

use crate::error::{Error, Result};
use crate::runner::{Job, RunOptions, StageReport};
use crate::stages::STAGES;

/// The name `--only`, `--from` and `--until` give the export step.
pub const EXPORT: &str = "export";

/// Runs `opts`' stages, then the exports unless `--until` stops before them.
pub fn run(job: &Job, opts: &RunOptions) -> Result<Vec<StageReport>> {
    for name in [&opts.only, &opts.from, &opts.until].into_iter().flatten() {
        check_name(name)?;
    }
    let is_export = |o: &Option<String>| o.as_deref() == Some(EXPORT);
    let exports = match &opts.until {
        Some(until) => until == EXPORT,
        None => true,
    };
    if exports {
        crate::export::check_formats(job)?;
    }
    // `--only export` and `--from export` force nothing upstream: the stages the exports
    // read are computed when missing or stale, as for any stage's inputs.
    let stage_opts = RunOptions {
        only: opts.only.clone().filter(|_| !is_export(&opts.only)),
        from: opts.from.clone().filter(|_| !is_export(&opts.from)),
        until: opts.until.clone().filter(|_| !is_export(&opts.until)),
        force: opts.force,
    };
    if stage_opts.only.is_some() && opts.until.is_none() {
        // `--only STAGE` stops at that stage.
        return crate::runner::run(job, &stage_opts);
    }
    let mut reports = crate::runner::run(job, &stage_opts)?;
    if exports {
        let start = std::time::Instant::now();
        let written = crate::export::run(&job.context(), &job.frames, &job.config.export.formats)?;
        reports.push(StageReport {
            stage: EXPORT,
            computed: written.files,
            reused: 0,
            seconds: start.elapsed().as_secs_f64(),
            location: job.config.output.clone(),
            warnings: written.warnings,
            outputs: written.outputs,
        });
    }
    Ok(reports)
}

/// Refuses a name that is neither a stage nor `export`, listing both.
fn check_name(name: &str) -> Result<()> {
    if name == EXPORT || STAGES.iter().any(|s| s.name == name) {
        return Ok(());
    }
    let names: Vec<&str> = STAGES.iter().map(|s| s.name).chain([EXPORT]).collect();
    Err(Error::Usage(format!(
        "there is no stage '{name}'; the stages are: {}",
        names.join(", ")
    )))
}
