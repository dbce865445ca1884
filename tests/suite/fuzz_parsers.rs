//! Mutation fuzzing of every parser of outside input: pipeline.yaml, cameras.yaml,
//! skeleton.yaml, joints.csv, PLY, OBJ and the calibration importers (OpenCV, COLMAP,
//! Pose2Sim/anipose TOML, Qualisys .qca.txt).
//!
//! Each target starts from the files under `tests/fuzz/<target>/` (valid seeds, plus any
//! input that once broke a parser, kept as a regression), replays them, then mutates them
//! (bit flips, byte edits, cut / duplicated / spliced ranges, and tokens such as huge counts,
//! `nan`, `-1`, quotes and brackets) for a time budget: `HULLPOSE_FUZZ_SECONDS` per target
//! (default 2). A parser may return any error but must never panic; a panicking input is
//! written to `target/fuzz-crashes/<target>/` and the test fails naming it (copy it into
//! `tests/fuzz/<target>/` once fixed, as a regression). Each target prints its executions
//! and the number of distinct outcomes (accepted, or each distinct error message with digits
//! removed) it reached: a rough measure of how much of the parser the inputs explore.

use std::collections::HashSet;
use std::panic::AssertUnwindSafe;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// xorshift64*: a small deterministic generator (the same run every time).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

const TOKENS: &[&str] = &[
    "-1",
    "0",
    "4294967296",
    "18446744073709551616",
    "1e309",
    "-1e309",
    "nan",
    "inf",
    "NaN",
    "\n",
    "\r\n",
    ":",
    ": ",
    "[",
    "]",
    "{",
    "}",
    "- ",
    ",",
    "\"",
    "'",
    "\0",
    "99999999999",
    "element vertex 4000000000\n",
    "property list uchar int vertex_indices\n",
    "!!opencv-matrix",
    "null",
    "~",
    "&a",
    "*a",
    "<<",
    "..",
    "../",
    "/",
    " ",
    "\t",
    "#",
    "%YAML:1.0\n",
    "---\n",
];

/// One to four random edits of `input`; `other` is another seed to splice from.
fn mutate(rng: &mut Rng, input: &[u8], other: &[u8]) -> Vec<u8> {
    let mut v = input.to_vec();
    for _ in 0..1 + rng.below(4) {
        let len = v.len();
        let at = rng.below(len + 1);
        match rng.below(8) {
            0 if len > 0 => {
                let i = rng.below(len);
                v[i] ^= 1 << rng.below(8);
            }
            1 if len > 0 => {
                let i = rng.below(len);
                v[i] = rng.next() as u8;
            }
            2 => v.insert(at, rng.next() as u8),
            3 if len > 0 => {
                let end = (at + 1 + rng.below(16)).min(len);
                v.drain(at.min(end)..end);
            }
            4 if len > 0 => {
                let start = rng.below(len);
                let end = (start + 1 + rng.below(64)).min(len);
                let chunk = v[start..end].to_vec();
                v.splice(at..at, chunk);
            }
            5 => v.truncate(at),
            6 if !other.is_empty() => {
                let start = rng.below(other.len());
                let end = (start + 1 + rng.below(128)).min(other.len());
                v.splice(at..at, other[start..end].iter().copied());
            }
            _ => {
                let t = TOKENS[rng.below(TOKENS.len())].as_bytes();
                // Replace a number-like run with the token, or insert it.
                let end = (at + rng.below(6)).min(len);
                v.splice(at..end, t.iter().copied());
            }
        }
    }
    v
}

/// A fuzz target: feeds one input to a parser (through files in `dir` where the parser
/// reads paths) and returns its outcome: `Ok` or the error text.
type Target = fn(&[u8], &Path) -> Result<(), String>;

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn outcome<T, E: std::fmt::Display>(r: Result<T, E>) -> Result<(), String> {
    r.map(|_| ()).map_err(|e| e.to_string())
}

