//! Names and paths shown in messages: every name a user or a file supplies is printed
//! escaped, so that a control character (a newline, a terminal escape) in a camera, bone or
//! file name can never fake a line of the program's output.

use std::path::Path;

/// `text` with every control character written as its Rust escape (`\n`, `\u{1b}`); all
/// other characters unchanged.
pub fn escape_controls(text: &str) -> String {
    if !text.chars().any(char::is_control) {
        return text.to_string();
    }
    text.chars()
        .map(|c| {
            if c.is_control() {
                c.escape_debug().to_string()
            } else {
                c.to_string()
            }
        })
        .collect()
}

/// A name between single quotes, its control characters escaped.
pub fn quoted(name: &str) -> String {
    format!("'{}'", escape_controls(name))
}

/// A path as shown in messages: its display form, control characters escaped.
pub fn shown_path(path: &Path) -> String {
    escape_controls(&path.display().to_string())
}

/// A path between single quotes, control characters escaped.
pub fn quoted_path(path: &Path) -> String {
    format!("'{}'", shown_path(path))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn control_characters_are_escaped_and_nothing_else() {
        assert_eq!(escape_controls("café"), "café");
        assert_eq!(escape_controls("a\ndone: b"), "a\\ndone: b");
        assert_eq!(quoted("x\u{1b}[2J"), "'x\\u{1b}[2J'");
        assert_eq!(shown_path(Path::new("f/0\n.png")), "f/0\\n.png");
    }
}
