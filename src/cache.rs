//! The artifact store: content keys, manifests beside artifacts, and per-frame cache locks.
//!
//! Layout: `<cache>/<stage>/<NNNNNN>.manifest.yaml` describes the artifact of one stage and
//! frame (its key and files); the files live under `<cache>/<stage>/`. Files are written
//! atomically and the manifest last, so an artifact is valid exactly when its manifest
//! exists, its key matches, and its files exist: an interrupted run leaves at worst
//! orphan files that the next run overwrites.

use crate::error::{Error, Result};
use rayon::prelude::*;
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

    /// Adds a file's content, not its path (a regular file only; hashed as it is read, so its
    /// size does not matter). Keys so depend on what the inputs hold, never on how their
    /// paths are spelled: a project moved, copied or run by an absolute path (as the Slurm
    /// scripts do) reuses its cache. Which file is which follows from the order of the calls
    /// and the calibration, which every stage that reads frames adds too.
    pub fn add_file(&mut self, path: &Path) -> Result<&mut Self> {
        let file = crate::limits::open_regular(path)?;
        let mut hasher = blake3::Hasher::new();
        hasher.update_reader(file).map_err(|e| Error::io(path, e))?;
        let digest = hasher.finalize();
        Ok(self.add("file", &digest.to_hex()))
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
    /// Each file's size and content hash as written ([`Cache::commit`] fills them in): a
    /// file whose bytes differ later is damaged, and its artifact is recomputed.
    #[serde(default)]
    pub digests: Vec<FileDigest>,
}

/// A file's size (bytes) and blake3 hash (hex).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FileDigest {
    pub bytes: u64,
    pub blake3: String,
}

impl FileDigest {
    /// The digest of the regular file at `path` (read as a stream).
    pub fn of(path: &Path) -> Result<FileDigest> {
        let file = crate::limits::open_regular(path)?;
        let mut hasher = blake3::Hasher::new();
        let bytes = std::io::copy(&mut std::io::BufReader::new(file), &mut hasher)
            .map_err(|e| Error::io(path, e))?;
        Ok(FileDigest {
            bytes,
            blake3: hasher.finalize().to_hex().to_string(),
        })
    }
}

