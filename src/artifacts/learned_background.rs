//! The learned background plates (`silhouette.method: learned`,
//! [`crate::recon::learned_background`]): one per camera, learned once per capture from the
//! frames pipeline.yaml selects, and read by every frame's silhouettes.
//!
//! Files, under `<cache>/learned_background/<key>/` (the key: what the plates are learned
//! from, [`key`]): `<camera>.png` (the plate, RGB), `<camera>.share.png` (the share of the
//! frames that showed it, grey, 255 = every frame) and `learned.yaml` (the frames used and
//! each camera's undecided share), written last: the plates are complete exactly when it
//! exists. Each file is written atomically.

use crate::cache::{Cache, KeyBuilder};
use crate::camera::Camera;
use crate::error::Result;
use crate::recon::learned_background::LearnedPlate;
use crate::recon::silhouette::SilhouetteParams;
use image::{GrayImage, RgbImage};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The folder under the cache.
pub const FOLDER: &str = "learned_background";

/// Bumped whenever the learning or the files change.
const FORMAT_VERSION: u32 = 1;

/// What `learned.yaml` records.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LearnedInfo {
    /// The frames the plates were learned from.
    pub frames: Vec<u32>,
    /// Per camera (calibration order): its name and the share of its pixels that showed no
    /// steady background in `silhouette.learned_min_share` of the frames (0..1).
    pub undecided: Vec<(String, f64)>,
}

/// The plates' key: the learning's parameters, the cameras and the content of every frame
/// learned from (`frame_files[c][k]`: camera c's k-th frame).
pub fn key(
    p: &SilhouetteParams,
    cameras: &[Camera],
    frame_files: &[Vec<PathBuf>],
) -> Result<String> {
    let mut key = KeyBuilder::new();
    key.add("format", &FORMAT_VERSION.to_string())
        .add("tolerance", &format!("{:?}", p.learned_tolerance))
        .add("min_share", &format!("{:?}", p.learned_min_share));
    for (cam, files) in cameras.iter().zip(frame_files) {
        key.add("camera", &cam.name);
        for f in files {
            key.add_file(f)?;
        }
    }
    Ok(key.finish())
}

/// The folder of the plates with `key`.
pub fn dir(cache: &Cache, key: &str) -> PathBuf {
    cache.root.join(FOLDER).join(key)
}

fn info_path(dir: &Path) -> PathBuf {
    dir.join("learned.yaml")
}

/// The record of complete plates with `key`, if they exist.
pub fn existing(cache: &Cache, key: &str) -> Option<LearnedInfo> {
    crate::yaml::read(&info_path(&dir(cache, key))).ok()
}

/// Writes the plates (calibration order) and, last, their record.
pub fn write(
    cache: &Cache,
    key: &str,
    cameras: &[Camera],
    plates: &[LearnedPlate],
    info: &LearnedInfo,
) -> Result<()> {
    let dir = dir(cache, key);
    crate::fsutil::create_dir_all(&dir)?;
    for (cam, learned) in cameras.iter().zip(plates) {
        crate::imageio::write_rgb(&dir.join(format!("{}.png", cam.name)), &learned.plate)?;
        let (w, h) = learned.plate.dimensions();
        let share = GrayImage::from_raw(
            w,
            h,
            learned
                .share
                .iter()
                .map(|s| (s * 255.0).round().clamp(0.0, 255.0) as u8)
                .collect(),
        )
        .expect("one share per pixel");
        crate::imageio::write_gray(&dir.join(format!("{}.share.png", cam.name)), &share)?;
    }
    let text = crate::yaml::to_string(info)?;
    crate::fsutil::write_atomic(&info_path(&dir), text.as_bytes())
}

/// Reads camera `cam`'s plate and per-pixel share (0..1, row-major) of the plates with `key`.
pub fn read(cache: &Cache, key: &str, cam: &Camera) -> Result<(RgbImage, Vec<f32>)> {
    let dir = dir(cache, key);
    let plate =
        crate::dataset::decode(&dir.join(format!("{}.png", cam.name)), Some(cam))?.into_rgb8();
    let share = crate::dataset::decode(&dir.join(format!("{}.share.png", cam.name)), Some(cam))?
        .into_luma8()
        .into_raw()
        .into_iter()
        .map(|v| v as f32 / 255.0)
        .collect();
    Ok((plate, share))
}
