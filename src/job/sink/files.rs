//! A mesh file per frame (a single file is one of these): each frame written atomically
//! to its own path by [`write_surface`], in the format of its extension.

use super::{Appended, FrameSink, Output, OutputProfile};
use crate::error::Result;
use crate::io::mesh::{write_surface, MeshWriteOptions};
use crate::job::JobOptions;
use crate::mesh::Surface;
use crate::pipeline::{ReconstructOptions, ReconstructionStats};
use crate::sequence::Frame;
use std::path::{Path, PathBuf};

/// A file per frame: every plan no sequence output takes.
pub(super) const OUTPUT: Output = Output {
    extensions: &[],
    noun: "mesh file",
    profile: OutputProfile {
        quantized: false,
        normals: true,
        animated: false,
        written_whole: false,
        stage_metadata: false,
    },
    per_frame: false,
    open: super::open::<FileSink>,
};

/// Writes each frame to its own mesh file.
pub(crate) struct FileSink {
    write: MeshWriteOptions,
}

impl FrameSink for FileSink {
    fn open(_: &[(Frame, PathBuf)], _: &ReconstructOptions, job: &JobOptions) -> Result<Self> {
        Ok(FileSink {
            write: job.write.clone(),
        })
    }

    fn holds(&self, _: &Frame, output: &Path) -> bool {
        output.exists()
    }

    fn append(
        &mut self,
        _: &Frame,
        output: &Path,
        surface: &Surface,
        _: &mut ReconstructionStats,
    ) -> Result<Appended> {
        let stats = write_surface(output, surface, &self.write)?;
        Ok(Appended {
            bytes: stats.bytes,
            dropped_attributes: stats.dropped_attributes,
        })
    }

    fn finish(self: Box<Self>) -> Result<Option<u64>> {
        Ok(None)
    }
}
