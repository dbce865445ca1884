//! All YAML parsing goes through this module, so the YAML library is one file's choice
//! (serde_yaml_ng: the maintained continuation of serde_yaml's API).

use crate::error::{Error, Result};
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::path::Path;

/// Parses `text` (the content of `path`) into `T`. Errors name the file and, where the YAML
/// library knows it, the line and column, and the key (for unknown or mistyped keys).
pub fn from_str<T: DeserializeOwned>(path: &Path, text: &str) -> Result<T> {
    serde_yaml_ng::from_str(text).map_err(|e| {
        let msg = e.to_string();
        match e.location() {
            // The library's message often ends with "at line L column C" already.
            Some(loc) if !msg.contains("line") => Error::invalid(
                path,
                format!("line {} column {}: {msg}", loc.line(), loc.column()),
            ),
            _ => Error::invalid(path, msg),
        }
    })
}

/// Reads and parses a YAML file.
pub fn read<T: DeserializeOwned>(path: &Path) -> Result<T> {
    let text = crate::fsutil::read_to_string(path)?;
    from_str(path, &text)
}

/// Serializes `value` to YAML text.
pub fn to_string<T: Serialize>(value: &T) -> Result<String> {
    serde_yaml_ng::to_string(value).map_err(|e| Error::Usage(format!("YAML serialization: {e}")))
}
