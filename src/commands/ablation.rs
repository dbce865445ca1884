//! `pipeline ablation`: every fitting method (the proposed one and the paper's baselines)
//! over the cached reconstruction, each method's joints written and, with ground truth,
//! compared.

use crate::error::{Error, Result};
use crate::runner::{Job, RunOptions};

/// `pipeline ablation`: every method over the cached reconstruction.
pub fn ablation(job: &Job) -> Result<()> {
    use crate::fit::Method;
    let start = std::time::Instant::now();
    let opts = RunOptions {
        until: Some("model".into()),
        ..Default::default()
    };
    let reports = crate::runner::run(job, &opts)?;
    let (computed, reused) = reports
        .iter()
        .fold((0, 0), |a, r| (a.0 + r.computed, a.1 + r.reused));
    println!("reconstruction and model: {computed} computed, {reused} reused");
    let tracked = job.tracked_frames()?;
    if tracked.is_empty() {
        return Err(Error::Usage(format!(
            "{} has no skeleton.yaml: there is nothing to fit",
            job.sequence.dir.display()
        )));
    }
    let ctx = job.context();
    let truth = job.sequence.ground_truth_joints()?;
    let truth_path = job.sequence.dir.join("ground_truth/joints.csv");
    let dir = job.config.output.join("ablation");
    let model = crate::artifacts::body_model::read(&job.cache)?;
    let mut errors = Vec::new();
    for method in Method::ALL {
        let t = std::time::Instant::now();
        let params = crate::fit::FitParams {
            method,
            ..job.config.fit.clone()
        };
        let bar = crate::runner::bar(tracked.len(), method.name());
        let results =
            crate::stages::fit::track_in_memory(&ctx, &tracked, &params, &|_| bar.inc(1))?.results;
        bar.finish_and_clear();
        let rows: Vec<_> = results
            .iter()
            .flat_map(|(f, r)| crate::stages::fit::joint_rows(&model.skeleton, *f, &r.pose))
            .collect();
        let path = dir.join(method.name()).join("joints.csv");
        crate::joints::write(&path, &rows)?;
        println!(
            "{:>9}: {} frames in {:.1} s -> {}",
            method.name(),
            results.len(),
            t.elapsed().as_secs_f64(),
            path.display()
        );
        if let Some(truth) = &truth {
            let selected: Vec<_> = rows
                .into_iter()
                .filter(|r| job.frames.contains(&r.frame))
                .collect();
            errors.push((
                method.name().to_string(),
                crate::eval::pose::joint_errors(truth, &selected, &truth_path)?,
            ));
        }
    }
    if errors.is_empty() {
        println!("no ground_truth/joints.csv: joints written, nothing to compare");
    } else {
        print!("{}", crate::eval::pose::table(&errors));
        for f in
            crate::eval::pose::write(&dir, "joint_error", &errors, "mean joint error per method")?
        {
            println!("written to {}", f.display());
        }
    }
    println!("done in {:.1} s", start.elapsed().as_secs_f64());
    Ok(())
}
