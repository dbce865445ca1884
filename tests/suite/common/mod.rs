//! Helpers shared by the integration tests: synthetic datasets made once per test binary,
//! plain voxel carving, mesh voxelization, and running the CLI.
#![allow(dead_code)]

use hullpose::camera::Camera;
use hullpose::geometry::grid::{GridSpec, FACE_OFFSETS};
use hullpose::geometry::TriMesh;
use hullpose::synth::{SceneKind, SynthOptions};
use nalgebra::{Vector2, Vector3};
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

/// A synthetic dataset shared by every test binary of one build: written once under
/// Cargo's per-build scratch folder (`CARGO_TARGET_TMPDIR`), so the suite keeps one copy of
/// each on disk instead of one per test process.
pub struct Made {
    pub root: PathBuf,
}

/// Writes the dataset into a fresh folder beside its final place and renames it there, so a
/// concurrent or interrupted test process never sees half a dataset.
fn make(scene: SceneKind, width: u32, height: u32) -> Made {
    let base = Path::new(env!("CARGO_TARGET_TMPDIR")).join("datasets");
    std::fs::create_dir_all(&base).expect("scratch folder");
    let name = format!("{scene:?}-{width}x{height}-");
    let root = base.join(format!("{name}{:016x}", source_hash()));
    if !root.join("pipeline.yaml").exists() {
        // Copies made by older sources are stale.
        for e in std::fs::read_dir(&base).into_iter().flatten().flatten() {
            if e.file_name().to_string_lossy().starts_with(&name) {
                let _ = std::fs::remove_dir_all(e.path());
            }
        }
        let fresh = tempfile::tempdir_in(&base).expect("temp dir");
        let mut opts = SynthOptions::new(scene, fresh.path());
        opts.width = width;
        opts.height = height;
        hullpose::synth::generate(&opts).expect("synthesis");
        // Losing the race to another process is fine: its copy is identical, and ours is
        // removed with `fresh`.
        let _ = std::fs::rename(fresh.path(), &root);
    }
    Made { root }
}

/// A hash of the crate's sources: a shared dataset is rewritten whenever they change.
fn source_hash() -> u64 {
    fn visit(dir: &Path, h: &mut std::collections::hash_map::DefaultHasher) {
        let mut entries: Vec<_> = std::fs::read_dir(dir).unwrap().flatten().collect();
        entries.sort_by_key(|e| e.file_name());
        for e in entries {
            if e.path().is_dir() {
                visit(&e.path(), h);
            } else {
                e.file_name().hash(h);
                std::fs::read(e.path()).unwrap().hash(h);
            }
        }
    }
    let mut h = std::collections::hash_map::DefaultHasher::new();
    visit(&Path::new(env!("CARGO_MANIFEST_DIR")).join("src"), &mut h);
    h.finish()
}

/// The tripod at the paper's 15 cameras, 512x384 (every test of one binary shares it).
pub fn tripod() -> &'static Made {
    static CELL: OnceLock<Made> = OnceLock::new();
    CELL.get_or_init(|| make(SceneKind::Tripod, 512, 384))
}

/// The humanoid at 15 cameras, 384x288.
pub fn humanoid() -> &'static Made {
    static CELL: OnceLock<Made> = OnceLock::new();
    CELL.get_or_init(|| make(SceneKind::Humanoid, 384, 288))
}

/// Folders to delete when the test process exits (Rust never drops `static`s, so a
/// `TempDir` kept in one would otherwise stay on disk).
static AT_EXIT: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

extern "C" fn remove_registered_dirs() {
    if let Ok(dirs) = AT_EXIT.lock() {
        for d in dirs.iter() {
            let _ = std::fs::remove_dir_all(d);
        }
    }
}

/// A temporary folder for a `static` shared by the tests of one binary: removed when the
/// process exits, whether the tests passed or not.
pub fn process_tempdir() -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut dirs = AT_EXIT.lock().unwrap();
    if dirs.is_empty() {
        // SAFETY: registers a plain function with the C runtime; it runs once at exit.
        unsafe { libc::atexit(remove_registered_dirs) };
    }
    dirs.push(dir.path().to_path_buf());
    dir
}

