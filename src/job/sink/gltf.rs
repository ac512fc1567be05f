//! The frames of a `{}` sequence in one animated `.glb`/`.gltf`: collected (fluid and
//! spheres merged) and written whole, atomically, by [`write_sequence_gltf`] when the run
//! finishes with at least one frame done; a node per frame named after its number, shown
//! from number/fps seconds (Blender's frame of that number).

use super::{Appended, FrameSink, Output, OutputProfile};
use crate::error::Result;
use crate::io::mesh::{write_sequence_gltf, MeshWriteOptions};
use crate::job::JobOptions;
use crate::mesh::{Surface, TriMesh};
use crate::pipeline::{ReconstructOptions, ReconstructionStats};
use crate::sequence::Frame;
use std::path::{Path, PathBuf};

/// One animated glTF for a `{}` sequence.
pub(super) const OUTPUT: Output = Output {
    extensions: &["glb", "gltf"],
    noun: "animated glTF",
    profile: OutputProfile {
        quantized: false,
        normals: true,
        animated: true,
        written_whole: true,
        stage_metadata: false,
    },
    per_frame: false,
    open: super::open::<AnimatedGltfSink>,
};

/// Collects the frames of an animated glTF.
pub(crate) struct AnimatedGltfSink {
    path: PathBuf,
    /// (frame number, fluid and spheres merged).
    frames: Vec<(i64, TriMesh)>,
    fps: f64,
    write: MeshWriteOptions,
}

impl FrameSink for AnimatedGltfSink {
    /// Frames of one number (`f_7`, `f_07`) are refused before any work.
    fn open(plan: &[(Frame, PathBuf)], _: &ReconstructOptions, job: &JobOptions) -> Result<Self> {
        super::check_distinct_numbers(plan)?;
        Ok(AnimatedGltfSink {
            path: plan.first().map(|(_, out)| out.clone()).unwrap_or_default(),
            frames: Vec::new(),
            fps: job.fps,
            write: job.write.clone(),
        })
    }

    /// Nothing to skip: the file is written whole.
    fn holds(&self, _: &Frame, _: &Path) -> bool {
        false
    }

    fn append(
        &mut self,
        frame: &Frame,
        _: &Path,
        surface: &Surface,
        _: &mut ReconstructionStats,
    ) -> Result<Appended> {
        self.frames.push((frame.number, surface.merged()));
        Ok(Appended::default())
    }

    fn finish(self: Box<Self>) -> Result<Option<u64>> {
        if self.frames.is_empty() {
            return Ok(None);
        }
        let written = write_sequence_gltf(&self.path, &self.frames, self.fps, &self.write)?;
        Ok(Some(written.bytes))
    }
}
