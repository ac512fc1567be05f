//! File-level jobs: read a particle file, reconstruct, write the surface; and whole
//! sequences of frames, chosen by [`crate::sequence::FrameChoice`] (a range, a
//! farm-style selection, a shard), each reported as done, skipped or failed
//! ([`FrameReport`]). The CLI is a thin layer over [`plan_frames`] and [`run_frames`].
//!
//! Where the frames go is a frame sink (`sink::FrameSink`), one per kind of output —
//! a mesh file per frame, one animated glTF, one `.mseq` archive, USD stages — chosen by
//! the output's extension in one place (`sink::choose`); the run itself knows no kind. A
//! new format that holds a whole sequence in one file is one new file in `job/sink/`
//! implementing the trait and defining its kind (extensions, [`OutputProfile`], opener),
//! plus its line in the chooser's list.
//!
//! [`settings`] holds the job-level settings as users state them (fps, threads, error
//! bounds, up axis, memory budget) and builds [`JobOptions`] from them for every front
//! end.

mod frame;
mod plan;
mod report;
pub mod settings;
mod sink;

pub use plan::plan_frames;
pub use report::{FrameReport, FrameStatus};
pub use settings::JobSettings;
pub use sink::{check_outputs, output_profile, OutputProfile};

use crate::attributes::AttributeSelection;
use crate::cancel::CancelToken;
use crate::error::{Error, Result};
use crate::io::mesh::MeshWriteOptions;
use crate::io::particles::ParticleFormat;
use crate::io::usd::{UpAxis, UsdDroplets};
use crate::pipeline::ReconstructOptions;
use crate::radius::RadiusAttribute;
use crate::sequence::Frame;
use sink::FrameSink;
use std::cell::RefCell;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What to do with the files of a job.
#[derive(Clone, Debug)]
pub struct JobOptions {
    /// Force an input format instead of choosing by extension.
    pub input_format: Option<ParticleFormat>,
    /// Mesh writer options.
    pub write: MeshWriteOptions,
    /// Skip frames whose output file already exists (resume a sequence); for a `.mseq`
    /// output, frames the archive already holds. Refused for one USD stage of several
    /// frames ([`crate::Error::InvalidOption`] `skip_existing`): a stage is written whole,
    /// so there is nothing to resume, and rewriting one would drop the frames it holds.
    pub skip_existing: bool,
    /// Error bound of `.mseq` outputs, world units.
    pub archive_error_bound: f64,
    /// Error bound of attributes in `.mseq` outputs, in each attribute's own units.
    pub archive_attribute_error_bound: f64,
    /// Playback rate of a sequence written into one glTF or USD stage, frames per second
    /// (a stage's `timeCodesPerSecond` and `framesPerSecond`).
    pub fps: f64,
    /// Up axis of a USD stage output (`upAxis`).
    pub up_axis: UpAxis,
    /// Meters in one world unit of a USD stage output (`metersPerUnit`).
    pub meters_per_unit: f64,
    /// How a USD stage output holds the isolated particles: points (the default) or a
    /// point instancer.
    pub usd_droplets: UsdDroplets,
    /// The point attributes carried to the surface.
    pub attributes: AttributeSelection,
    /// The point attribute holding each particle's radius (default Houdini's `pscale`
    /// when present). Every frame's radii are read and checked before the frame is
    /// reconstructed (a bad radius fails the frame, with no output); the caller takes
    /// the reference radius `r` of the options from them
    /// ([`crate::radius::ParticleRadii::median`]), and each particle is meshed with its
    /// own radius ([`crate::pipeline::reconstruct_sized`]).
    pub radius_attribute: RadiusAttribute,
    /// Stops the job between tiles, stages and frames ([`crate::Error::Interrupted`]).
    pub cancel: CancelToken,
    /// A frame that fails is reported (status [`FrameStatus::Failed`]) and the run goes
    /// on with the next; otherwise the first failure stops the run. Either way a `.mseq`
    /// output or a USD stage keeps the frames done (a failed frame is not appended) and is
    /// finished. An interruption, and an I/O error on the archive or stage itself (which
    /// leaves it unfit for more frames), always stop the run.
    pub keep_going: bool,
}

/// The callbacks of a run (see [`run_frames`]).
struct Callbacks<'a> {
    on_frame: &'a mut dyn FnMut(usize, &Frame),
    on_stage: &'a mut dyn FnMut(&str),
    on_done: &'a mut dyn FnMut(&FrameReport),
}