/// A voxel grid over a box: `dims` voxels of `size` metres from `lo` (voxel centres at
/// lo + size * (i + 0.5)).
#[derive(Clone)]
pub struct Grid {
    pub lo: Vector3<f64>,
    pub size: f64,
    pub dims: [usize; 3],
}

impl Grid {
    pub fn around(mesh: &TriMesh, margin: f64, size: f64) -> Grid {
        let (lo, hi) = mesh.bounds().unwrap();
        let lo = lo - Vector3::repeat(margin);
        let hi = hi + Vector3::repeat(margin);
        let dims = [0, 1, 2].map(|a| ((hi[a] - lo[a]) / size).ceil() as usize);
        Grid { lo, size, dims }
    }
    /// The same grid as the pipeline describes it.
    pub fn spec(&self) -> GridSpec {
        GridSpec {
            origin: self.lo,
            voxel: self.size,
            dims: self.dims,
        }
    }
    pub fn len(&self) -> usize {
        self.spec().len()
    }
    pub fn index(&self, x: usize, y: usize, z: usize) -> usize {
        self.spec().index(x, y, z)
    }
    pub fn coords(&self, i: usize) -> [usize; 3] {
        self.spec().coords(i)
    }
    pub fn centre(&self, i: usize) -> Vector3<f64> {
        let c = self.coords(i);
        self.lo + self.size * Vector3::new(c[0] as f64 + 0.5, c[1] as f64 + 0.5, c[2] as f64 + 0.5)
    }
}

/// Plain voxel carving: a voxel stays unless its centre projects, inside some camera's
/// image, onto background.
pub fn carve(grid: &Grid, cams: &[Camera], masks: &[image::GrayImage]) -> Vec<bool> {
    (0..grid.len())
        .map(|i| {
            let p = grid.centre(i);
            cams.iter().zip(masks).all(|(c, m)| match c.project(&p) {
                Some(px) if c.in_image(&px) => {
                    let (x, y) = (px.x.round() as u32, px.y.round() as u32);
                    m.get_pixel(x.min(c.width - 1), y.min(c.height - 1)).0[0] >= 128
                }
                _ => true,
            })
        })
        .collect()
}

/// Inside/outside of a closed mesh at voxel centres, by ray parity along +z per column.
pub fn voxelize(grid: &Grid, mesh: &TriMesh) -> Vec<bool> {
    let [nx, ny, nz] = grid.dims;
    let mut hits: Vec<Vec<f64>> = vec![Vec::new(); nx * ny];
    let col = |v: f64, lo: f64| (v - lo) / grid.size - 0.5;
    for t in &mesh.triangles {
        let [a, b, d] = t.map(|i| mesh.vertices[i as usize]);
        let (a2, b2, d2) = (a.xy(), b.xy(), d.xy());
        let area = (b2 - a2).perp(&(d2 - a2));
        if area.abs() < 1e-18 {
            continue;
        }
        let xs = [a.x, b.x, d.x].map(|v| col(v, grid.lo.x));
        let ys = [a.y, b.y, d.y].map(|v| col(v, grid.lo.y));
        let x0 = xs
            .iter()
            .cloned()
            .fold(f64::INFINITY, f64::min)
            .ceil()
            .max(0.0) as usize;
        let x1 = (xs.iter().cloned().fold(f64::NEG_INFINITY, f64::max).floor() as i64)
            .min(nx as i64 - 1);
        let y0 = ys
            .iter()
            .cloned()
            .fold(f64::INFINITY, f64::min)
            .ceil()
            .max(0.0) as usize;
        let y1 = (ys.iter().cloned().fold(f64::NEG_INFINITY, f64::max).floor() as i64)
            .min(ny as i64 - 1);
        for y in y0 as i64..=y1 {
            for x in x0 as i64..=x1 {
                let c = grid.centre(grid.index(x as usize, y as usize, 0));
                let q = Vector2::new(c.x, c.y);
                let l0 = (b2 - q).perp(&(d2 - q)) / area;
                let l1 = (d2 - q).perp(&(a2 - q)) / area;
                let l2 = 1.0 - l0 - l1;
                if l0 >= 0.0 && l1 >= 0.0 && l2 >= 0.0 {
                    hits[y as usize * nx + x as usize].push(l0 * a.z + l1 * b.z + l2 * d.z);
                }
            }
        }
    }
    let mut inside = vec![false; grid.len()];
    for y in 0..ny {
        for x in 0..nx {
            let h = &mut hits[y * nx + x];
            h.sort_by(f64::total_cmp);
            h.dedup_by(|a, b| (*a - *b).abs() < 1e-12);
            for z in 0..nz {
                let zc = grid.lo.z + grid.size * (z as f64 + 0.5);
                inside[grid.index(x, y, z)] = h.iter().filter(|&&v| v < zc).count() % 2 == 1;
            }
        }
    }
    inside
}

