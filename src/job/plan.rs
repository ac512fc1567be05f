//! The frames of a job and where each goes: [`plan_frames`].

use super::sink;
use crate::error::{Error, Result};
use crate::sequence::{self, Frame, FrameChoice};
use std::path::{Path, PathBuf};

/// The frames of a job: a single file, or the frames of a `{}` pattern or a `.pvd`
/// collection that `choice` takes ([`sequence::choose`]). The output must be a pattern
/// exactly when the input is a sequence (or one `.mseq`, `.glb`, `.gltf` or USD stage for
/// the whole sequence).
pub fn plan_frames(
    input: &str,
    output: &str,
    choice: &FrameChoice,
) -> Result<Vec<(Frame, PathBuf)>> {
    if sequence::is_pattern(output) {
        sink::check_pattern_output(output)?;
    }
    match (sequence::is_sequence(input), sequence::is_pattern(output)) {
        (true, true) => Ok(sequence::choose(input, choice)?
            .into_iter()
            .map(|f| {
                let out = sequence::substitute(output, &f.label);
                (f, out)
            })
            .collect()),
        (false, false) => single_file(input, output, choice),
        (true, false) if sink::holds_a_sequence(Path::new(output)) => {
            Ok(sequence::choose(input, choice)?
                .into_iter()
                .map(|f| (f, PathBuf::from(output)))
                .collect())
        }
        (true, false) => Err(Error::InvalidOption {
            option: "output",
            message: format!(
                "INPUT {input:?} is a sequence {}, so OUTPUT {output:?} needs a {{}} too (or is one {} for the whole sequence)",
                if sequence::is_pattern(input) { "pattern" } else { "collection" },
                sink::sequence_extensions()
            ),
        }),
        (false, true) => Err(Error::InvalidOption {
            option: "output",
            message: format!(
                "OUTPUT {output:?} has a {{}} but INPUT {input:?} is a single file{}",
                pattern_hint(input)
            ),
        }),
    }
}

/// For an INPUT without `{}` that looks meant as a sequence (a directory, a file that does
/// not exist, a name with `#`, `*` or `?`): how to write it as one; else nothing.
fn pattern_hint(input: &str) -> String {
    let path = Path::new(input);
    let meant = path.is_dir() || !path.exists() || input.contains(['#', '*', '?']);
    if !meant {
        return String::new();
    }
    format!(
        "; a sequence is one pattern with {{}} where the frame number goes, e.g. {:?}",
        sequence::suggested_pattern(input)
    )
}

/// The plan of a single file, frame 0: nothing may choose frames of it; a directory, or
/// a missing file whose name looks like a pattern, is refused with a hint at `{}`.
fn single_file(input: &str, output: &str, choice: &FrameChoice) -> Result<Vec<(Frame, PathBuf)>> {
    let path = Path::new(input);
    if path.is_dir() || (!path.exists() && input.contains(['#', '*', '?'])) {
        let (kind, what) = match path.is_dir() {
            true => (std::io::ErrorKind::IsADirectory, "is a directory"),
            false => (std::io::ErrorKind::NotFound, "no such file"),
        };
        return Err(Error::io(
            path,
            std::io::Error::new(kind, format!("{what}{}", pattern_hint(input))),
        ));
    }
    if choice.is_given() {
        let option = if choice.frames.is_some() {
            "frames"
        } else if choice.shard.is_some() && choice.start.is_none() && choice.end.is_none() {
            "shard"
        } else {
            "start/end"
        };
        return Err(Error::InvalidOption {
            option,
            message: format!(
                "choosing frames needs a {{}} pattern in INPUT and OUTPUT; {input:?} is a single file"
            ),
        });
    }
    Ok(vec![(
        Frame {
            number: 0,
            label: String::new(),
            input: PathBuf::from(input),
            time: None,
        },
        PathBuf::from(output),
    )])
}
