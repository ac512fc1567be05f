//! What became of each frame of a run: [`FrameReport`], as `--stats` and
//! `--json-progress` print it.

use crate::error::Error;
use crate::pipeline::{peak_rss_bytes, ReconstructionStats};
use crate::sequence::Frame;
use std::path::{Path, PathBuf};

/// What became of a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum FrameStatus {
    /// Reconstructed and written.
    Done,
    /// Not reconstructed: its output existed ([`super::JobOptions::skip_existing`]).
    Skipped,
    /// Reading, reconstructing or writing it failed ([`FrameReport::error`] says why).
    Failed,
}

/// The outcome of one frame.
#[derive(Clone, Debug, serde::Serialize)]
pub struct FrameReport {
    /// Frame number (0 for a single file).
    pub frame: i64,
    /// The frame's simulation time, when its input says it (a `.pvd` collection's
    /// `timestep`); absent from the JSON otherwise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub time: Option<f64>,
    /// Input file.
    pub input: PathBuf,
    /// Output file.
    pub output: PathBuf,
    /// Done, skipped or failed.
    pub status: FrameStatus,
    /// True when the frame was skipped because its output existed.
    pub skipped: bool,
    /// Why the frame failed (status [`FrameStatus::Failed`]).
    pub error: Option<String>,
    /// Wall time of the whole frame (read, reconstruct, write), seconds.
    pub seconds: f64,
    /// Reading time, seconds.
    pub read_seconds: f64,
    /// Pipeline figures (stages, counts).
    pub reconstruction: ReconstructionStats,
    /// Writing time, seconds.
    pub write_seconds: f64,
    /// Bytes written.
    pub output_bytes: u64,
    /// Attributes the output format could not hold (an OBJ file holds none).
    pub dropped_attributes: Vec<String>,
}

impl FrameReport {
    /// A frame that was not reconstructed: skipped, or failed with `error`.
    pub(crate) fn not_done(
        frame: &Frame,
        output: &Path,
        error: Option<&Error>,
        seconds: f64,
    ) -> Self {
        FrameReport {
            frame: frame.number,
            time: frame.time,
            input: frame.input.clone(),
            output: output.to_path_buf(),
            status: match error {
                Some(_) => FrameStatus::Failed,
                None => FrameStatus::Skipped,
            },
            skipped: error.is_none(),
            error: error.map(|e| e.to_string()),
            seconds,
            read_seconds: 0.0,
            reconstruction: ReconstructionStats::default(),
            write_seconds: 0.0,
            output_bytes: 0,
            dropped_attributes: Vec::new(),
        }
    }

    /// Triangles written: fluid surface plus isolated-particle spheres.
    pub fn triangles(&self) -> usize {
        self.reconstruction.fluid_triangles + self.reconstruction.sphere_triangles
    }

    /// What a farm manager needs of a finished frame, as one JSON object (the CLI's
    /// `--json-progress` line): `frame`, `input`, `output`, `status`, `triangles` (fluid
    /// plus spheres, `null` unless done), `seconds`, `peak_rss_bytes` (the process's peak
    /// so far) and, for a failed frame, `error`.
    pub fn progress_line(&self) -> serde_json::Value {
        let mut line = serde_json::json!({
            "frame": self.frame,
            "input": self.input,
            "output": self.output,
            "status": self.status,
            "triangles": (self.status == FrameStatus::Done).then(|| self.triangles()),
            "seconds": self.seconds,
            "peak_rss_bytes": peak_rss_bytes(),
        });
        if let Some(error) = &self.error {
            line["error"] = error.as_str().into();
        }
        if let Some(time) = self.time {
            line["time"] = time.into();
        }
        line
    }
}