/// Dilates a voxel set by one voxel (6-neighbourhood).
pub fn dilate(grid: &Grid, set: &[bool]) -> Vec<bool> {
    let spec = grid.spec();
    let mut out = set.to_vec();
    for (i, _) in set.iter().enumerate().filter(|(_, &inside)| inside) {
        for offset in FACE_OFFSETS {
            if let Some(j) = spec.face_neighbour(i, offset) {
                out[j] = true;
            }
        }
    }
    out
}

/// 6-connected components of a voxel set: lists of voxel indices.
pub fn components(grid: &Grid, set: &[bool]) -> Vec<Vec<usize>> {
    let spec = grid.spec();
    let mut seen = vec![false; grid.len()];
    let mut out = Vec::new();
    for s in 0..grid.len() {
        if !set[s] || seen[s] {
            continue;
        }
        let mut comp = vec![s];
        seen[s] = true;
        let mut k = 0;
        while k < comp.len() {
            let at = comp[k];
            k += 1;
            for offset in FACE_OFFSETS {
                if let Some(j) = spec.face_neighbour(at, offset) {
                    if set[j] && !seen[j] {
                        seen[j] = true;
                        comp.push(j);
                    }
                }
            }
        }
        out.push(comp);
    }
    out
}

/// A run folder whose pipeline.yaml points at a shared synthetic capture (given masks as
/// silhouettes), with `extra` YAML appended; it keeps its own cache.
pub fn run_folder(made: &Made, seq: &str, extra: &str) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let yaml = format!(
        "calibration: {}\nsequence: {}\n{extra}",
        made.root.join("calib/cameras.yaml").display(),
        made.root.join("data").join(seq).display()
    );
    std::fs::write(dir.path().join("pipeline.yaml"), yaml).unwrap();
    dir
}

/// A run folder holding links to `entries` of a shared synthetic capture's sequence
/// (`frames`, `background`, `skeleton.yaml`, ...; the rest, such as the true masks, left
/// out), a copy of its calibration and the default pipeline.yaml with `extra_yaml` appended;
/// it keeps its own cache.
pub fn linked_capture(
    made: &Made,
    seq: &str,
    entries: &[&str],
    extra_yaml: &str,
) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let src = made.root.join("data").join(seq);
    let dst = dir.path().join("data").join(seq);
    std::fs::create_dir_all(&dst).unwrap();
    for entry in entries {
        std::os::unix::fs::symlink(src.join(entry), dst.join(entry)).unwrap();
    }
    std::fs::create_dir_all(dir.path().join("calib")).unwrap();
    std::fs::copy(
        made.root.join("calib/cameras.yaml"),
        dir.path().join("calib/cameras.yaml"),
    )
    .unwrap();
    let yaml = hullpose::config::default_yaml("calib/cameras.yaml", &format!("data/{seq}"));
    std::fs::write(
        dir.path().join("pipeline.yaml"),
        format!("{yaml}{extra_yaml}"),
    )
    .unwrap();
    dir
}

