//! The crate's error type: every error names the file (or key, or camera) it is about and
//! says what is wrong, so the CLI can print it as is.

use std::path::{Path, PathBuf};

/// An error with enough context for a user to act on it.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The file could not be read or written.
    #[error("{}: {err}", crate::text::shown_path(path))]
    Io { path: PathBuf, err: std::io::Error },
    /// The file was read but its content is invalid (bad YAML, bad values, bad layout).
    #[error("{}: {msg}", crate::text::shown_path(path))]
    Invalid { path: PathBuf, msg: String },
    /// A problem not tied to one file (bad command-line argument, inconsistent options).
    #[error("{0}")]
    Usage(String),
}

/// Result with the crate's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// An I/O error on `path`.
    pub fn io(path: impl AsRef<Path>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.as_ref().to_path_buf(),
            err: source,
        }
    }

    /// Invalid content in `path`.
    pub fn invalid(path: impl AsRef<Path>, msg: impl Into<String>) -> Self {
        Error::Invalid {
            path: path.as_ref().to_path_buf(),
            msg: msg.into(),
        }
    }
}

/// What a core algorithm or check refuses, in words a user can act on (the bad value and
/// the fix). It names no file: the caller knows which file or key the value came from and
/// attaches it ([`Error::invalid`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Refusal(pub String);

impl std::fmt::Display for Refusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Refusal {}

impl From<String> for Refusal {
    fn from(m: String) -> Refusal {
        Refusal(m)
    }
}

impl From<&str> for Refusal {
    fn from(m: &str) -> Refusal {
        Refusal(m.to_string())
    }
}

impl From<Refusal> for String {
    fn from(r: Refusal) -> String {
        r.0
    }
}