fn pipeline_yaml(b: &[u8], dir: &Path) -> Result<(), String> {
    std::fs::create_dir_all(dir.join("calib")).unwrap();
    std::fs::create_dir_all(dir.join("data/tripod")).unwrap();
    std::fs::write(dir.join("calib/cameras.yaml"), "cameras: []\n").unwrap();
    let path = dir.join("pipeline.yaml");
    std::fs::write(&path, b).unwrap();
    outcome(hullpose::config::Config::load(&path))
}

fn cameras_yaml(b: &[u8], _: &Path) -> Result<(), String> {
    outcome(hullpose::camera::parse_cameras(
        Path::new("cameras.yaml"),
        &text(b),
    ))
}

fn skeleton_yaml(b: &[u8], _: &Path) -> Result<(), String> {
    outcome(hullpose::skeleton::Skeleton::parse(
        Path::new("skeleton.yaml"),
        &text(b),
    ))
}

fn joints_csv(b: &[u8], _: &Path) -> Result<(), String> {
    outcome(hullpose::joints::parse(Path::new("joints.csv"), &text(b)))
}

fn ply(b: &[u8], _: &Path) -> Result<(), String> {
    outcome(hullpose::geometry::ply::parse_ply(Path::new("mesh.ply"), b))
}

fn obj(b: &[u8], dir: &Path) -> Result<(), String> {
    let path = dir.join("mesh.obj");
    std::fs::write(&path, b).unwrap();
    outcome(hullpose::geometry::obj::read_obj(&path))
}

/// The OpenCV importer with one of its two files mutated (the other a valid seed).
fn opencv(b: &[u8], dir: &Path, mutate_intri: bool) -> Result<(), String> {
    let seeds = fuzz_root();
    let (intri, extri) = (dir.join("intri.yml"), dir.join("extri.yml"));
    let intri_seed = std::fs::read(seeds.join("opencv_intri/seed-intri.yml")).unwrap();
    let extri_seed = std::fs::read(seeds.join("opencv_extri/seed-extri.yml")).unwrap();
    let (i, e) = if mutate_intri {
        (b.to_vec(), extri_seed)
    } else {
        (intri_seed, b.to_vec())
    };
    std::fs::write(&intri, i).unwrap();
    std::fs::write(&extri, e).unwrap();
    outcome(hullpose::calib_import::from_opencv(
        &intri,
        &extri,
        Some((640, 480)),
    ))
}

fn opencv_intri(b: &[u8], dir: &Path) -> Result<(), String> {
    opencv(b, dir, true)
}

fn opencv_extri(b: &[u8], dir: &Path) -> Result<(), String> {
    opencv(b, dir, false)
}

/// The COLMAP importer with one of its two files mutated.
fn colmap(b: &[u8], dir: &Path, mutate_cameras: bool) -> Result<(), String> {
    let seeds = fuzz_root();
    let cams = std::fs::read(seeds.join("colmap_cameras/seed-cameras.txt")).unwrap();
    let images = std::fs::read(seeds.join("colmap_images/seed-images.txt")).unwrap();
    let (c, i) = if mutate_cameras {
        (b.to_vec(), images)
    } else {
        (cams, b.to_vec())
    };
    std::fs::write(dir.join("cameras.txt"), c).unwrap();
    std::fs::write(dir.join("images.txt"), i).unwrap();
    outcome(hullpose::calib_import::from_colmap(dir))
}

fn colmap_cameras(b: &[u8], dir: &Path) -> Result<(), String> {
    colmap(b, dir, true)
}

fn colmap_images(b: &[u8], dir: &Path) -> Result<(), String> {
    colmap(b, dir, false)
}

/// The Pose2Sim/anipose TOML importer (millimetre units, so the scale path runs too).
fn pose2sim_toml(b: &[u8], dir: &Path) -> Result<(), String> {
    let path = dir.join("Calib.toml");
    std::fs::write(&path, b).unwrap();
    outcome(hullpose::calib_import::pose2sim::from_toml(&path, 0.001))
}

/// The Qualisys .qca.txt importer (XML).
fn qualisys_qca(b: &[u8], dir: &Path) -> Result<(), String> {
    let path = dir.join("calib.qca.txt");
    std::fs::write(&path, b).unwrap();
    outcome(hullpose::calib_import::qualisys::from_qca(&path))
}

fn fuzz_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz")
}

