//! The silhouette stage's artifact: one binary mask per camera and frame, a grey PNG
//! (255 = subject), `NNNNNN/<camera>.png` in the stage folder.

use crate::cache::Cache;
use crate::camera::Camera;
use crate::dataset::frame_stem;
use crate::error::Result;
use image::GrayImage;
use std::path::Path;

/// The stage folder's name.
pub const STAGE: &str = "silhouette";

/// A frame's mask of `camera`, relative to the stage folder.
fn file(frame: u32, camera: &str) -> String {
    format!("{}/{camera}.png", frame_stem(frame))
}

/// A frame's masks, one per camera.
pub struct Silhouettes {
    /// The cameras' names, in calibration order.
    pub cameras: Vec<String>,
    /// Their masks (255 = subject).
    pub masks: Vec<GrayImage>,
    /// Method `person`: what the person model found in each view.
    pub person: Option<super::person::PersonFrame>,
}

impl super::Artifact for Silhouettes {
    fn write(&self, dir: &Path, frame: u32) -> Result<Vec<String>> {
        let mut files = Vec::with_capacity(self.masks.len() + 1);
        if let Some(person) = &self.person {
            files.push(super::person::write(person, dir, frame)?);
        }
        for (name, mask) in self.cameras.iter().zip(&self.masks) {
            let rel = file(frame, name);
            crate::imageio::write_gray(&dir.join(&rel), mask)?;
            files.push(rel);
        }
        Ok(files)
    }
}

/// Reads a frame's masks from the cache, one per camera in calibration order.
pub fn read(cache: &Cache, frame: u32, cameras: &[Camera]) -> Result<Vec<GrayImage>> {
    let dir = cache.stage_dir(STAGE);
    cameras
        .iter()
        .map(|cam| {
            Ok(crate::dataset::decode(&dir.join(file(frame, &cam.name)), None)?.into_luma8())
        })
        .collect()
}
