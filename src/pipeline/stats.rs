//! What one reconstruction measured: per-stage wall times, triangle counts and peak
//! memory (the paper's Table 1 for one frame), and the stages' own figures.

use crate::cancel::CancelToken;
use crate::containment::ContainmentStats;
use crate::decimation::DecimateStats;
use crate::error::Result;
use crate::field::FieldStats;
use crate::marching_cubes::MarchingCubesStats;
use crate::mesh::TriMesh;
use crate::smoothing::SmoothStats;
use crate::tiles::TileStats;
use std::time::Instant;

/// Time and output size of one stage.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct StageTiming {
    /// Stage name.
    pub stage: String,
    /// Wall time, seconds.
    pub seconds: f64,
    /// Triangles of the fluid surface after the stage (0 before marching cubes).
    pub triangles: usize,
    /// Peak resident memory of the process at the end of the stage (Linux), bytes. The
    /// stages the tile engine runs together, tile by tile (neighbours to marching cubes),
    /// all report it at the end of the last of them.
    pub peak_rss_bytes: Option<u64>,
}

/// Everything measured while reconstructing one frame.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct ReconstructionStats {
    /// Input particles.
    pub particles: usize,
    /// Particles emitted as icospheres instead of entering the field.
    pub isolated_particles: usize,
    /// Field stage figures.
    pub field: FieldStats,
    /// Marching-cubes figures.
    pub marching_cubes: MarchingCubesStats,
    /// Tiling figures.
    pub tiles: TileStats,
    /// Decimation figures, when it ran.
    pub decimation: Option<DecimateStats>,
    /// Smoothing figures, when it ran.
    pub smoothing: Option<SmoothStats>,
    /// Containment figures, when it ran.
    pub containment: Option<ContainmentStats>,
    /// Triangles straight out of marching cubes.
    pub marching_cubes_triangles: usize,
    /// Per-stage wall times in pipeline order.
    pub stages: Vec<StageTiming>,
    /// Triangles of the final fluid surface.
    pub fluid_triangles: usize,
    /// Triangles of all isolated-particle spheres together.
    pub sphere_triangles: usize,
}

impl ReconstructionStats {
    /// Records a stage that took `seconds`.
    pub fn push_stage(&mut self, stage: &str, seconds: f64, triangles: usize) {
        self.stages.push(StageTiming {
            stage: stage.to_string(),
            seconds,
            triangles,
            peak_rss_bytes: peak_rss_bytes(),
        });
    }

    /// Sum of all stage times, seconds.
    pub fn total_seconds(&self) -> f64 {
        self.stages.iter().map(|s| s.seconds).sum()
    }

    /// A plain-text table of the stages (the paper's Table 1 for one frame).
    pub fn table(&self) -> String {
        let mut out = format!(
            "{:<18} {:>10} {:>12} {:>14}\n",
            "stage", "time [ms]", "triangles", "peak RSS [MiB]"
        );
        for s in &self.stages {
            let rss = s
                .peak_rss_bytes
                .map(|b| format!("{:.1}", b as f64 / (1 << 20) as f64))
                .unwrap_or_else(|| "-".into());
            out += &format!(
                "{:<18} {:>10.1} {:>12} {:>14}\n",
                s.stage,
                s.seconds * 1e3,
                s.triangles,
                rss
            );
        }
        out += &format!(
            "{:<18} {:>10.1} {:>12}\n",
            "total",
            self.total_seconds() * 1e3,
            self.fluid_triangles + self.sphere_triangles
        );
        out
    }
}

/// Peak resident memory of this process so far (Linux `VmHWM`), bytes.
pub fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// Runs the stages of one reconstruction: before each, checks for cancellation and tells
/// the progress callback; times it and records it in the statistics.
pub(crate) struct Recorder<'a> {
    /// What the run measured so far.
    pub stats: ReconstructionStats,
    progress: &'a dyn Fn(&str),
    cancel: &'a CancelToken,
}

impl<'a> Recorder<'a> {
    /// A recorder for a run over `particles` particles.
    pub fn new(particles: usize, progress: &'a dyn Fn(&str), cancel: &'a CancelToken) -> Self {
        Recorder {
            stats: ReconstructionStats {
                particles,
                ..Default::default()
            },
            progress,
            cancel,
        }
    }

    /// The run's cancellation token.
    pub fn cancel(&self) -> &'a CancelToken {
        self.cancel
    }

    /// The run's progress callback.
    pub fn progress_callback(&self) -> &'a dyn Fn(&str) {
        self.progress
    }

    /// Fails with [`crate::Error::Interrupted`] when the run was cancelled.
    pub fn check(&self) -> Result<()> {
        self.cancel.check()
    }

    /// Tells the progress callback what the run is doing.
    pub fn progress(&self, what: &str) {
        (self.progress)(what)
    }

    /// Runs the stage `name` on the fluid surface: checks for cancellation, tells the
    /// progress, times `run` and records the surface's triangles after it.
    pub fn stage<T>(
        &mut self,
        name: &str,
        fluid: &mut TriMesh,
        run: impl FnOnce(&mut TriMesh, &mut ReconstructionStats) -> Result<T>,
    ) -> Result<T> {
        self.check()?;
        self.progress(name);
        let clock = Instant::now();
        let out = run(fluid, &mut self.stats)?;
        self.stats
            .push_stage(name, clock.elapsed().as_secs_f64(), fluid.triangle_count());
        Ok(out)
    }
}
