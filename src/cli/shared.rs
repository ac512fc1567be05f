//! The flags `reconstruct` and `archive extract` share: a USD stage's playback rate and
//! metadata, and the frame selection of a sequence.

use clap::Args;
use meniscus::io::usd::{UpAxis, UsdDroplets};
use meniscus::job::settings;

/// The playback rate of a sequence in one file, and a USD stage's metadata.
#[derive(Args)]
pub(crate) struct StageArgs {
    /// Playback rate of a `{}` sequence written into one .glb/.gltf, and the time codes
    /// per second of a USD stage, frames per second.
    #[arg(long, default_value_t = settings::DEFAULT_FPS)]
    pub(crate) fps: f64,
    /// Up axis of a USD stage output: Y (the simulators' convention) or Z.
    #[arg(long, default_value_t = UpAxis::Y)]
    pub(crate) up_axis: UpAxis,
    /// Meters in one world unit of a USD stage output (its `metersPerUnit`).
    #[arg(allow_negative_numbers = true, long, default_value_t = settings::DEFAULT_METERS_PER_UNIT)]
    pub(crate) meters_per_unit: f64,
    /// Isolated particles of a USD stage: `points` (a point cloud with widths and
    /// velocities, which renderers draw as spheres and blur) or `instancer` (a point
    /// instancer of the sphere mesh).
    #[arg(long, value_name = "points|instancer", default_value_t = UsdDroplets::Points)]
    pub(crate) usd_droplets: UsdDroplets,
}

/// Frame selection of a sequence: a range, or a list and a share as render farms give
/// them.
#[derive(Args)]
pub(crate) struct FarmArgs {
    /// First frame of a sequence (inclusive).
    #[arg(long, allow_negative_numbers = true)]
    pub(crate) start: Option<i64>,
    /// Last frame of a sequence (inclusive).
    #[arg(long, allow_negative_numbers = true)]
    pub(crate) end: Option<i64>,
    /// Frames to take, instead of --start/--end: `1-100`, `1-100:2` (every second),
    /// `1,5,7-20`; sorted, each once. Every selected frame needs a file.
    #[arg(long, value_name = "LIST", allow_hyphen_values = true, conflicts_with_all = ["start", "end"])]
    pub(crate) frames: Option<meniscus::sequence::FrameSelection>,
    /// Take every N-th frame of the selection starting at the I-th (0-based): one of N
    /// machines' share, round-robin.
    #[arg(long, value_name = "I/N")]
    pub(crate) shard: Option<meniscus::sequence::Shard>,
}

impl FarmArgs {
    pub(crate) fn choice(&self) -> meniscus::sequence::FrameChoice {
        meniscus::sequence::FrameChoice {
            start: self.start,
            end: self.end,
            frames: self.frames.clone(),
            shard: self.shard,
        }
    }
}
