//! The `pipeline` command: parses arguments, calls the library, prints errors well.

use clap::{Parser, Subcommand};
use hullpose::synth::{SceneKind, SynthOptions};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "pipeline",
    version,
    about = "hullpose: multi-view frames to visual hulls, refined surfaces and skeleton motion"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Write a synthetic capture with ground truth (calibration, frames, backgrounds, masks,
    /// skeleton, true joints and meshes) and a ready-to-run pipeline.yaml.
    Synth {
        /// Which scene to film.
        #[arg(long, value_enum)]
        scene: SceneKind,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Number of cameras on the ring.
        #[arg(long, default_value_t = 15)]
        cameras: usize,
        /// Image width, pixels.
        #[arg(long, default_value_t = 1024)]
        width: u32,
        /// Image height, pixels.
        #[arg(long, default_value_t = 768)]
        height: u32,
        /// Number of frames sampled over the motion (default: its key frames, 19 for the
        /// tripod, 24 for the humanoid).
        #[arg(long)]
        frames: Option<usize>,
        /// Random seed (camera jitter, pixel noise); the same seed gives the same bytes.
        #[arg(long, default_value_t = 0)]
        seed: u64,
    },
    /// Check a capture against its calibration and report what it holds.
    Check {
        /// The pipeline.yaml naming the calibration and the sequence.
        file: PathBuf,
    },
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Synth {
            scene,
            out,
            cameras,
            width,
            height,
            frames,
            seed,
        } => {
            let mut opts = SynthOptions::new(scene, out);
            opts.cameras = cameras;
            opts.width = width;
            opts.height = height;
            opts.frames = frames;
            opts.seed = seed;
            let s = hullpose::synth::generate(&opts)?;
            println!(
                "wrote {} frames from {} cameras ({} surface vertices) to {} in {:.1} s",
                s.frames,
                s.cameras,
                s.vertices,
                s.sequence_dir.display(),
                s.seconds
            );
            println!("run it with: pipeline run {}", s.pipeline_yaml.display());
        }
        Command::Check { file } => {
            let config = hullpose::config::Config::load(&file)?;
            let seq = hullpose::dataset::Sequence::open_with_calibration(
                &config.calibration,
                &config.sequence,
            )?;
            for w in &seq.warnings {
                eprintln!("warning: {w}");
            }
            let skeleton = seq.skeleton()?;
            let joints = seq.ground_truth_joints()?;
            println!(
                "{}: {} cameras, {} frames ({}..{}), masks: {}, background plates: {}, skeleton: {}, ground-truth joints: {}",
                seq.dir.display(),
                seq.cameras.len(),
                seq.frames.len(),
                seq.frames[0],
                seq.frames[seq.frames.len() - 1],
                if seq.has_masks { "yes" } else { "no" },
                if seq.has_backgrounds { "yes" } else { "no" },
                skeleton.map_or("no".to_string(), |s| format!("{} bones", s.bones.len())),
                joints.map_or("no".to_string(), |j| format!("{} rows", j.len())),
            );
        }
    }
    Ok(())
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