/// The silhouette IoU of two masks (>= 128 is the subject; 1 when both are empty).
pub fn mask_iou(a: &image::GrayImage, b: &image::GrayImage) -> f64 {
    let (mut both, mut either) = (0usize, 0usize);
    for (x, y) in a.as_raw().iter().zip(b.as_raw()) {
        both += (*x >= 128 && *y >= 128) as usize;
        either += (*x >= 128 || *y >= 128) as usize;
    }
    if either == 0 {
        1.0
    } else {
        both as f64 / either as f64
    }
}

/// The worst IoU of a run folder's silhouettes (`cache/silhouette`) against the true masks
/// under `truth` (`<camera>/NNNNNN.png`): the IoU, which camera and frame, and how many
/// images were compared.
pub fn worst_silhouette_iou(run: &Path, truth: &Path) -> (f64, String, usize) {
    let mut worst = (1.0, String::new(), 0);
    for frame in std::fs::read_dir(run.join("cache/silhouette"))
        .unwrap()
        .flatten()
    {
        if !frame.path().is_dir() {
            continue;
        }
        let f = frame.file_name().to_string_lossy().into_owned();
        for img in std::fs::read_dir(frame.path()).unwrap().flatten() {
            let cam = img
                .path()
                .file_stem()
                .unwrap()
                .to_string_lossy()
                .into_owned();
            let ours = image::open(img.path()).unwrap().to_luma8();
            let true_mask = image::open(truth.join(&cam).join(format!("{f}.png")))
                .unwrap()
                .to_luma8();
            let v = mask_iou(&ours, &true_mask);
            worst.2 += 1;
            if v < worst.0 {
                worst = (v, format!("{cam} frame {f}"), worst.2);
            }
        }
    }
    worst
}

/// Rows (frame, stage, accuracy90, completeness) of `output/evaluation/reconstruction.csv`
/// in a run folder.
pub fn reconstruction_rows(dir: &Path) -> Vec<ReconRow> {
    let csv = std::fs::read_to_string(dir.join("output/evaluation/reconstruction.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            let get = |name: &str| f[header.iter().position(|h| *h == name).unwrap()];
            let num = |name: &str| get(name).parse::<f64>().unwrap();
            ReconRow {
                frame: get("frame").parse().unwrap(),
                stage: get("stage").to_string(),
                accuracy: num("accuracy90_m"),
                completeness: num("completeness"),
                inside: num("inside_completeness"),
                offset: num("median_offset_m"),
            }
        })
        .collect()
}

/// One row of `pipeline evaluate`'s reconstruction.csv (metres and shares).
#[derive(Debug, Clone)]
pub struct ReconRow {
    pub frame: u32,
    pub stage: String,
    /// accuracy90.
    pub accuracy: f64,
    /// Within a voxel of the reconstructed surface.
    pub completeness: f64,
    /// Inside the reconstruction or within a voxel of it.
    pub inside: f64,
    /// Median signed offset, positive outside.
    pub offset: f64,
}

/// Path of the built `pipeline` binary.
pub fn pipeline_bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_pipeline"))
}

/// Runs `pipeline ARGS` and returns (exit success, stdout, stderr).
pub fn run_cli(args: &[&str], cwd: &Path) -> (bool, String, String) {
    let out = std::process::Command::new(pipeline_bin())
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("run pipeline");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Copies the bundled sample capture (`calib/` and `data/`) into the folder `to`.
pub fn copy_sample_capture(to: &Path) {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    copy_tree(&repo.join("calib"), &to.join("calib"));
    copy_tree(&repo.join("data"), &to.join("data"));
}

/// Copies the bundled sample capture with its `pipeline.yaml` into the folder `to`.
pub fn copy_sample(to: &Path) {
    copy_sample_capture(to);
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    std::fs::copy(repo.join("pipeline.yaml"), to.join("pipeline.yaml")).unwrap();
}

/// Copies a folder tree.
pub fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let target = to.join(e.file_name());
        if e.path().is_dir() {
            copy_tree(&e.path(), &target);
        } else {
            std::fs::copy(e.path(), target).unwrap();
        }
    }
}

