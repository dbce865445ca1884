//! Text that goes into shell scripts and Slurm `#SBATCH` lines: one quoting function for
//! each, and one check that refuses what no quoting makes safe (control characters, which
//! would end a `#SBATCH` comment line and start a command).

use crate::error::{Error, Result};

/// Single-quotes `s` for a POSIX shell: the result is one word whatever `s` holds.
pub fn quote(s: &str) -> String {
    format!("'{}'", s.replace('\'', r"'\''"))
}

/// Quotes `s` for an `#SBATCH` option value: sbatch reads these lines itself (not through
/// a shell), honouring double quotes and backslash escapes, and taking an unquoted `#` as the
/// start of a comment. `s` must have passed [`refuse_control`].
pub fn sbatch_quote(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        if c == '"' || c == '\\' {
            out.push('\\');
        }
        out.push(c);
    }
    out.push('"');
    out
}

/// Refuses `value` (named by `what`, e.g. `--partition` or `the project path`) when it holds
/// a control character (a newline would end a `#SBATCH` line and put the rest on a line of
/// its own, run as a command).
pub fn refuse_control(what: &str, value: &str) -> Result<()> {
    if let Some(c) = value.chars().find(|c| c.is_control()) {
        return Err(Error::Usage(format!(
            "{what} {:?} contains the control character {:?}; it would go into a job script, \
             where it could start a command of its own: rename it (or move the project to a \
             folder whose path has no control characters)",
            value, c
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quoting_keeps_one_word() {
        assert_eq!(quote("a'b"), r"'a'\''b'");
        assert_eq!(sbatch_quote(r#"a "b"\c"#), r#""a \"b\"\\c""#);
        assert!(refuse_control("x", "cpu\ntouch X").is_err());
        assert!(refuse_control("x", "a $(touch P) b").is_ok());
    }
}
