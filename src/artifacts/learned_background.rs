//! The learned background plates (`silhouette.method: learned`,
//! [`crate::recon::learned_background`]): one per camera, learned once per capture from the
//! frames pipeline.yaml selects, and read by every frame's silhouettes.
//!
//! Files, under `<cache>/learned_background/<key>/` (the key: what the plates are learned
//! from, [`key`]): per camera `<camera>.png` (the steady colour, RGB), `<camera>.share.png`
//! (the share of the frames that showed it, grey, 255 = every frame),
//! `<camera>.subject.png` (255 where the steady colour is the subject's) and
//! `<camera>.chroma.png` (24 x 24, 255 where a chromaticity bin is more the subject's than
//! the room's); then `learned.yaml` (the frames used and each camera's shares), written
//! last: the plates are complete exactly when it exists. Each file is written atomically.

use crate::cache::{Cache, KeyBuilder};
use crate::camera::Camera;
use crate::error::Result;
use crate::recon::learned_background::{Learned, CHROMA_BINS};
use crate::recon::silhouette::SilhouetteParams;
use image::GrayImage;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The folder under the cache.
pub const FOLDER: &str = "learned_background";

/// Bumped whenever the learning or the files change.
const FORMAT_VERSION: u32 = 2;

/// What `learned.yaml` records.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LearnedInfo {
    /// The frames the plates were learned from.
    pub frames: Vec<u32>,
    /// Per camera, in calibration order.
    pub cameras: Vec<CameraShares>,
}

/// What one camera's learning found, as shares of its pixels (0..1).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CameraShares {
    pub camera: String,
    /// Pixels whose steady colour holds fewer than `silhouette.learned_min_share` of the
    /// frames.
    pub undecided: f64,
    /// Pixels where a part of the subject stays (their background never shows).
    pub never_background: f64,
    /// Pixels that changed in some frame.
    pub changed: f64,
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
        .add("min_share", &format!("{:?}", p.learned_min_share))
        .add("color_threshold", &format!("{:?}", p.color_threshold))
        .add("min_brightness", &format!("{:?}", p.min_brightness));
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

/// A 0/255 image of `flags` (row-major, `w` x `h`).
fn flags_image(w: u32, h: u32, flags: &[bool]) -> GrayImage {
    GrayImage::from_raw(
        w,
        h,
        flags.iter().map(|&f| if f { 255 } else { 0 }).collect(),
    )
    .expect("one flag per pixel")
}

/// Writes the plates (calibration order) and, last, their record.
pub fn write(
    cache: &Cache,
    key: &str,
    cameras: &[Camera],
    learned: &[Learned],
    info: &LearnedInfo,
) -> Result<()> {
    let dir = dir(cache, key);
    crate::fsutil::create_dir_all(&dir)?;
    for (cam, l) in cameras.iter().zip(learned) {
        let (w, h) = l.plate.dimensions();
        crate::imageio::write_rgb(&dir.join(format!("{}.png", cam.name)), &l.plate)?;
        let share = GrayImage::from_raw(
            w,
            h,
            l.share
                .iter()
                .map(|s| (s * 255.0).round().clamp(0.0, 255.0) as u8)
                .collect(),
        )
        .expect("one share per pixel");
        crate::imageio::write_gray(&dir.join(format!("{}.share.png", cam.name)), &share)?;
        crate::imageio::write_gray(
            &dir.join(format!("{}.subject.png", cam.name)),
            &flags_image(w, h, &l.steady_subject),
        )?;
        let bins = CHROMA_BINS as u32;
        crate::imageio::write_gray(
            &dir.join(format!("{}.chroma.png", cam.name)),
            &flags_image(bins, bins, &l.subject_chroma),
        )?;
    }
    let text = crate::yaml::to_string(info)?;
    crate::fsutil::write_atomic(&info_path(&dir), text.as_bytes())
}

/// Reads camera `cam`'s learned background from the plates with `key`.
pub fn read(cache: &Cache, key: &str, cam: &Camera) -> Result<Learned> {
    let dir = dir(cache, key);
    let grey = |suffix: &str, expected: Option<&Camera>| -> Result<Vec<u8>> {
        let path = dir.join(format!("{}.{suffix}", cam.name));
        let img = crate::dataset::decode(&path, expected)?.into_luma8();
        if expected.is_none() && img.dimensions() != (CHROMA_BINS as u32, CHROMA_BINS as u32) {
            return Err(crate::error::Error::invalid(
                &path,
                format!("is not {CHROMA_BINS} x {CHROMA_BINS}: a damaged cache (delete it)"),
            ));
        }
        Ok(img.into_raw())
    };
    let plate =
        crate::dataset::decode(&dir.join(format!("{}.png", cam.name)), Some(cam))?.into_rgb8();
    let share = grey("share.png", Some(cam))?
        .into_iter()
        .map(|v| v as f32 / 255.0)
        .collect();
    let flags = |v: Vec<u8>| v.into_iter().map(|b| b >= 128).collect();
    Ok(Learned {
        plate,
        share,
        steady_subject: flags(grey("subject.png", Some(cam))?),
        subject_chroma: flags(grey("chroma.png", None)?),
    })
}
