//! `pipeline evaluate`: joint errors against the ground truth, the fit's health, and the
//! reconstructions against the true surfaces (or, without ground truth, against the
//! silhouettes and the images); tables on stdout and CSV files in `output/evaluation/`.

use crate::error::Result;
use crate::runner::Job;

/// Evaluates the job's cached results and outputs.
pub fn evaluate(job: &Job) -> Result<()> {
    evaluate_pose(job)?;
    evaluate_health(job)?;
    evaluate_tracked_silhouettes(job)?;
    if !job
        .frames
        .iter()
        .any(|&f| job.sequence.ground_truth_mesh_path(f).exists())
    {
        // No ground truth (real captures): how well the reconstructions explain the
        // silhouettes and the images.
        let (report, csv) = crate::eval::without_ground_truth(job)?;
        println!(
            "no ground truth: silhouette coverage and photo-consistency of the reconstructions"
        );
        print!("{report}");
        let path = job.config.output.join("evaluation").join("coverage.csv");
        crate::fsutil::write_atomic(&path, csv.as_bytes())?;
        println!("written to {}", path.display());
        return Ok(());
    }
    let rows = crate::eval::reconstruction(job)?;
    print!("{}", crate::eval::reconstruction_table(&rows));
    let csv = job
        .config
        .output
        .join("evaluation")
        .join("reconstruction.csv");
    crate::fsutil::write_atomic(&csv, crate::eval::reconstruction_csv(&rows).as_bytes())?;
    println!("written to {}", csv.display());
    let tracked = crate::eval::tracked::rows(job)?;
    if !tracked.is_empty() {
        println!("\nthe posed model and the tracked surface against the truth");
        print!("{}", crate::eval::tracked::table(&tracked));
        let path = job.config.output.join("evaluation").join("surface.csv");
        crate::fsutil::write_atomic(&path, crate::eval::tracked::to_csv(&tracked).as_bytes())?;
        println!("written to {}", path.display());
    }
    let rel = crate::eval::reliability::evaluate(job)?;
    if !rel.is_empty() {
        println!("\nreliability: ZNCC of true (<= 1 voxel) and false (> 2 voxels) vertices");
        print!("{}", crate::eval::reliability::table(&rel));
        let path = job.config.output.join("evaluation").join("reliability.csv");
        crate::fsutil::write_atomic(&path, crate::eval::reliability::to_csv(&rel).as_bytes())?;
        println!("written to {}", path.display());
    }
    Ok(())
}

/// `evaluate --holdout CAM`: the job rebuilt without the camera and scored in it
/// ([`crate::eval::holdout`]); a table and `output/evaluation/holdout_<CAM>.csv`.
pub fn evaluate_holdout(job: &Job, camera: &str) -> Result<()> {
    let rows = crate::eval::holdout::evaluate(job, camera)?;
    print!("{}", crate::eval::holdout::table(camera, &rows));
    let path = job
        .config
        .output
        .join("evaluation")
        .join(format!("holdout_{camera}.csv"));
    crate::fsutil::write_atomic(&path, crate::eval::holdout::to_csv(&rows).as_bytes())?;
    println!("written to {}", path.display());
    Ok(())
}

/// The tracked surface's part of `evaluate` that needs no truth: its worst silhouette IoU
/// per frame beside the graph cut's and the posed model's.
fn evaluate_tracked_silhouettes(job: &Job) -> Result<()> {
    let rows = crate::eval::tracked::silhouette_rows(job)?;
    if rows.is_empty() {
        return Ok(());
    }
    println!("the tracked surface against the silhouettes (full resolution)");
    print!("{}", crate::eval::tracked::silhouette_table(&rows));
    let path = job
        .config
        .output
        .join("evaluation")
        .join("surface_silhouettes.csv");
    crate::fsutil::write_atomic(
        &path,
        crate::eval::tracked::silhouette_csv(&rows).as_bytes(),
    )?;
    println!("written to {}\n", path.display());
    Ok(())
}

/// The health part of `evaluate`: fit.csv's silhouette IoU and joint motion per frame, a
/// table and a plot, with or without ground truth.
fn evaluate_health(job: &Job) -> Result<()> {
    let rows: Vec<_> = crate::eval::health_table::read(&job.config.output)?
        .into_iter()
        .filter(|r| job.frames.contains(&r.frame))
        .collect();
    if rows.is_empty() {
        return Ok(());
    }
    println!("fit health: the posed model's silhouette IoU per camera, and joint motion");
    print!("{}", crate::eval::health_table::table(&rows));
    let dir = job.config.output.join("evaluation");
    let path = crate::eval::health_table::write_plot(&dir, &rows)?;
    println!("written to {}\n", path.display());
    Ok(())
}

/// The pose part of `evaluate`: joint errors of the run's joints.csv against the ground
/// truth, when both exist.
fn evaluate_pose(job: &Job) -> Result<()> {
    let estimate_path = job.config.output.join("joints.csv");
    let Some(truth) = job.sequence.ground_truth_joints()? else {
        return Ok(());
    };
    if !estimate_path.is_file() {
        println!(
            "no {} yet: run the pipeline through the fit stage to evaluate poses",
            estimate_path.display()
        );
        return Ok(());
    }
    let estimate: Vec<_> = crate::joints::read(&estimate_path)?
        .into_iter()
        .filter(|r| job.frames.contains(&r.frame))
        .collect();
    let truth_path = job.sequence.dir.join("ground_truth/joints.csv");
    let errors = vec![(
        job.config.fit.method.name().to_string(),
        crate::eval::pose::joint_errors(&truth, &estimate, &truth_path)?,
    )];
    println!("poses: mean joint error of {}", estimate_path.display());
    print!("{}", crate::eval::pose::table(&errors));
    let dir = job.config.output.join("evaluation");
    for f in crate::eval::pose::write(&dir, "joint_error", &errors, "mean joint error")? {
        println!("written to {}", f.display());
    }
    println!();
    Ok(())
}
