//! The cached artifacts, one module per kind: each owns its files' names in its stage's
//! folder, its format, its writer and its reader. Nothing else builds a cache path or
//! parses an artifact; the stages, the exports and the tools read and write through these.
//!
//! | artifact | stage folder | files per frame |
//! |---|---|---|
//! | [`silhouettes`] | `silhouette` | `NNNNNN/<camera>.png`; method `person`: [`person`]'s `NNNNNN/person.yaml` |
//! | [`learned_background`] (method `learned`) | `learned_background/<key>` | per capture: `cameras/<camera>/{plate,share,subject,chroma}.png`, `learned.yaml` (with every file's size and hash) |
//! | [`reconstruction`] (hull) | `visual_hull` | `NNNNNN.ply`, `NNNNNN.grid`, `NNNNNN.band` |
//! | [`reconstruction`] (refined) | `graphcut` | `NNNNNN.ply`, `NNNNNN.grid` |
//! | [`observation`] | `reliability` | `NNNNNN.ply`, `NNNNNN.obs` |
//! | [`body_model`] | `model` | `model.hpm`, `model.ply` (reference frame) |
//! | [`tracked_surface`] | `surface` | `NNNNNN.ply`, `NNNNNN.track.yaml` |
//! | fitted frame ([`crate::stages::fit`], [`fitted`]) | `fit` | see there |

use crate::error::Result;
use std::path::Path;

pub mod body_model;
pub mod fitted;
pub mod learned_background;
pub mod observation;
pub mod person;
pub mod reconstruction;
pub mod silhouettes;
pub mod tracked_surface;

/// A frame's computed artifact, as a stage hands it to the runner: the runner alone writes
/// it into the stage's folder and records it in the cache.
pub trait Artifact: Send {
    /// Writes the artifact of `frame` into the stage folder `dir`; returns the files,
    /// relative to it (the last one written is the one whose presence marks it complete).
    fn write(&self, dir: &Path, frame: u32) -> Result<Vec<String>>;
}
