//! Running the person model: the two ONNX files `tools/setup-person-model.sh` writes, run by
//! ONNX Runtime's library from the same folder (loaded at run time, never downloaded).
//!
//! ONNX Runtime rather than a pure-Rust engine (`tract-onnx`): both give the same keypoints
//! to 0.1 px here, but ONNX Runtime builds in a fifth of the time (1.3 against 6.2 min clean)
//! and runs the two models 2.5x as fast on one core (30 against 77 ms per image).

use super::blazepose::{
    self, Crop, Detection, Landmark, LANDMARKS, LANDMARK_ROWS, LANDMARK_SIDE, LANDMARK_VALUES,
};
use crate::error::{Error, Result};
use image::{GrayImage, RgbImage};
use ort::session::Session;
use ort::value::TensorRef;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The detector's file in the model folder.
pub const DETECTOR_FILE: &str = "person_detector.onnx";
/// The landmark model's file in the model folder.
pub const LANDMARKS_FILE: &str = "person_landmarks.onnx";
/// ONNX Runtime's library in the model folder.
pub const RUNTIME_FILE: &str = "libonnxruntime.so";

/// The environment variable naming the model folder.
pub const FOLDER_VARIABLE: &str = "HULLPOSE_PERSON_MODEL";

/// The model folder: `$HULLPOSE_PERSON_MODEL`, else `~/.local/share/hullpose/person-model`
/// (where the setup script writes by default).
pub fn folder() -> PathBuf {
    match std::env::var_os(FOLDER_VARIABLE) {
        Some(dir) if !dir.is_empty() => PathBuf::from(dir),
        _ => {
            let home = std::env::var_os("HOME").unwrap_or_default();
            Path::new(&home).join(".local/share/hullpose/person-model")
        }
    }
}

/// Whether the model folder holds the three files.
pub fn is_set_up(dir: &Path) -> bool {
    [DETECTOR_FILE, LANDMARKS_FILE, RUNTIME_FILE]
        .iter()
        .all(|f| dir.join(f).is_file())
}

fn not_set_up(dir: &Path, what: &str) -> Error {
    Error::invalid(
        dir,
        format!(
            "{what}. The person model is set up once with `bash tools/setup-person-model.sh` \
             (from the hullpose source tree; it fetches MediaPipe's BlazePose models, Apache-2.0, \
             from the mediapipe 0.10.14 package on PyPI and converts them to ONNX), into this \
             folder or the one {FOLDER_VARIABLE} names"
        ),
    )
}

/// A key for the model's files (their content), for the caches that hold its results.
/// The 25 MB are hashed once per process and folder: the silhouette stage asks for it with
/// every frame's settings.
pub fn fingerprint(dir: &Path) -> Result<String> {
    static KNOWN: std::sync::Mutex<Vec<(PathBuf, String)>> = std::sync::Mutex::new(Vec::new());
    if !is_set_up(dir) {
        return Err(not_set_up(dir, "the person model is not set up here"));
    }
    let mut known = KNOWN.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((_, key)) = known.iter().find(|(d, _)| d == dir) {
        return Ok(key.clone());
    }
    let mut h = blake3::Hasher::new();
    for f in [DETECTOR_FILE, LANDMARKS_FILE] {
        let path = dir.join(f);
        let bytes = std::fs::read(&path).map_err(|e| Error::io(&path, e))?;
        h.update(&bytes);
    }
    let key = h.finalize().to_hex()[..16].to_string();
    known.push((dir.to_path_buf(), key.clone()));
    Ok(key)
}

/// The person found in one image.
#[derive(Debug, Clone)]
pub struct Person {
    /// The detector's score, 0..1.
    pub score: f32,
    /// The landmark model's confidence that the crop holds a body, 0..1.
    pub presence: f32,
    /// The 33 body landmarks.
    pub landmarks: [Landmark; LANDMARKS],
    /// The person's mask at image resolution (255 = person).
    pub mask: GrayImage,
    /// The crop the landmarks were found in.
    pub crop: Crop,
}

/// The loaded model: one detector and one landmark session.
pub struct PersonModel {
    detector: Session,
    landmarks: Session,
}

static RUNTIME: OnceLock<std::result::Result<ort::environment::Environment, String>> =
    OnceLock::new();

