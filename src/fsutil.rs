//! File-system helpers: atomic writes (temporary file in the same folder, then rename), so
//! an interrupted run never leaves a half-written artifact under its final name.

use crate::error::{Error, Result};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

static TMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// A temporary path beside `path`, unique within this process and across processes.
fn temp_path_for(path: &Path) -> PathBuf {
    let n = TMP_COUNTER.fetch_add(1, Ordering::Relaxed);
    let name = path
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(
        ".{name}.tmp-{}-{}-{n}",
        host_name(),
        std::process::id()
    ))
}

/// This machine's host name (for temporary file names on shared caches), `localhost` when
/// unknown; characters other than letters, digits, `.` and `_` become `_`.
pub fn host_name() -> String {
    static NAME: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    NAME.get_or_init(|| {
        let mut buf = [0u8; 256];
        // SAFETY: gethostname writes at most `buf.len()` bytes into the buffer.
        let ok = unsafe { libc::gethostname(buf.as_mut_ptr().cast(), buf.len()) } == 0;
        let end = buf.iter().position(|&b| b == 0).unwrap_or(buf.len());
        let name: String = String::from_utf8_lossy(&buf[..end])
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '.' || c == '_' {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        if ok && !name.is_empty() {
            name
        } else {
            "localhost".into()
        }
    })
    .clone()
}

/// The writer (host, process id) of a temporary file name made by this module
/// (`.<name>.tmp-<host>-<pid>-<n>`), or `None` for other names.
pub fn temp_writer(file_name: &str) -> Option<(String, u32)> {
    if !file_name.starts_with('.') {
        return None;
    }
    let (_, tail) = file_name.rsplit_once(".tmp-")?;
    let mut parts = tail.rsplitn(3, '-');
    let _counter: u64 = parts.next()?.parse().ok()?;
    let pid: u32 = parts.next()?.parse().ok()?;
    Some((parts.next()?.to_string(), pid))
}

/// Creates `dir` and its parents.
pub fn create_dir_all(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| {
        // The folder itself, or one of its parents, is a file.
        match dir.ancestors().find(|a| a.exists() && !a.is_dir()) {
            Some(file) => Error::invalid(
                file,
                format!(
                    "is a file, but a folder is needed here (for {}); move the file or choose another folder",
                    dir.display()
                ),
            ),
            None => Error::io(dir, e),
        }
    })
}

/// Writes `path` atomically with whatever `fill` writes into the buffered temporary file.
/// The parent folder is created when missing.
pub fn write_atomic_with(
    path: &Path,
    fill: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<()> {
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        create_dir_all(parent)?;
    }
    let tmp = temp_path_for(path);
    let result = (|| -> std::io::Result<()> {
        let file = std::fs::File::create(&tmp)?;
        let mut writer = std::io::BufWriter::new(file);
        fill(&mut writer)?;
        // No fsync: the rename makes the write atomic for any interruption of the process
        // (including SIGKILL); durability across a power loss is not worth its cost here.
        writer.into_inner().map_err(|e| e.into_error())?;
        std::fs::rename(&tmp, path)
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(Error::io(path, e));
    }
    Ok(())
}

/// Writes `bytes` to `path` atomically.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic_with(path, |w| w.write_all(bytes))
}

/// Reads a whole text file, naming the path on error: a regular file only, read within
/// the text cap ([`crate::limits`]) whatever its metadata claims.
pub fn read_to_string(path: &Path) -> Result<String> {
    let bytes = crate::limits::read_text_file(path)?;
    String::from_utf8(bytes)
        .map_err(|_| Error::invalid(path, "is not UTF-8 text; save it as UTF-8"))
}

/// `path` made absolute with its symlinks resolved as far as it exists (the rest, not yet
/// created, appended as written), so that two spellings of one folder compare equal.
pub fn resolved(path: &Path) -> PathBuf {
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let mut existing = absolute.as_path();
    let mut rest = Vec::new();
    loop {
        if let Ok(real) = existing.canonicalize() {
            return rest.iter().rev().fold(real, |p, part| p.join(part));
        }
        match (existing.parent(), existing.file_name()) {
            (Some(parent), Some(name)) => {
                rest.push(name.to_os_string());
                existing = parent;
            }
            _ => return absolute,
        }
    }
}

