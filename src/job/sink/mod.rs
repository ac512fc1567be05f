//! Where reconstructed frames go: the [`FrameSink`] trait, one implementation per kind of
//! output, and the one place that chooses among them by the output's extension
//! ([`choose`]).
//!
//! * [`files`]: a mesh file per frame (a single file is one of these), each written
//!   atomically by [`crate::io::mesh::write_surface`]; `--skip-existing` skips the frames
//!   whose file exists.
//! * [`gltf`]: a `{}` sequence written into one `.glb`/`.gltf`: the frames are collected
//!   and written whole by [`crate::io::mesh::write_sequence_gltf`] when the run finishes.
//! * [`mseq`]: every frame appended to one `.mseq` archive ([`crate::archive::ArchiveWriter`]),
//!   new or existing; it stores the control mesh (subdivision deferred to its decoder) and is
//!   finished with the frames done when a frame fails.
//! * [`usd`]: every frame appended to one USD stage (`.usdc`, `.usda`, `.usd`) as it
//!   comes, finished with the frames done when a frame fails; with `{}` in its name, a
//!   stage per frame.
//!
//! A new format that holds a whole sequence in one file is a new file here implementing
//! [`FrameSink`] and defining its [`Output`] (extensions, [`OutputProfile`], opener), plus
//! its line in [`SEQUENCES`]. `.mseq` is not a mesh format: a single input file goes into
//! it too, and a `{}` in its name is refused. A USD stage is not a mesh format either, but
//! its sink takes a `{}` name too ([`Output::per_frame`]): a stage per frame.
//! `.glb`/`.gltf` are mesh formats: only the frames of a `{}` pattern written into one
//! path of that extension go to its sink; a single file, or a `{}` output, is a file per
//! frame. The same rule holds for a new format by whether [`MeshFormat`] knows its
//! extension.

mod files;
mod gltf;
mod mseq;
mod usd;

use super::JobOptions;
use crate::error::{Error, Result};
use crate::io::mesh::MeshFormat;
use crate::mesh::Surface;
use crate::pipeline::{ReconstructOptions, ReconstructionStats};
use crate::sequence::Frame;
use std::borrow::Cow;
use std::path::{Path, PathBuf};

/// The receiver of a run's frames, one per kind of output. A run opens it before the first
/// frame ([`Output::open`]), asks it which frames are there already, reconstructs each
/// other frame with the options it asks for and appends the surface, then finishes it
/// once; a failed frame that stops the run stops it instead. A sink dropped without
/// either (an interruption, an error of the sink's own output) must leave no partial file
/// behind, or one that holds the frames done.
pub(crate) trait FrameSink {
    /// Opens the output of `plan` (every frame's output path; the frames a kind takes,
    /// see [`choose`]) before any frame is reconstructed: reads what it holds already and
    /// refuses what it cannot take.
    fn open(
        plan: &[(Frame, PathBuf)],
        options: &ReconstructOptions,
        job: &JobOptions,
    ) -> Result<Self>
    where
        Self: Sized;

    /// True when the output holds `frame` already (its file `output` exists, or the
    /// archive has it): with [`JobOptions::skip_existing`] it is skipped.
    fn holds(&self, frame: &Frame, output: &Path) -> bool;

    /// The options to reconstruct a frame with; by default the run's.
    fn options<'a>(&self, options: &'a ReconstructOptions) -> Cow<'a, ReconstructOptions> {
        Cow::Borrowed(options)
    }

    /// Writes `frame`'s `surface` (to `output`, or into the sink's one file). `stats` are
    /// the frame's figures, for a sink that adds a stage of its own.
    fn append(
        &mut self,
        frame: &Frame,
        output: &Path,
        surface: &Surface,
        stats: &mut ReconstructionStats,
    ) -> Result<Appended>;

    /// True when a frame that failed with `error` leaves the output unfit for more frames
    /// (an I/O error on the sink's own file): the run stops at once and the sink is
    /// dropped. By default false.
    fn is_broken_by(&self, _error: &Error) -> bool {
        false
    }

    /// Ends the output when a failed frame stops the run ([`JobOptions::keep_going`]
    /// unset). By default nothing is written.
    fn stop(self: Box<Self>) -> Result<()> {
        Ok(())
    }

    /// Ends the output after the last frame. Returns the bytes of a file written whole at
    /// the end, which the run credits to its last frame's report.
    fn finish(self: Box<Self>) -> Result<Option<u64>>;
}

/// What [`FrameSink::append`] wrote.
#[derive(Debug, Default)]
pub(crate) struct Appended {
    /// Bytes written for the frame (0 when the file is written at the end).
    pub(crate) bytes: u64,
    /// Attributes the output could not hold.
    pub(crate) dropped_attributes: Vec<String>,
}

/// What an output makes of the job's options, so that a caller can say which of those it
/// was given have no effect.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub struct OutputProfile {
    /// The error bounds ([`JobOptions::archive_error_bound`] and
    /// [`JobOptions::archive_attribute_error_bound`]) quantize it.
    pub quantized: bool,
    /// It holds vertex normals ([`crate::io::mesh::MeshWriteOptions::normals`]).
    pub normals: bool,
    /// It plays at [`JobOptions::fps`].
    pub animated: bool,
    /// It is written whole at the end: no frame of it exists before (nothing for
    /// [`JobOptions::skip_existing`] to skip).
    pub written_whole: bool,
    /// It records [`JobOptions::up_axis`] and [`JobOptions::meters_per_unit`] (a USD
    /// stage's `upAxis` and `metersPerUnit`).
    pub stage_metadata: bool,
}