fn session(env: &ort::environment::Environment, dir: &Path, file: &str) -> Result<Session> {
    let path = dir.join(file);
    let fail = |e: String| Error::invalid(&path, format!("cannot load the person model: {e}"));
    Session::builder(env)
        .map_err(|e| fail(e.to_string()))?
        .with_intra_threads(1)
        .map_err(|e| fail(e.to_string()))?
        .commit_from_file(&path)
        .map_err(|e| fail(e.to_string()))
}

impl PersonModel {
    /// Loads the model from `dir` (see [`folder`]).
    pub fn load(dir: &Path) -> Result<PersonModel> {
        if !is_set_up(dir) {
            return Err(not_set_up(dir, "the person model is not set up here"));
        }
        let runtime = RUNTIME.get_or_init(|| {
            let lib = dir.join(RUNTIME_FILE);
            ort::init_from(&lib)
                .map_err(|e| format!("{}: {e}", lib.display()))?
                .with_telemetry(false)
                .build()
                .map_err(|e| e.to_string())
        });
        let env = match runtime {
            Ok(env) => env,
            Err(e) => {
                return Err(not_set_up(
                    dir,
                    &format!("ONNX Runtime cannot be loaded ({e})"),
                ));
            }
        };
        Ok(PersonModel {
            detector: session(env, dir, DETECTOR_FILE)?,
            landmarks: session(env, dir, LANDMARKS_FILE)?,
        })
    }

    /// The detector's strongest person in `img`, image pixels.
    pub fn detect(&mut self, img: &RgbImage) -> Result<Option<Detection>> {
        let side = blazepose::DETECTOR_SIDE;
        let letterbox = blazepose::letterbox(img.width(), img.height());
        let input = blazepose::sample(img, &letterbox, side, -1.0, 1.0);
        let fail = |e: ort::Error| Error::Usage(format!("the person detector failed: {e}"));
        let tensor =
            TensorRef::from_array_view(([1usize, side, side, 3], &input[..])).map_err(fail)?;
        let out = self.detector.run(ort::inputs![tensor]).map_err(fail)?;
        let (_, boxes) = out[0].try_extract_tensor::<f32>().map_err(fail)?;
        let (_, scores) = out[1].try_extract_tensor::<f32>().map_err(fail)?;
        if boxes.len() != blazepose::ANCHORS * blazepose::DETECTION_VALUES
            || scores.len() != blazepose::ANCHORS
        {
            return Err(Error::Usage(format!(
                "the person detector's outputs have {} and {} values, not the {} and {} of \
                 BlazePose's detector: set the model up again",
                boxes.len(),
                scores.len(),
                blazepose::ANCHORS * blazepose::DETECTION_VALUES,
                blazepose::ANCHORS
            )));
        }
        Ok(blazepose::strongest_person(boxes, scores, &letterbox))
    }

    /// The person in `img`: detection, then landmarks and mask in the detection's crop.
    /// `None` when the detector finds nobody.
    pub fn find(&mut self, img: &RgbImage) -> Result<Option<Person>> {
        let Some(detection) = self.detect(img)? else {
            return Ok(None);
        };
        let crop = blazepose::crop_of(&detection);
        let n = LANDMARK_SIDE;
        let input = blazepose::sample(img, &crop.affine(), n, 0.0, 1.0);
        let fail = |e: ort::Error| Error::Usage(format!("the person landmark model failed: {e}"));
        let tensor = TensorRef::from_array_view(([1usize, n, n, 3], &input[..])).map_err(fail)?;
        let out = self.landmarks.run(ort::inputs![tensor]).map_err(fail)?;
        let (_, raw) = out[0].try_extract_tensor::<f32>().map_err(fail)?;
        let (_, flag) = out[1].try_extract_tensor::<f32>().map_err(fail)?;
        let (_, logits) = out[2].try_extract_tensor::<f32>().map_err(fail)?;
        if raw.len() != LANDMARK_ROWS * LANDMARK_VALUES || flag.len() != 1 || logits.len() != n * n
        {
            return Err(Error::Usage(
                "the person landmark model's outputs are not BlazePose's: set the model up again"
                    .into(),
            ));
        }
        Ok(Some(Person {
            score: detection.score,
            presence: flag[0],
            landmarks: blazepose::landmarks(raw, &crop),
            mask: blazepose::mask(logits, &crop, img.width(), img.height()),
            crop,
        }))
    }
}
