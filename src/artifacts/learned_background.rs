//! The learned background plates (`silhouette.method: learned`,
//! [`crate::recon::learned_background`]): one per camera, learned once per capture from the
//! frames pipeline.yaml selects, and read by every frame's silhouettes.
//!
//! Files, under `<cache>/learned_background/<key>/` (the key: what the plates are learned
//! from, [`key`]): per camera a folder `cameras/<camera>/` (no camera name can collide with
//! another's files) holding `plate.png` (the steady colour, RGB), `share.png` (the share of
//! the frames that showed it, grey, 255 = every frame), `subject.png` (255 where the steady
//! colour is the subject's) and `chroma.png` (24 x 24, 255 where a chromaticity bin is more
//! the subject's than the room's); then `learned.yaml` (the frames used, each camera's
//! shares, and every file's size and hash), written last: the plates are complete exactly
//! when it exists and every file matches it; damaged plates are learned again. Each file
//! is written atomically.

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
const FORMAT_VERSION: u32 = 3;

/// What `learned.yaml` records.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LearnedInfo {
    /// The frames the plates were learned from.
    pub frames: Vec<u32>,
    /// Per camera, in calibration order.
    pub cameras: Vec<CameraShares>,
    /// Every plate file as written (path under the plates' folder, size, hash).
    #[serde(default)]
    pub files: Vec<FileRecord>,
}

/// One file of the plates as written.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FileRecord {
    /// Under the plates' folder, `/`-separated.
    pub path: String,
    pub bytes: u64,
    /// BLAKE3, hex.
    pub blake3: String,
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

/// The record of complete plates with `key`, if they exist and every file is as written
/// (a damaged set is removed, to be learned again).
pub fn existing(cache: &Cache, key: &str) -> Option<LearnedInfo> {
    let dir = dir(cache, key);
    let info: LearnedInfo = crate::yaml::read(&info_path(&dir)).ok()?;
    let intact = !info.files.is_empty()
        && info.files.iter().all(|f| {
            std::fs::read(dir.join(&f.path)).is_ok_and(|bytes| {
                bytes.len() as u64 == f.bytes && blake3::hash(&bytes).to_hex().as_str() == f.blake3
            })
        });
    if !intact {
        let _ = std::fs::remove_file(info_path(&dir));
        return None;
    }
    Some(info)
}

/// Camera `cam`'s file `name` under the plates' folder, `/`-separated.
fn camera_file(cam: &Camera, name: &str) -> String {
    format!("cameras/{}/{name}", cam.name)
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
    // A damaged earlier set is replaced whole.
    let _ = std::fs::remove_file(info_path(&dir));
    crate::fsutil::create_dir_all(&dir)?;
    let mut files = Vec::new();
    for (cam, l) in cameras.iter().zip(learned) {
        let (w, h) = l.plate.dimensions();
        let share = GrayImage::from_raw(
            w,
            h,
            l.share
                .iter()
                .map(|s| (s * 255.0).round().clamp(0.0, 255.0) as u8)
                .collect(),
        )
        .expect("one share per pixel");
        let bins = CHROMA_BINS as u32;
        let images = [
            ("plate.png", image::DynamicImage::ImageRgb8(l.plate.clone())),
            ("share.png", image::DynamicImage::ImageLuma8(share)),
            (
                "subject.png",
                image::DynamicImage::ImageLuma8(flags_image(w, h, &l.steady_subject)),
            ),
            (
                "chroma.png",
                image::DynamicImage::ImageLuma8(flags_image(bins, bins, &l.subject_chroma)),
            ),
        ];
        for (name, img) in images {
            let rel = camera_file(cam, name);
            let path = dir.join(&rel);
            match &img {
                image::DynamicImage::ImageRgb8(rgb) => crate::imageio::write_rgb(&path, rgb)?,
                other => crate::imageio::write_gray(&path, &other.to_luma8())?,
            }
            let bytes = std::fs::read(&path).map_err(|e| crate::error::Error::io(&path, e))?;
            files.push(FileRecord {
                path: rel,
                bytes: bytes.len() as u64,
                blake3: blake3::hash(&bytes).to_hex().to_string(),
            });
        }
    }
    let mut info = info.clone();
    info.files = files;
    let text = crate::yaml::to_string(&info)?;
    crate::fsutil::write_atomic(&info_path(&dir), text.as_bytes())
}

/// Reads camera `cam`'s learned background from the plates with `key`.
pub fn read(cache: &Cache, key: &str, cam: &Camera) -> Result<Learned> {
    let dir = dir(cache, key);
    let grey = |suffix: &str, expected: Option<&Camera>| -> Result<Vec<u8>> {
        let path = dir.join(camera_file(cam, suffix));
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
        crate::dataset::decode(&dir.join(camera_file(cam, "plate.png")), Some(cam))?.into_rgb8();
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