/// Runs one target: its corpus, then mutations for the budget. Panics (the test fails) on
/// an input that makes the parser panic, after saving it.
fn fuzz(name: &str, target: Target) {
    let budget = std::env::var("HULLPOSE_FUZZ_SECONDS")
        .ok()
        .and_then(|s| s.parse::<f64>().ok())
        .unwrap_or(2.0);
    let mut corpus: Vec<Vec<u8>> = std::fs::read_dir(fuzz_root().join(name))
        .map(|d| {
            let mut files: Vec<PathBuf> = d.flatten().map(|e| e.path()).collect();
            files.sort();
            files.iter().map(|p| std::fs::read(p).unwrap()).collect()
        })
        .unwrap_or_default();
    assert!(!corpus.is_empty(), "no seeds in tests/fuzz/{name}");
    let dir = tempfile::tempdir().unwrap();
    let mut seen: HashSet<String> = HashSet::new();
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15 ^ name.len() as u64);
    let run = |input: &[u8], seen: &mut HashSet<String>| -> bool {
        let result = std::panic::catch_unwind(AssertUnwindSafe(|| target(input, dir.path())));
        match result {
            Ok(r) => {
                let key = match r {
                    Ok(()) => "accepted".to_string(),
                    Err(e) => e.chars().filter(|c| !c.is_ascii_digit()).collect(),
                };
                seen.insert(key)
            }
            Err(_) => {
                let out = Path::new(env!("CARGO_MANIFEST_DIR"))
                    .join("target/fuzz-crashes")
                    .join(name);
                std::fs::create_dir_all(&out).unwrap();
                let file = out.join(format!("crash-{:016x}", fnv1a(input)));
                std::fs::write(&file, input).unwrap();
                panic!(
                    "fuzz target {name}: the parser panicked on {}",
                    file.display()
                );
            }
        }
    };
    for input in corpus.clone() {
        run(&input, &mut seen);
    }
    let start = Instant::now();
    let mut executions = corpus.len() as u64;
    while start.elapsed() < Duration::from_secs_f64(budget) {
        let a = rng.below(corpus.len());
        let b = rng.below(corpus.len());
        let input = mutate(&mut rng, &corpus[a], &corpus[b]);
        if input.len() > 1 << 16 {
            continue;
        }
        executions += 1;
        // Inputs that reach a new outcome join the working corpus (in memory).
        if run(&input, &mut seen) && corpus.len() < 512 {
            corpus.push(input);
        }
    }
    eprintln!(
        "fuzz {name}: {executions} executions in {:.1} s, {} distinct outcomes",
        start.elapsed().as_secs_f64(),
        seen.len()
    );
    assert!(
        executions > 100,
        "{name}: too few executions ({executions})"
    );
}

/// A 64-bit FNV-1a hash, to name crash files.
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x100_0000_01b3)
    })
}

#[test]
fn fuzz_pipeline_yaml() {
    fuzz("pipeline_yaml", pipeline_yaml);
}

#[test]
fn fuzz_cameras_yaml() {
    fuzz("cameras_yaml", cameras_yaml);
}

#[test]
fn fuzz_skeleton_yaml() {
    fuzz("skeleton_yaml", skeleton_yaml);
}

#[test]
fn fuzz_joints_csv() {
    fuzz("joints_csv", joints_csv);
}

#[test]
fn fuzz_ply() {
    fuzz("ply", ply);
}

#[test]
fn fuzz_obj() {
    fuzz("obj", obj);
}

#[test]
fn fuzz_opencv_intri() {
    fuzz("opencv_intri", opencv_intri);
}

#[test]
fn fuzz_opencv_extri() {
    fuzz("opencv_extri", opencv_extri);
}

#[test]
fn fuzz_colmap_cameras() {
    fuzz("colmap_cameras", colmap_cameras);
}

#[test]
fn fuzz_colmap_images() {
    fuzz("colmap_images", colmap_images);
}

#[test]
fn fuzz_pose2sim_toml() {
    fuzz("pose2sim_toml", pose2sim_toml);
}

#[test]
fn fuzz_qualisys_qca() {
    fuzz("qualisys_qca", qualisys_qca);
}
