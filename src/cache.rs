//! The artifact store: content keys, manifests beside artifacts, and the cache lock.
//!
//! Layout: `<cache>/<stage>/<NNNNNN>.manifest.yaml` describes the artifact of one stage and
//! frame (its key and files); the files live under `<cache>/<stage>/`. Files are written
//! atomically and the manifest last, so an artifact is valid exactly when its manifest
//! exists, its key matches, and its files exist: an interrupted run leaves at worst
//! orphan files that the next run overwrites.

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::fs::File;
use std::path::{Path, PathBuf};

/// A content hash builder for cache keys (blake3, hex output).
pub struct KeyBuilder(blake3::Hasher);

impl Default for KeyBuilder {
    fn default() -> Self {
        Self::new()
    }
}

impl KeyBuilder {
    pub fn new() -> Self {
        KeyBuilder(blake3::Hasher::new())
    }

    /// Adds a labelled string (length-prefixed, so concatenations cannot collide).
    pub fn add(&mut self, label: &str, value: &str) -> &mut Self {
        for part in [label, value] {
            self.0.update(&(part.len() as u64).to_le_bytes());
            self.0.update(part.as_bytes());
        }
        self
    }

    /// Adds a file's content.
    pub fn add_file(&mut self, path: &Path) -> Result<&mut Self> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        let digest = blake3::hash(&bytes);
        Ok(self.add(&path.to_string_lossy(), &digest.to_hex()))
    }

    pub fn finish(&self) -> String {
        self.0.finalize().to_hex().to_string()
    }
}

/// What the cache holds for one stage and frame.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    pub stage: String,
    pub frame: u32,
    /// The cache key the artifact was computed for.
    pub key: String,
    pub format_version: u32,
    /// Artifact files, relative to the stage folder.
    pub files: Vec<String>,
    /// Seconds the computation took.
    pub seconds: f64,
}

/// State of one artifact against the key it should have.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ArtifactState {
    UpToDate,
    /// Present, but computed for other parameters or inputs.
    Stale,
    Missing,
}

/// The cache folder.
#[derive(Debug, Clone)]
pub struct Cache {
    pub root: PathBuf,
}

impl Cache {
    pub fn new(root: impl Into<PathBuf>) -> Cache {
        Cache { root: root.into() }
    }

    /// Folder of a stage's artifacts.
    pub fn stage_dir(&self, stage: &str) -> PathBuf {
        self.root.join(stage)
    }

    pub fn manifest_path(&self, stage: &str, frame: u32) -> PathBuf {
        self.stage_dir(stage).join(format!(
            "{}.manifest.yaml",
            crate::dataset::frame_stem(frame)
        ))
    }

    /// The manifest of (stage, frame), if present and readable (an unreadable one counts as
    /// missing and is recomputed).
    pub fn manifest(&self, stage: &str, frame: u32) -> Option<Manifest> {
        let path = self.manifest_path(stage, frame);
        let text = std::fs::read_to_string(&path).ok()?;
        crate::yaml::from_str(&path, &text).ok()
    }

    /// Whether (stage, frame) is up to date for `key`.
    pub fn state(&self, stage: &str, frame: u32, key: &str) -> ArtifactState {
        match self.manifest(stage, frame) {
            None => ArtifactState::Missing,
            Some(m) => {
                let dir = self.stage_dir(stage);
                if m.key != key {
                    ArtifactState::Stale
                } else if m.files.iter().all(|f| dir.join(f).is_file()) {
                    ArtifactState::UpToDate
                } else {
                    ArtifactState::Missing
                }
            }
        }
    }

    /// Records an artifact whose files are written: the manifest goes last.
    pub fn commit(&self, manifest: &Manifest) -> Result<()> {
        let text = crate::yaml::to_string(manifest)?;
        crate::fsutil::write_atomic(
            &self.manifest_path(&manifest.stage, manifest.frame),
            text.as_bytes(),
        )
    }

    /// Removes temporary files an interrupted run left behind (only call under the lock).
    pub fn sweep_temporaries(&self) {
        fn walk(dir: &Path) {
            let Ok(entries) = std::fs::read_dir(dir) else {
                return;
            };
            for e in entries.flatten() {
                let p = e.path();
                let name = e.file_name().to_string_lossy().into_owned();
                if p.is_dir() {
                    walk(&p);
                } else if name.starts_with('.') && name.contains(".tmp-") {
                    let _ = std::fs::remove_file(&p);
                }
            }
        }
        walk(&self.root);
    }

    /// Takes the cache's exclusive lock; a second concurrent run is refused. The lock is
    /// released when the returned guard drops or the process ends (even by SIGKILL).
    pub fn lock(&self) -> Result<CacheLock> {
        crate::fsutil::create_dir_all(&self.root)?;
        let path = self.root.join(".lock");
        let file = File::options()
            .create(true)
            .truncate(false)
            .write(true)
            .open(&path)
            .map_err(|e| Error::io(&path, e))?;
        match file.try_lock() {
            Ok(()) => Ok(CacheLock { _file: file }),
            Err(std::fs::TryLockError::WouldBlock) => Err(Error::invalid(
                &self.root,
                "another pipeline run is using this cache; wait for it to finish \
                 (or give this run another cache folder in pipeline.yaml)",
            )),
            Err(std::fs::TryLockError::Error(e)) => Err(Error::io(&path, e)),
        }
    }
}

/// Holds the cache lock while alive.
pub struct CacheLock {
    _file: File,
}
