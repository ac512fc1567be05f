//! USD stages (`.usdc`, `.usda`, `.usd`): every frame of the plan appended to one stage as
//! it comes ([`UsdStageWriter`]), or, with `{}` in the output's name, a stage per frame
//! ([`write_stage`]).
//!
//! One stage is opened before any work (an unwritable path fails then, with nothing
//! written) and finished with the frames done: after the last frame, or when a failed
//! frame stops the run. A failed frame is not appended; an I/O error on the stage itself
//! stops the run at once and leaves no file (the writer removes its temporary file, an
//! existing stage is kept). `--skip-existing` is refused for one stage: it is written
//! whole, from the frames of this run, so there is nothing to resume and rewriting it
//! would drop the frames it holds. A stage per frame is skipped when its file exists.

use super::{Appended, FrameSink, Output, OutputProfile};
use crate::error::{Error, Result};
use crate::io::usd::{write_stage, UsdOptions, UsdStageWriter};
use crate::job::JobOptions;
use crate::mesh::Surface;
use crate::pipeline::{ReconstructOptions, ReconstructionStats};
use crate::sequence::Frame;
use std::path::{Path, PathBuf};

/// A USD stage for every frame, or a stage per frame.
pub(super) const OUTPUT: Output = Output {
    extensions: &["usdc", "usda", "usd"],
    noun: "USD stage",
    profile: OutputProfile {
        quantized: false,
        normals: true,
        animated: true,
        written_whole: false,
        stage_metadata: true,
    },
    per_frame: true,
    open: super::open::<UsdSink>,
};

/// Writes frames into USD stages.
pub(crate) enum UsdSink {
    /// Every frame into one stage.
    Sequence(Box<UsdStageWriter>),
    /// A stage per frame, each at its own path.
    PerFrame(UsdOptions),
}

/// The stage options of `job`.
pub(crate) fn stage_options(job: &JobOptions) -> UsdOptions {
    UsdOptions {
        fps: job.fps,
        up_axis: job.up_axis,
        meters_per_unit: job.meters_per_unit,
        normals: job.write.normals,
        format: None,
        droplets: job.usd_droplets,
    }
}

/// True when every frame of `plan` goes into one file.
fn one_file(plan: &[(Frame, PathBuf)]) -> bool {
    plan.windows(2).all(|w| w[0].1 == w[1].1)
}

impl FrameSink for UsdSink {
    /// One stage: frames of one number refused, `skip_existing` refused, the stage's
    /// temporary file created (its directory made first).
    fn open(plan: &[(Frame, PathBuf)], _: &ReconstructOptions, job: &JobOptions) -> Result<Self> {
        let options = stage_options(job);
        options.validate()?;
        for (frame, path) in plan {
            crate::io::usd::check_time_codes(path, &[frame.number])?;
        }
        let Some((_, path)) = plan.first().filter(|_| one_file(plan)) else {
            return Ok(UsdSink::PerFrame(options));
        };
        if job.skip_existing {
            return Err(Error::InvalidOption {
                option: "skip_existing",
                message: format!(
                    "{} is one USD stage, written whole from the frames of this run: there is \
                     nothing to resume, and rewriting it would drop the frames it holds \
                     (a {{}} in the output's name writes a stage per frame, which it skips)",
                    path.display()
                ),
            });
        }
        super::check_distinct_numbers(plan)?;
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        }
        Ok(UsdSink::Sequence(Box::new(UsdStageWriter::create(
            path, &options,
        )?)))
    }

    fn holds(&self, _: &Frame, output: &Path) -> bool {
        matches!(self, UsdSink::PerFrame(_)) && output.exists()
    }

    fn append(
        &mut self,
        frame: &Frame,
        output: &Path,
        surface: &Surface,
        _: &mut ReconstructionStats,
    ) -> Result<Appended> {
        let bytes = match self {
            UsdSink::Sequence(stage) => {
                stage.append_frame(frame.number, surface)?;
                0
            }
            UsdSink::PerFrame(options) => {
                write_stage(output, frame.number, surface, options)?.bytes
            }
        };
        Ok(Appended {
            bytes,
            dropped_attributes: Vec::new(),
        })
    }

    /// A failed write leaves the stage unusable.
    fn is_broken_by(&self, error: &Error) -> bool {
        match (self, error) {
            (UsdSink::Sequence(stage), Error::Io { path, .. }) => path == stage.path(),
            _ => false,
        }
    }

    /// Finished with the frames done.
    fn stop(self: Box<Self>) -> Result<()> {
        self.finish().map(|_| ())
    }

    /// A stage none of whose frames was done is not written (dropping the writer removes
    /// its temporary file).
    fn finish(self: Box<Self>) -> Result<Option<u64>> {
        match *self {
            UsdSink::Sequence(stage) if stage.frames() > 0 => Ok(Some(stage.finish()?.bytes)),
            _ => Ok(None),
        }
    }
}