/// Whether `path` is `folder` or lies inside it, however either is spelled ([`resolved`]).
pub fn lies_within(path: &Path, folder: &Path) -> bool {
    resolved(path).starts_with(resolved(folder))
}

/// Refuses a folder the pipeline writes (`what`: the key or flag naming it) that lies inside
/// one of the capture's input folders `inputs`, or contains one, or is the root or the home
/// folder: writing there could overwrite an input (a ground-truth `joints.csv`, a frame).
pub fn check_writable_place(what: &str, place: &Path, inputs: &[&Path]) -> Result<()> {
    let target = resolved(place);
    let home = std::env::var_os("HOME").map(|h| resolved(Path::new(&h)));
    if target.parent().is_none() || home.as_deref() == Some(target.as_path()) {
        return Err(Error::Usage(format!(
            "{what}: {} is the root or the home folder; give a folder of its own",
            place.display()
        )));
    }
    for &input in inputs {
        if lies_within(place, input) || lies_within(input, place) {
            return Err(Error::Usage(format!(
                "{what}: {} overlaps the capture's input folder {}; write outside the capture (for example beside pipeline.yaml)",
                place.display(),
                input.display()
            )));
        }
    }
    Ok(())
}

/// Checks a file the user names for the pipeline to write (`flag`: the option naming it,
/// e.g. `--out`): an existing target must be a regular file (never a device, a FIFO, a
/// folder or a link to one: the write would replace it) and, without `force`, is refused
/// ("pass --force"); a target that is one of `protected` (the pipeline file, the
/// calibration, an input of the command) or lies inside one of them (the sequence folder) is
/// refused whatever `force` says.
pub fn check_output_target(
    flag: &str,
    target: &Path,
    protected: &[&Path],
    force: bool,
) -> Result<()> {
    for &p in protected {
        if lies_within(target, p) {
            return Err(Error::Usage(format!(
                "{flag} {}: would overwrite {} (an input of this command or of the capture); \
                 write it elsewhere",
                target.display(),
                p.display()
            )));
        }
    }
    let Ok(meta) = std::fs::symlink_metadata(target) else {
        return Ok(());
    };
    // A link is judged by what it points to (a link to /dev/null is a device).
    let regular = if meta.file_type().is_symlink() {
        std::fs::metadata(target).is_ok_and(|m| m.is_file())
    } else {
        meta.is_file()
    };
    if !regular {
        return Err(Error::Usage(format!(
            "{flag} {}: exists and is not a regular file (a folder, device, FIFO or socket, or \
             a link to one); writing would replace it: give the path of a new or regular file",
            target.display()
        )));
    }
    if !force {
        return Err(Error::Usage(format!(
            "{flag} {}: the file exists; pass --force to replace it",
            target.display()
        )));
    }
    Ok(())
}

/// Refuses a symbolic link inside `root` (down to `depth` levels) that leads into one of
/// `inputs`: writing through it (an `output/export` pointing at the capture's ground truth)
/// would overwrite an input. `what` names the folder's key.
pub fn refuse_links_into(what: &str, root: &Path, depth: usize, inputs: &[&Path]) -> Result<()> {
    let Ok(entries) = std::fs::read_dir(root) else {
        return Ok(());
    };
    for entry in entries.flatten() {
        let path = entry.path();
        let Ok(kind) = entry.file_type() else {
            continue;
        };
        if kind.is_symlink() {
            if let Some(input) = inputs.iter().find(|i| lies_within(&path, i)) {
                return Err(Error::Usage(format!(
                    "{what}: {} is a link into the capture's input {}; writing through it would \
                     overwrite the capture: remove the link",
                    path.display(),
                    input.display()
                )));
            }
        } else if kind.is_dir() && depth > 1 {
            refuse_links_into(what, &path, depth - 1, inputs)?;
        }
    }
    Ok(())
}
