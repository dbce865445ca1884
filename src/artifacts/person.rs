//! The person model's evidence of a frame (silhouette method `person`): per camera, the
//! person found (detector score, 33 body landmarks with their visibility) or none, and how
//! many of its mask's pixels the other cameras' silhouettes do not support. One YAML file,
//! `NNNNNN/person.yaml` in the silhouette stage's folder.

use crate::cache::Cache;
use crate::dataset::frame_stem;
use crate::error::{Error, Result};
pub use crate::person::{PersonFrame, PersonView};
use std::path::Path;

/// A frame's file, relative to the silhouette stage folder.
fn file(frame: u32) -> String {
    format!("{}/person.yaml", frame_stem(frame))
}

/// Writes `person.yaml` of `frame` into the stage folder `dir`; returns its name.
pub fn write(person: &PersonFrame, dir: &Path, frame: u32) -> Result<String> {
    let rel = file(frame);
    crate::fsutil::write_atomic(&dir.join(&rel), crate::yaml::to_string(person)?.as_bytes())?;
    Ok(rel)
}

/// Reads a frame's evidence from the cache; `None` when the frame's silhouettes were not
/// made by the person model.
pub fn read(cache: &Cache, frame: u32) -> Result<Option<PersonFrame>> {
    let path = cache.stage_dir(super::silhouettes::STAGE).join(file(frame));
    if !path.is_file() {
        return Ok(None);
    }
    let text = crate::fsutil::read_to_string(&path)?;
    let frame: PersonFrame = crate::yaml::from_str(&path, &text)?;
    if frame
        .views
        .iter()
        .any(|v| v.found && v.landmarks.len() != crate::person::LANDMARKS)
    {
        return Err(Error::invalid(
            &path,
            format!(
                "a view lists other than {} landmarks: the file is damaged; remove it and \
                 run the silhouette stage again",
                crate::person::LANDMARKS
            ),
        ));
    }
    Ok(Some(frame))
}