/// Runs every planned frame in order. `on_frame` is called before each frame with its
/// index in the plan, `on_stage` at each phase, `on_done` after each frame: done,
/// skipped or failed. A failed frame stops the run with its error unless
/// [`JobOptions::keep_going`]; then the reports say which frames failed (the caller
/// decides the exit status).
pub fn run_frames(
    plan: &[(Frame, PathBuf)],
    options: &ReconstructOptions,
    job: &JobOptions,
    on_frame: &mut dyn FnMut(usize, &Frame),
    on_stage: &mut dyn FnMut(&str),
    on_done: &mut dyn FnMut(&FrameReport),
) -> Result<Vec<FrameReport>> {
    // A panic becomes an error naming the frame being worked on (its input file), also
    // when an inner entry point (reconstruct) caught it first.
    let current: RefCell<Option<PathBuf>> = Default::default();
    let name = || {
        current
            .borrow()
            .as_ref()
            .or_else(|| plan.first().map(|(_, out)| out))
            .map(|p| p.display().to_string())
            .unwrap_or_default()
    };
    let callbacks = Callbacks {
        on_frame,
        on_stage,
        on_done,
    };
    let result = crate::error::guard(name, || {
        run_frames_unguarded(plan, options, job, &current, callbacks)
    });
    match result {
        Err(Error::Internal { input, message }) if input != name() => Err(Error::Internal {
            input: name(),
            message: format!("{input}: {message}"),
        }),
        other => other,
    }
}

/// What runs killed before they could clean up left in the temporary directory and
/// beside the outputs of `plan` (names with a PID that is no running process).
fn remove_leftovers(plan: &[(Frame, PathBuf)], options: &ReconstructOptions) {
    let temp = options
        .tiles
        .temp_dir
        .clone()
        .unwrap_or_else(std::env::temp_dir);
    crate::io::tempfiles::remove_temp_leftovers(&temp);
    crate::io::tempfiles::remove_output_leftovers(plan.iter().map(|(_, out)| out.as_path()));
}

fn run_frames_unguarded(
    plan: &[(Frame, PathBuf)],
    options: &ReconstructOptions,
    job: &JobOptions,
    current: &RefCell<Option<PathBuf>>,
    callbacks: Callbacks,
) -> Result<Vec<FrameReport>> {
    check_outputs(plan)?;
    let output = sink::choose(plan);
    remove_leftovers(plan, options);
    let mut sink = (output.open)(plan, options, job)?;
    let Callbacks {
        on_frame,
        on_stage,
        on_done,
    } = callbacks;
    let mut reports = Vec::with_capacity(plan.len());
    for (i, (frame, out)) in plan.iter().enumerate() {
        if job.cancel.is_cancelled() {
            // An interruption keeps the frames done, as a failed frame does.
            sink.stop()?;
            return Err(Error::Interrupted);
        }
        *current.borrow_mut() = Some(frame.input.clone());
        on_frame(i, frame);
        if job.skip_existing && sink.holds(frame, out) {
            let report = FrameReport::not_done(frame, out, None, 0.0);
            on_done(&report);
            reports.push(report);
            continue;
        }
        let started = Instant::now();
        match write_frame(frame, out, options, job, sink.as_mut(), on_stage) {
            Ok(report) => {
                on_done(&report);
                reports.push(report);
            }
            Err(Error::Interrupted) => {
                sink.stop()?;
                return Err(Error::Interrupted);
            }
            Err(e) => {
                let seconds = started.elapsed().as_secs_f64();
                let report = FrameReport::not_done(frame, out, Some(&e), seconds);
                on_done(&report);
                if sink.is_broken_by(&e) {
                    return Err(e);
                }
                if !job.keep_going {
                    sink.stop()?;
                    return Err(e);
                }
                reports.push(report);
            }
        }
    }
    if let Some(bytes) = sink.finish()? {
        if let Some(last) = reports.last_mut() {
            last.output_bytes = bytes;
        }
    }
    Ok(reports)
}

/// Runs one frame into `sink`, its output directory made first.
fn write_frame(
    frame: &Frame,
    output: &Path,
    options: &ReconstructOptions,
    job: &JobOptions,
    sink: &mut dyn FrameSink,
    on_stage: &mut dyn FnMut(&str),
) -> Result<FrameReport> {
    if let Some(dir) = output.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    frame::run_frame(frame, output, options, job, sink, on_stage)
}

pub use crate::pipeline::peak_rss_bytes;
