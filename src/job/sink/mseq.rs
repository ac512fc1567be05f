//! Every frame appended to one `.mseq` archive, new or existing ([`ArchiveWriter`]).
//!
//! Frames the archive holds already are refused before it is touched, unless
//! [`JobOptions::skip_existing`] skips them; an archive without an index (an interrupted
//! run) gets one, whether frames are appended or all are skipped. The archive stores the control mesh and
//! subdivides on decoding (a quarter of the triangles per level to store), so the
//! pipeline stops before subdivision ([`FrameSink::options`]). A failed frame is not
//! appended; the archive is finished with the frames done, and an I/O error on the
//! archive itself stops the run at once (the dropped writer cuts the partial record and
//! indexes the complete ones, as far as the disk lets it).

use super::{Appended, FrameSink, Output, OutputProfile};
use crate::archive::{ArchiveFrame, ArchiveOptions, ArchiveReader, ArchiveWriter};
use crate::error::{Error, Result};
use crate::job::JobOptions;
use crate::mesh::Surface;
use crate::pipeline::{ReconstructOptions, ReconstructionStats};
use crate::sequence::Frame;
use std::borrow::Cow;
use std::path::{Path, PathBuf};

/// One `.mseq` archive for every frame.
pub(super) const OUTPUT: Output = Output {
    extensions: &["mseq"],
    noun: "archive",
    profile: OutputProfile {
        quantized: true,
        normals: false,
        animated: false,
        written_whole: false,
        stage_metadata: false,
    },
    per_frame: false,
    open: super::open::<ArchiveSink>,
};

/// Appends frames to an archive.
pub(crate) struct ArchiveSink {
    path: PathBuf,
    /// `None` when every frame of the plan is held already and skipped: the archive is not
    /// opened for writing (nor its error bound compared); only an archive without an index
    /// gets one ([`ArchiveWriter::finish_unindexed`]).
    writer: Option<ArchiveWriter>,
    /// The frames the archive holds (for the writer, also those whose record header is
    /// damaged, kept in place).
    held: Vec<i64>,
    /// Subdivision levels left to the decoder.
    levels: u32,
}

/// The frames the archive at `path` holds, refusing those of `plan` unless they are to be
/// skipped; none when it does not exist.
fn held_frames(path: &Path, plan: &[(Frame, PathBuf)], job: &JobOptions) -> Result<Vec<i64>> {
    if !path.exists() {
        return Ok(Vec::new());
    }
    let reader = ArchiveReader::open(path)?;
    if !job.skip_existing {
        let numbers: Vec<i64> = plan.iter().map(|(f, _)| f.number).collect();
        reader.check_new_frames(&numbers)?;
    }
    Ok(reader.frames().iter().map(|f| f.number).collect())
}

/// The archive at `path` opened for appending, or created (with its directory).
fn open_writer(path: &Path, job: &JobOptions) -> Result<ArchiveWriter> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    let options = ArchiveOptions {
        attribute_error_bound: job.archive_attribute_error_bound,
        ..ArchiveOptions::new(job.archive_error_bound)
    };
    if path.exists() {
        ArchiveWriter::open_append(path, &options)
    } else {
        ArchiveWriter::create(path, &options)
    }
}

impl FrameSink for ArchiveSink {
    fn open(
        plan: &[(Frame, PathBuf)],
        options: &ReconstructOptions,
        job: &JobOptions,
    ) -> Result<Self> {
        let path = plan.first().map(|(_, out)| out.clone()).unwrap_or_default();
        if let Some((_, other)) = plan.iter().find(|(_, o)| *o != path) {
            return Err(Error::InvalidOption {
                option: "output",
                message: format!(
                    "one .mseq archive holds the whole sequence, not {} and {}",
                    path.display(),
                    other.display()
                ),
            });
        }
        let held = held_frames(&path, plan, job)?;
        let all_skipped = job.skip_existing && plan.iter().all(|(f, _)| held.contains(&f.number));
        let writer = match all_skipped {
            true => {
                // An archive holding every frame but no index (a run killed before it
                // wrote the index) is finished now.
                if path.exists() {
                    ArchiveWriter::finish_unindexed(&path)?;
                }
                None
            }
            false => Some(open_writer(&path, job)?),
        };
        Ok(ArchiveSink {
            held: writer.as_ref().map_or(held, ArchiveWriter::frame_numbers),
            path,
            writer,
            levels: options.subdivide.levels,
        })
    }

    fn holds(&self, frame: &Frame, _: &Path) -> bool {
        self.held.contains(&frame.number)
    }

    /// Subdivision deferred to the decoder (which the containment stage measures for).
    fn options<'a>(&self, options: &'a ReconstructOptions) -> Cow<'a, ReconstructOptions> {
        if self.levels == 0 {
            return Cow::Borrowed(options);
        }
        let mut deferred = options.clone();
        deferred.subdivide.levels = 0;
        deferred.deferred_subdivision = self.levels;
        Cow::Owned(deferred)
    }

    fn append(
        &mut self,
        frame: &Frame,
        _: &Path,
        surface: &Surface,
        stats: &mut ReconstructionStats,
    ) -> Result<Appended> {
        let writer = self
            .writer
            .as_mut()
            .expect("the archive is opened when a frame is to be written");
        let record = ArchiveFrame {
            fluid: &surface.fluid,
            subdivision_levels: self.levels,
            spheres: &surface.spheres,
        };
        let bytes = writer.append_frame(frame.number, &record)?;
        if self.levels > 0 {
            stats.fluid_triangles <<= 2 * self.levels;
            stats.push_stage("subdivision (on decoding)", 0.0, stats.fluid_triangles);
        }
        Ok(Appended {
            bytes,
            dropped_attributes: Vec::new(),
        })
    }

    /// A write that failed part-way may have left part of a record.
    fn is_broken_by(&self, error: &Error) -> bool {
        matches!(error, Error::Io { path, .. } if *path == self.path)
    }

    /// Finished with the frames done.
    fn stop(self: Box<Self>) -> Result<()> {
        self.finish().map(|_| ())
    }

    /// A new archive none of whose frames was done is not left behind, empty (dropping the
    /// writer removes it).
    fn finish(self: Box<Self>) -> Result<Option<u64>> {
        if let Some(writer) = self.writer {
            if writer.is_started() {
                writer.finish()?;
            }
        }
        Ok(None)
    }
}
