//! Frame sequences: `{}` patterns in input and output paths.
//!
//! `sim/ParticleData_Fluid_{}.bgeo` names one file per frame; `{}` stands for the frame
//! number. With a range (`--start`/`--end`, inclusive) the numbers are written plainly
//! (`7`, `10`); without one, the pattern's directory is scanned and every file whose name
//! matches (with the number written in any way, such as `0007`) is taken, in increasing
//! frame order. The output pattern receives the number exactly as the input file wrote it.

use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

/// One frame of a sequence.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Frame {
    /// Frame number.
    pub number: i64,
    /// The number as written in the input file name (keeps zero padding).
    pub label: String,
    /// Input file.
    pub input: PathBuf,
}

/// The placeholder in file patterns.
pub const PLACEHOLDER: &str = "{}";

/// True when `path` is a pattern (contains `{}`).
pub fn is_pattern(path: &str) -> bool {
    path.contains(PLACEHOLDER)
}

/// Replaces every placeholder of `pattern` with `label`.
pub fn substitute(pattern: &str, label: &str) -> PathBuf {
    PathBuf::from(pattern.replace(PLACEHOLDER, label))
}

/// The frames of an input pattern, in increasing frame order. With `start`/`end`
/// (inclusive; both or either) the range is generated, and missing files are an error;
/// without either, the directory is scanned. A pattern must contain exactly one `{}`, in
/// its file name.
pub fn frames(pattern: &str, start: Option<i64>, end: Option<i64>) -> Result<Vec<Frame>> {
    let invalid = |message: String| Error::InvalidOption {
        option: "input",
        message,
    };
    if pattern.matches(PLACEHOLDER).count() != 1 {
        return Err(invalid(format!(
            "pattern {pattern:?} must contain exactly one {{}}"
        )));
    }
    let path = Path::new(pattern);
    let file_name = path
        .file_name()
        .and_then(|f| f.to_str())
        .filter(|f| f.contains(PLACEHOLDER))
        .ok_or_else(|| invalid(format!("the {{}} of {pattern:?} must be in the file name")))?;
    let (prefix, suffix) = file_name.split_once(PLACEHOLDER).expect("checked above");
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let mut found: Vec<Frame> = Vec::new();
    if let (Some(s), Some(e)) = (start, end) {
        if s > e {
            return Err(Error::InvalidOption {
                option: "start/end",
                message: format!("start {s} is after end {e}"),
            });
        }
        for number in s..=e {
            let label = number.to_string();
            let input = substitute(pattern, &label);
            if !input.exists() {
                return Err(Error::io(
                    &input,
                    std::io::Error::new(
                        std::io::ErrorKind::NotFound,
                        format!("frame {number} of the range {s}..={e} is missing"),
                    ),
                ));
            }
            found.push(Frame {
                number,
                label,
                input,
            });
        }
        return Ok(found);
    }
    let entries = std::fs::read_dir(&dir).map_err(|e| Error::io(&dir, e))?;
    for entry in entries {
        let entry = entry.map_err(|e| Error::io(&dir, e))?;
        let name = entry.file_name();
        let Some(name) = name.to_str() else { continue };
        let Some(middle) = name
            .strip_prefix(prefix)
            .and_then(|m| m.strip_suffix(suffix))
        else {
            continue;
        };
        let digits = middle.strip_prefix('-').unwrap_or(middle);
        if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
            continue;
        }
        let Ok(number) = middle.parse::<i64>() else {
            continue;
        };
        if start.is_some_and(|s| number < s) || end.is_some_and(|e| number > e) {
            continue;
        }
        found.push(Frame {
            number,
            label: middle.to_string(),
            input: dir.join(name),
        });
    }
    found.sort_by(|a, b| (a.number, &a.label).cmp(&(b.number, &b.label)));
    if found.is_empty() {
        return Err(Error::io(
            path,
            std::io::Error::new(
                std::io::ErrorKind::NotFound,
                format!("no file in {} matches the pattern", dir.display()),
            ),
        ));
    }
    Ok(found)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_placeholder_of_an_output_pattern_is_replaced() {
        assert_eq!(
            substitute("out/{}/frame_{}.ply", "0042"),
            PathBuf::from("out/0042/frame_0042.ply")
        );
    }

    #[test]
    fn scan_sorts_numerically_and_keeps_padding() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["f_10.xyz", "f_9.xyz", "f_0002.xyz", "f_x.xyz", "g_1.xyz"] {
            std::fs::write(dir.path().join(name), b"").unwrap();
        }
        let pattern = format!("{}/f_{{}}.xyz", dir.path().display());
        let frames = frames(&pattern, None, None).unwrap();
        let labels: Vec<&str> = frames.iter().map(|f| f.label.as_str()).collect();
        assert_eq!(labels, ["0002", "9", "10"]);
        let ranged = super::frames(&pattern, Some(9), None).unwrap();
        assert_eq!(ranged.len(), 2);
        assert!(
            super::frames(&pattern, Some(9), Some(11)).is_err(),
            "frame 11 is missing"
        );
        assert_eq!(
            substitute("out/s_{}.ply", "0002"),
            PathBuf::from("out/s_0002.ply")
        );
    }

    #[test]
    fn patterns_need_one_placeholder_in_the_file_name() {
        assert!(frames("a/{}/b.xyz", None, None).is_err());
        assert!(frames("a/b_{}_{}.xyz", None, None).is_err());
        assert!(frames("a/b.xyz", None, None).is_err());
    }
}