/// State of one artifact against the key it should have.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ArtifactState {
    UpToDate,
    /// Present, but computed for other parameters or inputs.
    Stale,
    Missing,
    /// Present for this key, but a file's bytes differ from those written (truncated,
    /// overwritten) or the manifest records no digests: recomputed, never used.
    Damaged,
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
        let text = crate::fsutil::read_to_string(&path).ok()?;
        crate::yaml::from_str(&path, &text).ok()
    }

    /// Whether (stage, frame) is up to date for `key`.
    pub fn state(&self, stage: &str, frame: u32, key: &str) -> ArtifactState {
        match self.manifest(stage, frame) {
            None => ArtifactState::Missing,
            Some(m) => {
                let dir = self.stage_dir(stage);
                if m.key != key {
                    return ArtifactState::Stale;
                }
                // Absent files: missing. Present but not written by the pipeline (a link, a
                // FIFO, a folder in a file's place): damaged.
                let kinds: Vec<Option<std::fs::FileType>> = m
                    .files
                    .iter()
                    .map(|f| {
                        std::fs::symlink_metadata(dir.join(f))
                            .ok()
                            .map(|x| x.file_type())
                    })
                    .collect();
                if kinds.iter().any(|k| k.is_some_and(|k| !k.is_file())) {
                    return ArtifactState::Damaged;
                }
                if kinds.iter().any(|k| k.is_none()) {
                    return ArtifactState::Missing;
                }
                // Sizes first (cheap: a truncated file), then the contents.
                let intact = m.digests.len() == m.files.len()
                    && m.files.iter().zip(&m.digests).all(|(f, d)| {
                        std::fs::metadata(dir.join(f)).is_ok_and(|x| x.len() == d.bytes)
                    })
                    && m.files
                        .par_iter()
                        .zip(&m.digests)
                        .all(|(f, d)| FileDigest::of(&dir.join(f)).is_ok_and(|x| &x == d));
                if intact {
                    ArtifactState::UpToDate
                } else {
                    ArtifactState::Damaged
                }
            }
        }
    }

    /// Records an artifact whose files are written, with their digests: the manifest goes
    /// last.
    pub fn commit(&self, manifest: &Manifest) -> Result<()> {
        let dir = self.stage_dir(&manifest.stage);
        let digests = manifest
            .files
            .iter()
            .map(|f| FileDigest::of(&dir.join(f)))
            .collect::<Result<_>>()?;
        let manifest = Manifest {
            digests,
            ..manifest.clone()
        };
        let text = crate::yaml::to_string(&manifest)?;
        crate::fsutil::write_atomic(
            &self.manifest_path(&manifest.stage, manifest.frame),
            text.as_bytes(),
        )
    }

    /// Removes temporary files that runs on this host left behind when they were
    /// interrupted: those whose writer (the host and process id in the name, see
    /// [`crate::fsutil`]) is no longer running. Temporaries of live runs (other shards on
    /// the same cache) and of other hosts are left alone. Only the folders the cache makes
    /// are visited (the stage folders and one level below them, the silhouettes' frame
    /// folders), and symlinks are never followed nor removed.
    pub fn sweep_temporaries(&self) {
        /// Folder levels below the cache root that the cache itself creates.
        const DEPTH: usize = 2;
        fn walk(dir: &Path, host: &str, depth: usize) {
            let Ok(entries) = std::fs::read_dir(dir) else {
                return;
            };
            for e in entries.flatten() {
                let p = e.path();
                let name = e.file_name().to_string_lossy().into_owned();
                let Ok(kind) = e.file_type() else {
                    continue;
                };
                if kind.is_dir() {
                    if depth < DEPTH {
                        walk(&p, host, depth + 1);
                    }
                } else if !kind.is_file() {
                    continue;
                } else if let Some((writer_host, pid)) = crate::fsutil::temp_writer(&name) {
                    let alive = Path::new(&format!("/proc/{pid}")).exists();
                    if writer_host == host && !alive {
                        let _ = std::fs::remove_file(&p);
                    }
                }
            }
        }
        walk(&self.root, &crate::fsutil::host_name(), 0);
    }

    /// Locks `frames` of this cache for one run: a second run that wants any of them is
    /// refused until this one ends, while runs over disjoint frames proceed together (shards
    /// of one sequence on a shared cache). The locks are POSIX record locks on the bytes of
    /// `<cache>/.lock` (byte f for frame f), which network filesystems with lock support
    /// honour across machines; the system releases them when the process ends, however
    /// it ends.
    pub fn lock_frames(&self, frames: &[u32]) -> Result<CacheLock> {
        crate::fsutil::create_dir_all(&self.root)?;
        let path = self.root.join(".lock");
        let file = File::options()
            .create(true)
            .truncate(false)
            .read(true)
            .write(true)
            .open(&path)
            .map_err(|e| Error::io(&path, e))?;
        let mut sorted = frames.to_vec();
        sorted.sort_unstable();
        sorted.dedup();
        // Contiguous runs of frames, one lock call each.
        let mut ranges: Vec<(u32, u32)> = Vec::new();
        for f in sorted {
            match ranges.last_mut() {
                Some(r) if r.1 + 1 == f => r.1 = f,
                _ => ranges.push((f, f)),
            }
        }
        for (first, last) in ranges {
            if let Err(busy) = record_lock(&file, first, last) {
                return Err(match busy {
                    Some((frame, pid)) => Error::invalid(
                        &self.root,
                        format!(
                            "another pipeline run{} is using frame {frame} of this cache; wait \
                             for it to finish, run other frames (--frames), or give this run \
                             another cache folder in pipeline.yaml",
                            if pid > 0 {
                                format!(" (process {pid})")
                            } else {
                                String::new()
                            }
                        ),
                    ),
                    None => Error::io(&path, std::io::Error::last_os_error()),
                });
            }
        }
        Ok(CacheLock { _file: file })
    }
}

/// Takes a write lock on bytes `first..=last` of `file` without waiting. On refusal:
/// `Err(Some((frame, pid)))` names a locked frame and its holder (pid 0 when unknown),
/// `Err(None)` is an I/O error (in `errno`).
fn record_lock(file: &File, first: u32, last: u32) -> std::result::Result<(), Option<(u32, i64)>> {
    use std::os::fd::AsRawFd;
    // SAFETY: a zeroed `flock` is a valid value of the plain C struct.
    let mut lock: libc::flock = unsafe { std::mem::zeroed() };
    lock.l_type = libc::F_WRLCK as libc::c_short;
    lock.l_whence = libc::SEEK_SET as libc::c_short;
    lock.l_start = first as libc::off_t;
    lock.l_len = (last - first + 1) as libc::off_t;
    // SAFETY: fcntl on an open descriptor with a pointer to a live `flock`.
    if unsafe { libc::fcntl(file.as_raw_fd(), libc::F_SETLK, &lock) } == 0 {
        return Ok(());
    }
    let err = std::io::Error::last_os_error().raw_os_error();
    if err != Some(libc::EAGAIN) && err != Some(libc::EACCES) {
        return Err(None);
    }
    // Who holds it: F_GETLK rewrites `lock` with the first conflicting lock.
    // SAFETY: as above.
    if unsafe { libc::fcntl(file.as_raw_fd(), libc::F_GETLK, &mut lock) } == 0
        && lock.l_type != libc::F_UNLCK as libc::c_short
    {
        let frame = (lock.l_start.max(first as libc::off_t) as u32).min(last);
        return Err(Some((frame, lock.l_pid as i64)));
    }
    Err(Some((first, 0)))
}

/// Holds a run's cache locks while alive.
pub struct CacheLock {
    _file: File,
}
