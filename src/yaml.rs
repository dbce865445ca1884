//! All YAML parsing goes through this module, so the YAML library is one file's choice
//! (serde_yaml_ng: the maintained continuation of serde_yaml's API).

use crate::error::{Error, Result};
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::path::Path;

/// Parses `text` (the content of `path`) into `T`. Errors name the file and, where the YAML
/// library knows it, the line and column, and the key (for unknown or mistyped keys).
pub fn from_str<T: DeserializeOwned>(path: &Path, text: &str) -> Result<T> {
    let depth = flow_depth(text);
    if depth > MAX_FLOW_DEPTH {
        return Err(Error::invalid(
            path,
            format!(
                "brackets nest {depth} levels deep, more than the {MAX_FLOW_DEPTH} a pipeline file, calibration or skeleton needs"
            ),
        ));
    }
    serde_yaml_ng::from_str(text).map_err(|e| {
        // The library may quote the input at length (an XML file as one scalar).
        let msg = shorten(&e.to_string());
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

/// The deepest nesting of flow collections (`[...]`, `{...}`) accepted: the YAML library
/// takes time quadratic in it (200,000 levels in 400 KB took 86 s to reject).
const MAX_FLOW_DEPTH: usize = 64;

/// The deepest nesting of `[` and `{` in `text` outside quoted strings and comments (a
/// bracket inside a plain scalar counts too, which only overestimates).
fn flow_depth(text: &str) -> usize {
    let (mut depth, mut deepest) = (0usize, 0usize);
    let mut quote: Option<char> = None;
    let (mut escaped, mut comment, mut after_space) = (false, false, true);
    for c in text.chars() {
        if comment {
            comment = c != '\n';
        } else if let Some(q) = quote {
            if escaped {
                escaped = false;
            } else if q == '"' && c == '\\' {
                escaped = true;
            } else if c == q {
                quote = None;
            }
        } else {
            match c {
                '#' if after_space => comment = true,
                '"' | '\'' => quote = Some(c),
                '[' | '{' => {
                    depth += 1;
                    deepest = deepest.max(depth);
                }
                ']' | '}' => depth = depth.saturating_sub(1),
                _ => {}
            }
        }
        after_space = c.is_whitespace();
    }
    deepest
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

/// `text` as one YAML scalar, quoted where YAML would read it otherwise (`*x`, `null`,
/// `~`, `- a`, `#`...): for names written into YAML text laid out by hand (flow-style
/// rows), so that every name goes through the one serializer.
pub fn scalar(text: &str) -> String {
    let out = serde_yaml_ng::to_string(text).expect("a string always serializes");
    out.trim_end_matches('\n').to_string()
}

/// The longest text quoted from an input in a message, characters.
const MAX_QUOTED_CHARS: usize = 240;

/// `text` cut to [`MAX_QUOTED_CHARS`] characters (marked with `...`), control characters
/// escaped: for quoting an input in a message.
pub fn shorten(text: &str) -> String {
    let mut out: String = text.chars().take(MAX_QUOTED_CHARS).collect();
    if text.chars().nth(MAX_QUOTED_CHARS).is_some() {
        out += "...";
    }
    out.chars()
        .flat_map(|c| {
            if c.is_control() && c != '\n' {
                c.escape_debug().collect::<Vec<_>>()
            } else {
                vec![c]
            }
        })
        .collect()
}

#[cfg(test)]
mod scalar_tests {
    #[test]
    fn every_name_reads_back_as_itself() {
        for name in [
            "cam00",
            "*x",
            "&a",
            "!t",
            "#c",
            "[x",
            "- x",
            "|",
            "%d",
            "@x",
            ">f",
            "{x",
            "null",
            "~",
            "true",
            "1.5",
            "c<!--#1?x",
            "a: b",
            "'q'",
            "\"d\"",
            "café",
            "0x1F",
            "1e3",
        ] {
            let text = format!("name: {}\n", super::scalar(name));
            let back: std::collections::BTreeMap<String, String> =
                serde_yaml_ng::from_str(&text).unwrap_or_else(|e| panic!("{name:?}: {e}"));
            assert_eq!(back["name"], name, "{text}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flow_depth_skips_strings_and_comments() {
        assert_eq!(flow_depth("a: [[1, 2], {b: [3]}]\n"), 3);
        assert_eq!(flow_depth("a: \"[[[\" # {{{{\nb: '[[' \n"), 0);
        assert_eq!(flow_depth("a: \"\\\"[\"\nb: [1]\n"), 1);
        assert_eq!(flow_depth("url: x#[[[\n"), 3);
    }
}
