//! The `pipeline` command: parses arguments, calls the library, prints errors well.

use clap::{Parser, Subcommand};
use hullpose::config::{Config, FrameRange};
use hullpose::runner::{Job, RunOptions};
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
        /// tripod, 24 for the humanoid and its walk, 39 for its dance).
        #[arg(long)]
        frames: Option<usize>,
        /// Random seed (camera jitter, pixel noise); the same seed gives the same bytes.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Grid spacing of the subject's true surface, metres (smaller: finer true meshes).
        #[arg(long, default_value_t = 0.01)]
        mesh_spacing: f64,
        /// The humanoid's motion: `default`, `dance` (fast arms crossing, a leg crossing
        /// step and a 120-degree turn at 25 frames per second, 39 frames), `arms-down` (ten
        /// frames with the arms at the sides first) or `walk` (once around a 1 m circle,
        /// through every camera's view: for `silhouette.method: learned`).
        #[arg(long, value_enum, default_value = "default")]
        motion: hullpose::synth::Motion,
        /// The humanoid's body: 0 the standard 1.8 m body, any other number a body drawn
        /// from it (height within 15%, legs, torso, arms and width each within 7% more).
        #[arg(long, default_value_t = 0)]
        body: u64,
        /// The humanoid wears a dress: a skirt from the waist to above the knees that fuses
        /// the thighs into one volume and swings with the legs (`--dress` or `--dress
        /// fitted`); `--dress loose`: its hem also swings after the body as a damped
        /// pendulum, a shape no skinning of the pose gives.
        #[arg(long, value_enum, num_args = 0..=1, default_missing_value = "fitted")]
        dress: Option<hullpose::synth::Dress>,
        /// What the humanoid wears: `costume` (a saturated noise pattern everywhere but
        /// plain trousers) or `person` (skin, hair, a red shirt, trousers, white shoes: a
        /// look a person model recognizes).
        #[arg(long, value_enum, default_value = "costume")]
        look: hullpose::synth::Look,
        /// The humanoid holds one pose in every frame instead of a motion (one frame unless
        /// --frames says more): `a-pose`, `t-pose`, `arms-down`, `arms-out-bent` (upper arms
        /// out, elbows bent, fists down), `arms-overhead`, `one-arm-forward`, `hands-on-hips`.
        #[arg(long, value_enum)]
        pose: Option<hullpose::synth::humanoid::HeldPose>,
        /// Tilt the written world by this many degrees (and move its origin): the
        /// calibration and the truth are turned together, the images are the same, and
        /// nothing but ground_truth/world.yaml says where up is.
        #[arg(long, value_name = "DEG", default_value_t = 0.0)]
        world_tilt: f64,
        /// With `--scene meshes`: the folder of the mesh sequence to film (OBJ or PLY, one
        /// file per frame, a frame number in each name, one topology, metres).
        #[arg(long, value_name = "DIR")]
        meshes: Option<PathBuf>,
        /// The mesh sequence's up axis (`+x` ... `-z`).
        #[arg(long, value_name = "AXIS", default_value = "+y", value_parser = parse_axis)]
        mesh_up: hullpose::geometry::axes::UpAxis,
    },
    /// Run the pipeline: compute what is stale, reuse what the cache holds.
    Run {
        /// The pipeline.yaml to run.
        file: PathBuf,
        /// Re-run only this stage (computing missing inputs first).
        #[arg(long, value_name = "STAGE")]
        only: Option<String>,
        /// Re-run this stage and every stage downstream of it.
        #[arg(long, value_name = "STAGE")]
        from: Option<String>,
        /// Run the stages up to this one only (e.g. the per-frame stages of a shard).
        #[arg(long, value_name = "STAGE")]
        until: Option<String>,
        /// Frames to process, A..B inclusive (overrides pipeline.yaml).
        #[arg(long, value_name = "A..B", value_parser = parse_range)]
        frames: Option<FrameRange>,
        /// Recompute everything selected, ignoring the cache.
        #[arg(long)]
        force: bool,
    },
    /// Show, per stage, how many frames are up to date, stale or missing in the cache.
    Status {
        /// The pipeline.yaml.
        file: PathBuf,
        /// Frames to consider, A..B inclusive (overrides pipeline.yaml).
        #[arg(long, value_name = "A..B", value_parser = parse_range)]
        frames: Option<FrameRange>,
    },
    /// Compare cached results with the capture's ground truth: reconstruction accuracy
    /// and completeness per frame and stage, and joint errors (tables, CSVs under the output
    /// folder). Without ground truth: each view's silhouette coverage and IoU and the mean
    /// ZNCC per reconstruction stage (coverage.csv).
    Evaluate {
        /// The pipeline.yaml.
        file: PathBuf,
        /// Frames to evaluate, A..B inclusive (overrides pipeline.yaml).
        #[arg(long, value_name = "A..B", value_parser = parse_range)]
        frames: Option<FrameRange>,
        /// Instead: rebuild, fit and track the frames without this camera (cache and
        /// output under holdout/CAM/) and score each surface's silhouette IoU in it.
        #[arg(long, value_name = "CAM")]
        holdout: Option<String>,
    },
    /// Whether a fitted frame's pose is wrong: from the cached fit, search for a pose whose
    /// model explains the frame's silhouettes better (a higher worst-camera IoU, fit.csv's
    /// measure); prints each camera's IoU before and after and the joints that moved.
    /// Nothing is written.
    PoseSearch {
        /// The pipeline.yaml.
        file: PathBuf,
        /// The fitted frame to search from.
        #[arg(long)]
        frame: u32,
        /// At most this many poses tried (about 20 ms each on an 8-camera capture).
        #[arg(long, default_value_t = 2000, value_parser = count::<1, 1_000_000>)]
        tries: usize,
    },
    /// Run every fitting method (icp, normals, rho_c, rho_p, proposed) on one sequence over
    /// the cached reconstruction, and compare their joint errors (the paper's Fig. 8): a
    /// table, and joints, a CSV and a PNG plot under <output>/ablation/.
    Ablation {
        /// The pipeline.yaml.
        file: PathBuf,
        /// Frames, A..B inclusive (overrides pipeline.yaml); tracking starts at t0.
        #[arg(long, value_name = "A..B", value_parser = parse_range)]
        frames: Option<FrameRange>,
    },
    /// Write exports from the cache without recomputing anything: glb (skinned model and
    /// motion), bvh (motion), ply / obj (every reconstruction's meshes), overlay (skeleton on
    /// the frames, contact sheets). Under <output>/export/.
    Export {
        /// The pipeline.yaml.
        file: PathBuf,
        /// Formats to write (repeat or comma-separate; default: export.formats).
        #[arg(long, value_enum, value_delimiter = ',')]
        format: Vec<hullpose::config::Format>,
        /// Frames, A..B inclusive (overrides pipeline.yaml).
        #[arg(long, value_name = "A..B", value_parser = parse_range)]
        frames: Option<FrameRange>,
    },
    /// Write an HTML report of a run, <output>/report/index.html: the fitted model playing
    /// its motion in a 3D view with the surfaces and the skeleton, a frame slider with the
    /// overlays, the fit's health as plots, the parameters and the evaluation's tables.
    /// Opens from the file system, no server or network needed
    Report {
        /// The pipeline.yaml (after `pipeline run`).
        file: PathBuf,
        /// Frames, A..B inclusive (overrides pipeline.yaml).
        #[arg(long, value_name = "A..B", value_parser = parse_range)]
        frames: Option<FrameRange>,
    },
    /// Write a Slurm batch plan for a frame-sharded run: an array job running the per-frame
    /// stages on slices of the frames, and a job after it running the model, the fit and the
    /// exports from the shared cache. Prints the scripts; `--submit` submits them.
    Slurm {
        /// The pipeline.yaml (its cache must be on a filesystem every node shares).
        file: PathBuf,
        /// Number of array tasks (frame slices).
        #[arg(long, default_value_t = 4)]
        shards: usize,
        /// Slurm partition (default: the cluster's default partition).
        #[arg(long)]
        partition: Option<String>,
        /// Time limit per job, Slurm's format.
        #[arg(long, default_value = "04:00:00")]
        time: String,
        /// CPUs per task (threads per run).
        #[arg(long, default_value_t = 2)]
        cpus: usize,
        /// Memory per task in MB (default: an estimate from the image sizes).
        #[arg(long, value_name = "MB")]
        mem: Option<u64>,
        /// Frames, A..B inclusive (overrides pipeline.yaml).
        #[arg(long, value_name = "A..B", value_parser = parse_range)]
        frames: Option<FrameRange>,
        /// Submit with sbatch and print the job ids.
        #[arg(long)]
        submit: bool,
    },
    /// Time the inner steps of a stage (benchmarks; nothing is written).
    Bench {
        #[command(subcommand)]
        what: BenchWhat,
    },
    /// Render a frame's cached reconstruction through one camera beside the input frame
    /// (silhouette outline in green; silhouette the mesh misses in red).
    Render {
        /// The pipeline.yaml.
        file: PathBuf,
        /// The frame.
        #[arg(long, default_value_t = 0)]
        frame: u32,
        /// The camera name (default: the first camera).
        #[arg(long)]
        camera: Option<String>,
        /// Which reconstruction: visual_hull or graphcut.
        #[arg(long, default_value = "visual_hull")]
        stage: String,
        /// Output PNG.
        #[arg(long)]
        out: PathBuf,
    },
    /// Convert another tool's calibration to calib/cameras.yaml: OpenCV FileStorage
    /// (`--from opencv INTRI EXTRI`, e.g. intri.yml extri.yml) or a COLMAP text model
    /// (`--from colmap DIR` holding cameras.txt and images.txt).
    ImportCalib {
        /// The source format.
        #[arg(long, value_enum)]
        from: CalibSource,
        /// opencv: INTRI EXTRI; colmap: DIR; pose2sim: Calib.toml; qualisys: FILE.qca.txt.
        #[arg(required = true, num_args = 1..=2)]
        paths: Vec<PathBuf>,
        /// pose2sim: the unit of the file's translations (Pose2Sim writes metres; anipose
        /// its calibration board's unit).
        #[arg(long, value_enum, default_value = "m")]
        units: LengthUnit,
        /// Where to write cameras.yaml.
        #[arg(long, default_value = "calib/cameras.yaml")]
        out: PathBuf,
        /// Image size WIDTHxHEIGHT for OpenCV cameras without W_<name> / H_<name>.
        #[arg(long, value_parser = hullpose::calib_import::parse_size)]
        size: Option<(u32, u32)>,
        /// Replace an existing file at --out.
        #[arg(long)]
        force: bool,
    },
    /// Check a capture against its calibration, with every check `run` makes before its
    /// first stage, and report what it holds.
    Check {
        /// The pipeline.yaml naming the calibration and the sequence.
        file: PathBuf,
    },
    /// Make the sequence's skeleton.yaml: reconstruct the reference frame and embed a
    /// template skeleton in its surface (bones along the medial axis, the template's
    /// proportions). Writes output/skeleton/bones.ply and output/skeleton/overlay.png to
    /// check it. The world's up is world.up (or export.up_axis), else found from the cameras.
    Skeleton {
        /// The pipeline.yaml naming the calibration and the sequence.
        file: PathBuf,
        /// `humanoid` (the built-in 17-bone body) or a skeleton.yaml to use as a template
        /// (its bones, names and proportions; its size and place do not matter).
        #[arg(long, default_value = "humanoid")]
        template: String,
        /// The reference frame. Default: up to 12 frames spread over pipeline.yaml's range are
        /// examined (only they are reconstructed), and the best embedding is written.
        #[arg(long)]
        frame: Option<u32>,
        /// Replace an existing skeleton.yaml.
        #[arg(long)]
        force: bool,
    },
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum CalibSource {
    /// OpenCV FileStorage YAML: intri.yml and extri.yml.
    Opencv,
    /// COLMAP text model: a folder with cameras.txt and images.txt.
    Colmap,
    /// Pose2Sim or anipose calibration TOML (Calib.toml); see --units.
    #[value(alias = "anipose", alias = "toml")]
    Pose2sim,
    /// Qualisys Track Manager calibration (.qca.txt), its video cameras.
    #[value(alias = "qca")]
    Qualisys,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum LengthUnit {
    /// Metres (Pose2Sim).
    M,
    /// Centimetres.
    Cm,
    /// Millimetres (anipose with a board measured in mm).
    Mm,
}

impl LengthUnit {
    fn metres(self) -> f64 {
        match self {
            LengthUnit::M => 1.0,
            LengthUnit::Cm => 0.01,
            LengthUnit::Mm => 0.001,
        }
    }
}

#[derive(Subcommand)]
enum BenchWhat {
    /// The visual hull's steps on one frame (needs the frame's silhouettes in the cache).
    VisualHull {
        file: PathBuf,
        #[arg(long, default_value_t = 0)]
        frame: u32,
        /// Repetitions; the best time is reported.
        #[arg(long, default_value_t = 3, value_parser = count::<1, 1000>)]
        repeat: usize,
        /// Carve a fixed N^3 grid (voxel_size from pipeline.yaml) centred on the derived box.
        #[arg(long, value_parser = count::<1, 1024>)]
        cube: Option<usize>,
    },
    /// The graph cut's steps on one frame (needs the frame's hull in the cache).
    Graphcut {
        file: PathBuf,
        #[arg(long, default_value_t = 0)]
        frame: u32,
    },
    /// The person model on one frame's images (silhouette method `person`): model loading,
    /// then per image the detector alone and the whole (detector, landmarks, full-size mask),
    /// on one thread, then every camera's image on all threads.
    Person {
        file: PathBuf,
        #[arg(long, default_value_t = 0)]
        frame: u32,
        /// Repetitions; the best time is reported.
        #[arg(long, default_value_t = 3, value_parser = count::<1, 1000>)]
        repeat: usize,
    },
    /// The max-flow solver on the reference fixture graph of size N^3.
    Maxflow {
        #[arg(long, default_value_t = 64, value_parser = count::<2, 256>)]
        size: usize,
    },
    /// The reliability stage's steps on one frame (needs the frame's refined surface in the
    /// cache); `--dump-patches` also writes normalized-free raw patch pairs for a comparison.
    Reliability {
        file: PathBuf,
        #[arg(long, default_value_t = 0)]
        frame: u32,
        /// Write PAIRS patch pairs (f32, window^2 values each) to this file and time the
        /// crate's ZNCC on them.
        #[arg(long)]
        dump_patches: Option<PathBuf>,
        #[arg(long, default_value_t = 200_000, value_parser = count::<1, 100_000_000>)]
        pairs: usize,
    },
    /// The fit's steps on one frame (needs the model and the frame's reliability in the
    /// cache): vertex counts and milliseconds per round of each step.
    Fit {
        file: PathBuf,
        #[arg(long, default_value_t = 1)]
        frame: u32,
        /// Override fit.sample_spacing and fit.model_spacing (metres; 0 keeps every vertex).
        #[arg(long)]
        spacing: Option<f64>,
    },
    /// The fit stage's tracking over the configured frames, in memory (needs the model and
    /// every frame's reliability in the cache; nothing is written but `--joints`): seconds,
    /// rounds, (with ground truth) mean joint error and residual per frame, and milliseconds
    /// per round of each step; the same results as `pipeline run`.
    Track {
        file: PathBuf,
        /// Override fit.method.
        #[arg(long)]
        method: Option<String>,
        /// Also write the tracked joints here (the joints.csv schema).
        #[arg(long)]
        joints: Option<PathBuf>,
        /// Also write every round of every frame's fit here (CSV: its largest joint motion,
        /// eq. 4 and, with ground truth, the mean joint error after it): how much each round
        /// buys, for tuning fit.stop.tolerance and fit.stop.max_rounds.
        #[arg(long)]
        rounds: Option<PathBuf>,
    },
    /// k-d tree nearest-neighbour queries per second (compare tools/bench_fit.py), and the
    /// fit's bounded two-nearest search by the k-d tree and by the cell grid side by side
    Nearest {
        #[arg(long, default_value_t = 100_000, value_parser = count::<1, 100_000_000>)]
        points: usize,
        #[arg(long, default_value_t = 1_000_000, value_parser = count::<1, 1_000_000_000>)]
        queries: usize,
    },
    /// Iso-surface extraction of a sphere on an N^3 grid.
    Meshing {
        #[arg(long, default_value_t = 256, value_parser = count::<2, 1024>)]
        size: usize,
        #[arg(long, default_value_t = 3, value_parser = count::<1, 1000>)]
        repeat: usize,
    },
}

/// A count from `MIN` to `MAX` (bench sizes: beyond them a run would exhaust memory).
fn count<const MIN: usize, const MAX: usize>(s: &str) -> Result<usize, hullpose::error::Refusal> {
    let n: usize = s
        .trim()
        .parse()
        .map_err(|_| format!("'{s}' is not a whole number"))?;
    if !(MIN..=MAX).contains(&n) {
        return Err(format!("{n} is outside {MIN}..={MAX}").into());
    }
    Ok(n)
}

fn parse_axis(s: &str) -> Result<hullpose::geometry::axes::UpAxis, String> {
    hullpose::geometry::axes::UpAxis::try_from(s.to_string()).map_err(|e| e.0)
}

fn parse_range(s: &str) -> Result<FrameRange, hullpose::error::Refusal> {
    FrameRange::parse(s)
}

fn run(cli: Cli) -> hullpose::Result<()> {
    match cli.command {
        Command::Run {
            file,
            only,
            from,
            until,
            frames,
            force,
        } => {
            let start = std::time::Instant::now();
            let job = Job::load(Config::load(&file)?, frames)?;
            for w in &job.sequence.warnings {
                eprintln!("warning: {}", hullpose::text::escape_controls(w));
            }
            for line in job.sequence.video_report() {
                println!("      videos: {line}");
            }
            if let Some(line) = &job.learning {
                println!("  silhouette: {line}");
            }
            let opts = RunOptions {
                only,
                from,
                until,
                force,
            };
            let reports = hullpose::commands::run::run(&job, &opts)?;
            let (mut computed, mut reused) = (0, 0);
            for r in &reports {
                println!(
                    "{:>12}: {} computed, {} reused, {:.1} s -> {}",
                    r.stage,
                    r.computed,
                    r.reused,
                    r.seconds,
                    r.location.display()
                );
                for w in &r.warnings {
                    eprintln!("warning: {}", hullpose::text::escape_controls(w));
                }
                for o in &r.outputs {
                    println!("{:>12}  wrote {}", "", o.display());
                }
                computed += r.computed;
                reused += r.reused;
            }
            println!(
                "done: {computed} artifacts computed, {reused} reused, {} frames, {:.1} s; cache in {}, outputs in {}",
                job.frames.len(),
                start.elapsed().as_secs_f64(),
                job.cache.root.display(),
                job.config.output.display()
            );
        }
        Command::Export {
            file,
            format,
            frames,
        } => {
            let start = std::time::Instant::now();
            let job = Job::load(Config::load(&file)?, frames)?;
            let formats = if format.is_empty() {
                job.config.export.formats.clone()
            } else {
                format
            };
            let written = hullpose::export::from_cache(&job, &formats)?;
            for w in &written.warnings {
                eprintln!("warning: {}", hullpose::text::escape_controls(w));
            }
            for o in &written.outputs {
                println!("wrote {}", o.display());
            }
            println!(
                "done: {} files from the cache in {:.1} s",
                written.files,
                start.elapsed().as_secs_f64()
            );
        }
        Command::Report { file, frames } => {
            let start = std::time::Instant::now();
            let job = Job::load(Config::load(&file)?, frames)?;
            let written = hullpose::report::write(&job)?;
            println!(
                "wrote {} ({} frames, surfaces of {}, {:.1} MB) in {:.1} s; open it in a browser",
                written.path.display(),
                written.frames,
                written.surface_frames,
                written.bytes as f64 / 1e6,
                start.elapsed().as_secs_f64()
            );
        }
        Command::Slurm {
            file,
            shards,
            partition,
            time,
            cpus,
            mem,
            frames,
            submit,
        } => {
            let job = Job::load(Config::load(&file)?, frames)?;
            let opts = hullpose::slurm::SlurmOptions {
                shards,
                partition,
                time,
                cpus,
                mem_mb: mem,
                program: std::env::current_exe().map_err(|e| {
                    hullpose::Error::Usage(format!("cannot find this program's own path: {e}"))
                })?,
            };
            let plan = hullpose::slurm::plan(&job, &opts)?;
            let (array, last) = hullpose::slurm::write(&plan)?;
            if submit {
                let (a, b) = hullpose::slurm::submit(&array, &last)?;
                println!(
                    "submitted array job {a} ({} tasks, {} MB each) and job {b} (model, fit, exports; {} MB) after it",
                    plan.shards.len(),
                    plan.shard_mem_mb,
                    plan.final_mem_mb
                );
                println!(
                    "watch with: squeue -j {a},{b}; logs in {}",
                    plan.dir.display()
                );
            } else {
                println!(
                    "# {}
{}",
                    array.display(),
                    plan.array_script
                );
                println!(
                    "# {}
{}",
                    last.display(),
                    plan.final_script
                );
                let q = |p: &std::path::Path| hullpose::shell::quote(&p.display().to_string());
                println!(
                    "# submit with: jobid=$(sbatch --parsable {}) && sbatch --dependency=afterok:\"$jobid\" {}",
                    q(&array),
                    q(&last)
                );
                println!("# or run: pipeline slurm {} --submit", q(&file));
            }
        }
        Command::Ablation { file, frames } => {
            let job = Job::load(Config::load(&file)?, frames)?;
            hullpose::commands::ablation::ablation(&job)?;
        }
        Command::Evaluate {
            file,
            frames,
            holdout,
        } => {
            let job = Job::load(Config::load(&file)?, frames)?;
            match holdout {
                Some(camera) => hullpose::commands::evaluate::evaluate_holdout(&job, &camera)?,
                None => hullpose::commands::evaluate::evaluate(&job)?,
            }
        }
        Command::PoseSearch { file, frame, tries } => {
            let job = Job::load(Config::load(&file)?, Some(FrameRange::single(frame)))?;
            print!(
                "{}",
                hullpose::eval::pose_search::report(&job, frame, tries)?
            );
        }
        Command::Bench { what } => match what {
            BenchWhat::VisualHull {
                file,
                frame,
                repeat,
                cube,
            } => {
                let job = Job::load(Config::load(&file)?, Some(FrameRange::single(frame)))?;
                print!(
                    "{}",
                    hullpose::bench::visual_hull(&job, frame, repeat, cube)?
                );
            }
            BenchWhat::Graphcut { file, frame } => {
                let job = Job::load(Config::load(&file)?, Some(FrameRange::single(frame)))?;
                print!("{}", hullpose::bench::graphcut(&job, frame)?);
            }
            BenchWhat::Reliability {
                file,
                frame,
                dump_patches,
                pairs,
            } => {
                let job = Job::load(Config::load(&file)?, Some(FrameRange::single(frame)))?;
                print!(
                    "{}",
                    hullpose::bench::reliability(&job, frame, dump_patches.as_deref(), pairs)?
                );
            }
            BenchWhat::Fit {
                file,
                frame,
                spacing,
            } => {
                let job = Job::load(Config::load(&file)?, Some(FrameRange::single(frame)))?;
                print!("{}", hullpose::bench::fit(&job, frame, spacing)?);
            }
            BenchWhat::Track {
                file,
                method,
                joints,
                rounds,
            } => {
                let job = Job::load(Config::load(&file)?, None)?;
                print!(
                    "{}",
                    hullpose::bench::track(
                        &job,
                        method.as_deref(),
                        joints.as_deref(),
                        rounds.as_deref()
                    )?
                );
            }
            BenchWhat::Nearest { points, queries } => {
                print!("{}", hullpose::bench::nearest(points, queries))
            }
            BenchWhat::Person {
                file,
                frame,
                repeat,
            } => {
                let job = Job::load(Config::load(&file)?, Some(FrameRange::single(frame)))?;
                print!("{}", hullpose::bench::person(&job, frame, repeat)?);
            }
            BenchWhat::Maxflow { size } => print!("{}", hullpose::bench::maxflow_fixture(size)),
            BenchWhat::Meshing { size, repeat } => {
                print!("{}", hullpose::bench::meshing(size, repeat))
            }
        },
        Command::Render {
            file,
            frame,
            camera,
            stage,
            out,
        } => {
            let config = Config::load(&file)?;
            config.check_output_file("--out", &out)?;
            let job = Job::load(config, Some(FrameRange::single(frame)))?;
            let img = hullpose::drawing::hull_beside_frame(&job, &stage, frame, camera.as_deref())?;
            hullpose::imageio::write_rgb(&out, &img)?;
            println!("wrote {}", out.display());
        }
        Command::Status { file, frames } => {
            // Read-only: decodes nothing, learns nothing, writes nothing.
            let job = Job::load_read_only(Config::load(&file)?, frames)?;
            for note in &job.pending {
                println!("note: {note}; every stage counts as missing");
            }
            println!(
                "{:>12}  {:>10}  {:>6}  {:>7}",
                "stage", "up to date", "stale", "missing"
            );
            for s in hullpose::runner::status(&job)? {
                println!(
                    "{:>12}  {:>10}  {:>6}  {:>7}",
                    s.stage, s.up_to_date, s.stale, s.missing
                );
            }
        }
        Command::Synth {
            scene,
            out,
            cameras,
            width,
            height,
            frames,
            seed,
            mesh_spacing,
            motion,
            body,
            dress,
            look,
            pose,
            world_tilt,
            meshes,
            mesh_up,
        } => {
            let mut opts = SynthOptions::new(scene, out);
            opts.meshes = meshes;
            opts.mesh_up = mesh_up;
            opts.motion = motion;
            opts.dress = dress;
            opts.look = look;
            opts.pose = pose;
            opts.world_tilt_deg = world_tilt;
            if body != 0 {
                opts.proportions = hullpose::synth::humanoid::Proportions::from_seed(body);
            }
            opts.cameras = cameras;
            opts.width = width;
            opts.height = height;
            opts.frames = frames;
            opts.seed = seed;
            opts.mesh_spacing = mesh_spacing;
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
        Command::ImportCalib {
            from,
            paths,
            units,
            out,
            size,
            force,
        } => {
            // Refused before reading: never over the command's own inputs, a device or a
            // FIFO, and an existing file only with --force.
            let inputs: Vec<&std::path::Path> = paths.iter().map(|p| p.as_path()).collect();
            hullpose::fsutil::check_output_target("--out", &out, &inputs, force)?;
            let imported = match (from, paths.as_slice()) {
                (CalibSource::Opencv, [intri, extri]) => {
                    hullpose::calib_import::from_opencv(intri, extri, size)?
                }
                (CalibSource::Colmap, [dir]) => hullpose::calib_import::from_colmap(dir)?,
                (CalibSource::Pose2sim, [file]) => {
                    hullpose::calib_import::pose2sim::from_toml(file, units.metres())?
                }
                (CalibSource::Qualisys, [file]) => {
                    hullpose::calib_import::qualisys::from_qca(file)?
                }
                (CalibSource::Pose2sim | CalibSource::Qualisys, _) => {
                    return Err(hullpose::Error::Usage(
                        "--from pose2sim and --from qualisys take one file".into(),
                    ))
                }
                (CalibSource::Opencv, _) => {
                    return Err(hullpose::Error::Usage(
                        "--from opencv takes two files: INTRI EXTRI (intri.yml extri.yml)".into(),
                    ))
                }
                (CalibSource::Colmap, _) => {
                    return Err(hullpose::Error::Usage(
                        "--from colmap takes one folder holding cameras.txt and images.txt".into(),
                    ))
                }
            };
            for w in &imported.warnings {
                eprintln!("warning: {}", hullpose::text::escape_controls(w));
            }
            hullpose::camera::write_cameras(&out, &imported.cameras)?;
            println!(
                "wrote {} cameras to {}",
                imported.cameras.len(),
                out.display()
            );
        }
        Command::Skeleton {
            file,
            template,
            frame,
            force,
        } => {
            let mut job = Job::load(Config::load(&file)?, None)?;
            // --force replaces whatever skeleton.yaml holds, valid or not: it is not read.
            job.sequence.skeleton_ignored = force;
            let template = hullpose::autoskeleton::Template::parse(&template);
            let w = hullpose::autoskeleton::make(&job, &template, frame, force)?;
            if let Some(up) = &w.up_found {
                println!("{up}");
            }
            if w.candidates.len() > 1 {
                println!("frames examined (score: the share of joints every view's silhouette holds, less the surface left unexplained and the left/right limb difference):");
                for c in &w.candidates {
                    match &c.outcome {
                        Ok(score) => println!("  frame {:>5}: score {score:.3}", c.frame),
                        Err(why) => println!("  frame {:>5}: refused: {why}", c.frame),
                    }
                }
            }
            println!(
                "embedded {} bones in frame {} in {:.2} s",
                w.skeleton_value.bones.len(),
                w.frame,
                w.embed_seconds
            );
            for bone in &w.skeleton_value.bones {
                println!("  {:<14} {:>6.1} cm", bone.name, 100.0 * bone.length());
            }
            println!(
                "every joint lies inside the silhouettes (within {} px) of at least {} of {} cameras (fewest: {})",
                hullpose::autoskeleton::MASK_SLACK_PX,
                w.least_seen_joint.1,
                job.sequence.cameras.len(),
                w.least_seen_joint.0
            );
            for (name, left, right) in &w.limb_lengths {
                println!(
                    "  limb from {name}: left {:.1} cm, right {:.1} cm ({:+.0}%)",
                    100.0 * left,
                    100.0 * right,
                    100.0 * (left - right) / left.max(*right)
                );
            }
            println!(
                "{:.0}% of the surface lies far from every bone",
                100.0 * w.uncovered_share
            );
            if w.uncovered_share > hullpose::skeleton::embed::UNCOVERED_WARN {
                eprintln!(
                    "warning: {:.0}% of frame {}'s surface lies far from every bone: phantom \
                     volume (few cameras), a dress, or a limb the template could not follow \
                     (hands on the hips, crossed arms); check the overlay below, or choose a \
                     frame where the arms and legs stand clear of the torso with --frame",
                    100.0 * w.uncovered_share,
                    w.frame
                );
            }
            println!("wrote {}", w.skeleton.display());
            println!(
                "wrote {} (open it with the reference frame's mesh in MeshLab or Blender)",
                w.bones_ply.display()
            );
            println!(
                "wrote {} (the skeleton on the reference frame in every camera)",
                w.overlay.display()
            );
        }
        Command::Check { file } => {
            // The same checks as `run` before its first stage.
            let job = Job::load(Config::load(&file)?, None)?;
            job.validate()?;
            hullpose::export::check_formats(&job)?;
            let seq = &job.sequence;
            for w in seq.warnings.iter().chain(&job.inspect_first_frame()?) {
                eprintln!("warning: {}", hullpose::text::escape_controls(w));
            }
            let skeleton = seq.skeleton()?;
            let joints = seq.ground_truth_joints()?;
            println!(
                "{}: {} cameras, {} frames ({}..{}), frame images: {}, masks: {}, background plates: {}, skeleton: {}, ground-truth joints: {}",
                seq.dir.display(),
                seq.cameras.len(),
                seq.frames.len(),
                seq.frames[0],
                seq.frames[seq.frames.len() - 1],
                if seq.has_frames { "yes" } else { "no (masks only)" },
                if seq.has_masks { "yes" } else { "no" },
                if seq.has_backgrounds { "yes" } else { "no" },
                skeleton.map_or("no".to_string(), |s| format!("{} bones", s.bones.len())),
                joints.map_or("no".to_string(), |j| format!("{} rows", j.len())),
            );
            for line in seq.video_report() {
                println!("video {line}");
            }
            if let Some(line) = &job.learning {
                println!("{line}");
            }
            println!("stages:");
            for line in hullpose::stages::plan_notes(&job.context())? {
                println!("  {line}");
            }
            match hullpose::stages::model::check_skeleton(&job.context())? {
                Some(line) => println!("skeleton: {line}"),
                None if seq.skeleton()?.is_some() => println!(
                    "skeleton: not tested yet against the reference frame's surface (run the \
                     stages up to graphcut for that frame, then check again)"
                ),
                None => {}
            }
        }
    }
    Ok(())
}

fn main() -> ExitCode {
    // Die quietly when the reader of our output goes away (`pipeline evaluate | head`), as
    // command-line tools do, instead of panicking on a broken pipe.
    // SAFETY: resetting a signal disposition to its default before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