/// One kind of output: its file extensions, what it makes of the job's options, and its
/// sink.
pub(crate) struct Output {
    /// Extensions (lowercase, without the dot) of the one file that holds a whole
    /// sequence; none for the file per frame.
    extensions: &'static [&'static str],
    /// What the output is called in messages (`archive`).
    noun: &'static str,
    /// What it makes of the job's options.
    profile: OutputProfile,
    /// A `{}` in the output's name is a file of this kind per frame, written by its sink
    /// too; otherwise such a name is refused.
    per_frame: bool,
    /// Opens its sink ([`FrameSink::open`]).
    pub(crate) open: Opener,
}

/// [`FrameSink::open`] of one kind, boxed.
type Opener =
    fn(&[(Frame, PathBuf)], &ReconstructOptions, &JobOptions) -> Result<Box<dyn FrameSink>>;

/// [`FrameSink::open`], boxed: the opener of an [`Output`].
fn open<S: FrameSink + 'static>(
    plan: &[(Frame, PathBuf)],
    options: &ReconstructOptions,
    job: &JobOptions,
) -> Result<Box<dyn FrameSink>> {
    Ok(Box::new(S::open(plan, options, job)?))
}

/// The outputs that hold a whole sequence in one file, found by extension (the order
/// messages list them in). A new sequence format is a line here and its sink's file.
const SEQUENCES: [&Output; 3] = [&mseq::OUTPUT, &gltf::OUTPUT, &usd::OUTPUT];

/// The kind of output that holds a whole sequence in one file of `path`'s extension.
fn sequence_output(path: &Path) -> Option<&'static Output> {
    let extension = path.extension()?;
    SEQUENCES.into_iter().find(|output| {
        output
            .extensions
            .iter()
            .any(|e| extension.eq_ignore_ascii_case(e))
    })
}

/// True when a mesh writer writes `path` as one frame.
fn is_mesh_file(path: &Path) -> bool {
    MeshFormat::from_path(path).is_ok()
}

/// The kind of output of `plan`: the one place that tells the kinds apart. An extension
/// that only a sequence output knows takes every plan (its sink refuses what it cannot
/// take, or writes a file per frame: [`Output::per_frame`]); one a mesh writer knows takes
/// the frames of a `{}` pattern written into one path; anything else is a file per frame.
pub(crate) fn choose(plan: &[(Frame, PathBuf)]) -> &'static Output {
    let Some((first, out)) = plan.first() else {
        return &files::OUTPUT;
    };
    match sequence_output(out) {
        Some(output)
            if !is_mesh_file(out)
                || (!first.label.is_empty() && plan.iter().all(|(_, o)| o == out)) =>
        {
            output
        }
        _ => &files::OUTPUT,
    }
}

/// What the output of `plan` makes of the job's options (see [`OutputProfile`]).
pub fn output_profile(plan: &[(Frame, PathBuf)]) -> OutputProfile {
    choose(plan).profile
}

/// Checks that every output of `plan` has a format [`super::run_frames`] writes (before
/// any work).
pub fn check_outputs(plan: &[(Frame, PathBuf)]) -> Result<()> {
    for (_, out) in plan {
        if sequence_output(out).is_none() && !is_mesh_file(out) {
            return Err(Error::UnsupportedFormat {
                path: out.clone(),
                message: format!(
                    "unknown output extension {:?}; supported: .glb, .gltf, .ply, .obj, .vtk, .usdc, .usda, .usd (USD stage), .mseq (archive)",
                    out.extension().unwrap_or_default().to_string_lossy()
                ),
            });
        }
    }
    Ok(())
}

/// Refuses a `{}` pattern `output` that names a file only a whole sequence goes into.
pub(crate) fn check_pattern_output(output: &str) -> Result<()> {
    match sequence_output(Path::new(output)) {
        Some(kind) if !is_mesh_file(Path::new(output)) && !kind.per_frame => {
            Err(Error::InvalidOption {
                option: "output",
                message: format!(
                    "{output:?}: one .{} {} holds the whole sequence; name it without {{}}",
                    kind.extensions[0], kind.noun
                ),
            })
        }
        _ => Ok(()),
    }
}

/// Refuses a plan whose frames go into one file and share a number (`f_7` and `f_07`):
/// one file holds a frame per number.
fn check_distinct_numbers(plan: &[(Frame, PathBuf)]) -> Result<()> {
    let mut numbers: Vec<(i64, &Path)> = plan
        .iter()
        .map(|(f, _)| (f.number, f.input.as_path()))
        .collect();
    numbers.sort();
    match numbers.windows(2).find(|w| w[0].0 == w[1].0) {
        Some(pair) => Err(Error::InvalidOption {
            option: "input",
            message: format!(
                "{} and {} are both frame {}, and {} holds one frame per number",
                pair[0].1.display(),
                pair[1].1.display(),
                pair[0].0,
                plan[0].1.display()
            ),
        }),
        None => Ok(()),
    }
}

/// True when `output` (no pattern) can hold every frame of a `{}` sequence.
pub(crate) fn holds_a_sequence(output: &Path) -> bool {
    sequence_output(output).is_some()
}

/// The extensions of the outputs that hold a whole sequence, for messages: `.mseq, .glb,
/// .gltf, .usdc, .usda or .usd`.
pub(crate) fn sequence_extensions() -> String {
    let all: Vec<String> = SEQUENCES
        .iter()
        .flat_map(|output| output.extensions.iter().map(|e| format!(".{e}")))
        .collect();
    match all.split_last() {
        Some((last, [])) => last.clone(),
        Some((last, rest)) => format!("{} or {last}", rest.join(", ")),
        None => String::new(),
    }
}