/// Tracks `frames` with `params` over the cached reconstruction of `ctx`'s run (as the fit
/// stage does) and returns the joints of every frame's pose.
pub fn tracked_joint_rows(
    ctx: &hullpose::stages::Context,
    skeleton: &hullpose::skeleton::Skeleton,
    frames: &[u32],
    params: &hullpose::fit::FitParams,
) -> Vec<hullpose::joints::JointRow> {
    let tracked = hullpose::stages::fit::track_in_memory(ctx, frames, params, &|_| {}).unwrap();
    joint_rows_of(skeleton, &tracked)
}

/// The joint rows of every frame of a tracking.
pub fn joint_rows_of(
    skeleton: &hullpose::skeleton::Skeleton,
    tracked: &hullpose::stages::fit::Tracked,
) -> Vec<hullpose::joints::JointRow> {
    tracked
        .results
        .iter()
        .flat_map(|(f, r)| hullpose::stages::fit::joint_rows(skeleton, *f, &r.pose))
        .collect()
}

/// Mean joint error per frame, centimetres, of the run's `output/joints.csv` in `dir`
/// against the sequence `seq`'s ground truth.
pub fn output_joint_errors_cm(dir: &Path, seq: &str) -> Vec<f64> {
    let truth_path = dir.join(format!("data/{seq}/ground_truth/joints.csv"));
    let truth = hullpose::joints::read(&truth_path).unwrap();
    let rows = hullpose::joints::read(&dir.join("output/joints.csv")).unwrap();
    hullpose::eval::pose::joint_errors(&truth, &rows, &truth_path)
        .unwrap()
        .into_iter()
        .map(|x| x.1 * 100.0)
        .collect()
}

/// The fit's health in the run's `output/fit.csv` in `dir`: the silhouettes held
/// ([`assert_silhouettes_held`]) and no frame flagged.
pub fn assert_fit_health(dir: &Path) {
    for r in assert_silhouettes_held(dir) {
        assert!(r.flags.is_empty(), "frame {} flagged {}", r.frame, r.flags);
    }
}

/// Every frame of the run's `output/fit.csv` in `dir` has its health, and the posed
/// model's worst-camera silhouette IoU never falls below 0.9 times its value at the
/// reference frame (issue bound: no drift, no lost limb); returns the rows.
pub fn assert_silhouettes_held(dir: &Path) -> Vec<hullpose::stages::fit::HealthRow> {
    let rows = hullpose::eval::health_table::read(&dir.join("output")).unwrap();
    assert!(!rows.is_empty(), "fit.csv has the health columns");
    let reference = rows.iter().find(|r| r.status == "reference").unwrap();
    assert!(
        reference.iou_worst > 0.8,
        "reference IoU {}",
        reference.iou_worst
    );
    for r in &rows {
        assert!(
            r.iou_worst >= 0.9 * reference.iou_worst,
            "frame {}: worst IoU {} ({}) against {} at the reference",
            r.frame,
            r.iou_worst,
            r.iou_worst_camera,
            reference.iou_worst
        );
        assert!(r.iou_median >= r.iou_worst && r.joint_motion.is_finite());
    }
    rows
}

/// fit.csv's flags against the truth of the sequence `seq` (the bound for flags that
/// mean something): no frame whose joints all lie within 3 cm of the truth is flagged, and
/// every frame with a joint over 10 cm off is.
pub fn assert_flags_follow_truth(dir: &Path, seq: &str) {
    let rows = hullpose::eval::health_table::read(&dir.join("output")).unwrap();
    let worst: std::collections::BTreeMap<u32, f64> =
        output_worst_joint_errors_cm(dir, seq).into_iter().collect();
    for r in &rows {
        let w = worst[&r.frame];
        assert!(
            w > 3.0 || r.flags.is_empty(),
            "frame {}: worst joint {w:.2} cm, flagged {}",
            r.frame,
            r.flags
        );
        assert!(
            w <= 10.0 || !r.flags.is_empty(),
            "frame {}: worst joint {w:.2} cm, not flagged",
            r.frame
        );
    }
}

/// The worst joint error per frame (a bone's head or tail), centimetres, of the run's
/// `output/joints.csv` in `dir` against the sequence `seq`'s ground truth, in frame order.
pub fn output_worst_joint_errors_cm(dir: &Path, seq: &str) -> Vec<(u32, f64)> {
    let truth =
        hullpose::joints::read(&dir.join(format!("data/{seq}/ground_truth/joints.csv"))).unwrap();
    let rows = hullpose::joints::read(&dir.join("output/joints.csv")).unwrap();
    let mut worst: std::collections::BTreeMap<u32, f64> = Default::default();
    for r in &rows {
        let t = truth
            .iter()
            .find(|t| t.frame == r.frame && t.bone == r.bone)
            .unwrap();
        let e = 100.0 * (r.head - t.head).norm().max((r.tail - t.tail).norm());
        let w = worst.entry(r.frame).or_insert(0.0);
        *w = w.max(e);
    }
    worst.into_iter().collect()
}

/// Every file under `dir` with its bytes, by relative path; the cache's manifests (which
/// record seconds) and lock left out.
pub fn tree_files(dir: &Path) -> std::collections::BTreeMap<String, Vec<u8>> {
    let mut out = std::collections::BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            let name = p.file_name().unwrap().to_string_lossy().to_string();
            if p.is_dir() {
                stack.push(p);
            } else if !name.ends_with(".manifest.yaml") && name != ".lock" {
                let rel = p.strip_prefix(dir).unwrap().display().to_string();
                out.insert(rel, std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

/// Asserts that two [`tree_files`] hold the same files with the same bytes; `what` names
/// the comparison and `folder` the tree in messages.
pub fn assert_same_files(
    a: &std::collections::BTreeMap<String, Vec<u8>>,
    b: &std::collections::BTreeMap<String, Vec<u8>>,
    folder: &str,
    what: &str,
) {
    assert_eq!(
        a.keys().collect::<Vec<_>>(),
        b.keys().collect::<Vec<_>>(),
        "{what}: other files in {folder}"
    );
    for (path, bytes) in a {
        assert!(bytes == &b[path], "{what}: {folder}/{path} differs");
    }
}

/// Runs `pipeline run pipeline.yaml` in `dir` and kills it (SIGKILL) as soon as `reached`
/// says so (or when the run ends first, or after two minutes).
pub fn run_killed_when(dir: &Path, reached: impl Fn() -> bool) {
    let mut child = std::process::Command::new(pipeline_bin())
        .args(["run", "pipeline.yaml"])
        .current_dir(dir)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let started = std::time::Instant::now();
    while started.elapsed().as_secs() < 120 && !reached() && child.try_wait().unwrap().is_none() {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    let _ = child.kill();
    let _ = child.wait();
}

/// How many files in `dir` (not below it) have names ending with `suffix`; 0 when `dir`
/// does not exist yet.
pub fn count_files_ending(dir: &Path, suffix: &str) -> usize {
    std::fs::read_dir(dir).map_or(0, |d| {
        d.flatten()
            .filter(|e| e.file_name().to_string_lossy().ends_with(suffix))
            .count()
    })
}

/// Whether the system's ffmpeg runs; without it the video tests say so and pass, unless
/// `HULLPOSE_EXTERNAL_CHECKS=1` (as CI sets it), which makes its absence a failure.
pub fn have_ffmpeg() -> bool {
    let found = std::process::Command::new("ffmpeg")
        .arg("-version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !found && std::env::var("HULLPOSE_EXTERNAL_CHECKS").is_ok_and(|v| v == "1") {
        panic!("ffmpeg is required (HULLPOSE_EXTERNAL_CHECKS=1): apt install ffmpeg");
    }
    if !found {
        eprintln!("ffmpeg not installed: video tests skipped");
    }
    found
}
