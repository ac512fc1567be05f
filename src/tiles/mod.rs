//! The tiled engine: the lattice cut into cubic tiles of blocks, each reconstructed from
//! its own particles plus a ghost margin, the block surfaces stitched into one mesh.
//!
//! **Input:** particle centres (world units), field options, [`TileOptions`].
//! **Output:** the marching-cubes mesh and the isolated-particle centres — *identical*,
//! bit for bit, whatever the tile size and thread count (a tile larger than the scene is
//! the untiled run).
//!
//! Why the result does not depend on the tiling:
//! * tile `t` owns blocks `o + T·t ..= o + T·t + T − 1` (`T` blocks per axis, `o` the
//!   lowest block the field reaches, so a tile larger than the scene is one tile); it
//!   marches its own
//!   blocks only (reading the field one block further up), and every mesh vertex is owned
//!   by exactly one block;
//! * a field block sums over particles whose home block is within `reach` blocks
//!   (`field::block_reach`), in (home half-block, global index) order — the
//!   tile loads every particle within `reach` of its field blocks ("zone 1") sorted in
//!   that order, which is also the order the tile's isolation search sees, and the field
//!   takes them without sorting again;
//! * the isolation flag of a zone-1 particle depends on the particles within `R` of it, so
//!   the tile also loads a second ghost ring of `reach` blocks ("zone 2");
//! * coverage (`field::apply_coverage`) reads the field around particles within
//!   `c·r + 2h` of the used blocks, so field blocks are computed one block further all
//!   round;
//! * `marching_cubes::stitch` numbers vertices in global block order.
//!
//! **The engine: plan → store → run → sink.**
//! * `plan_tiles` (`plan`): a first pass over the [`ParticleSource`] checks the
//!   positions and counts particles per block; the memory budget picks the tile size.
//! * `store`: where a tile's particles come from, in the canonical order: the source in
//!   memory, or (tiled, out of core) a spill file on disk (`spill`) that a second pass
//!   fills, after which the source is dropped; each tile reads back the spill cells its
//!   zones overlap. The payload (selected attributes) travels with the positions in the
//!   spill records and stays there until the attribute stage (`transfer`).
//! * `run_tiles`: the loop only: load → isolate → field → marching cubes → hand the
//!   tile's block surfaces to a `TileSink`. Tiles run one after another, each parallel
//!   inside.
//! * sinks: `StitchSink` stitches the block surfaces into one mesh;
//!   `TileDecimation` decimates each tile's piece with its border
//!   locked (the locked-seam contract is written down there).
//!
//! **Memory budget.** [`TileOptions::memory_budget_bytes`] picks the tile size (the largest
//! of a few steps, powers of two and halfway between, whose densest tile fits next to the expected output) or
//! refuses, before any work, a run whose smallest tile cannot fit. The estimate counts the
//! particles, the blocks they populate and the triangles the populated blocks on the
//! fluid's surface will carry, calibrated on a real frame and a splash of it (`budget`). An untiled run whose
//! estimate leaves a quarter of it spare keeps the buffers it frees for reuse, in a
//! program that allows it ([`TileStats::kept_freed_memory`]): 9–11 % more peak memory,
//! fewer fresh pages.
//!
//! **Decimation in tiles.** With decimation requested and more than one tile, the
//! pipeline runs the tiles into `TileDecimation`: the raw surface is
//! then never whole in memory, memory follows the output. The result is deterministic
//! and independent of the thread count, but depends on the tile size; without decimation
//! the stitched marching-cubes mesh is bit-identical for every tiling.

mod budget;
mod decimating;
pub(crate) mod plan;
pub(crate) mod spill;
pub(crate) mod store;

use crate::cancel::CancelToken;
use crate::error::Result;
use crate::field::{
    compute_tile, coverage_blocks, largest_ratio, FieldOptions, FieldStats, Sizes, TileParticles,
};
use crate::grid::{block_of_half, BlockKey, BlockRange, HALF_BLOCK_EDGE};
use crate::io::particles::ParticleSource;
use crate::marching_cubes::{march_blocks, stitch, BlockSurface, MarchingCubesStats};
use crate::mesh::TriMesh;
use crate::neighbors::find_isolated_sorted;
pub(crate) use budget::OutputCost;
pub use budget::{default_memory_budget, parse_memory_size};
pub(crate) use decimating::TileDecimation;
use glam::Vec3;
pub(crate) use plan::{plan_tiles, TilePlan};
use std::path::PathBuf;
use std::time::Instant;
pub(crate) use store::ParticleStore;

/// How the lattice is cut.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub struct TileOptions {
    /// Tile edge in marching-cubes cells, rounded up to whole 8-cell blocks. `None`: chosen
    /// from the memory budget, or one tile when there is no budget. Default `None`.
    pub tile_size_cells: Option<u32>,
    /// Memory the run may use, bytes (see the module docs). `None`: no limit. Default
    /// `None`; the CLI defaults to half the available memory.
    #[serde(default)]
    pub memory_budget_bytes: Option<u64>,
    /// Directory for the spill file of a tiled run. `None`: the system's temporary
    /// directory. Default `None`.
    #[serde(default)]
    pub temp_dir: Option<PathBuf>,
}

impl TileOptions {
    /// Tiles of `cells` marching-cubes cells per edge (rounded up to whole blocks).
    pub fn tile_size(cells: u32) -> Self {
        TileOptions {
            tile_size_cells: Some(cells),
            ..Default::default()
        }
    }

    /// Tiles chosen under a memory budget of `bytes`.
    pub fn memory_budget(bytes: u64) -> Self {
        TileOptions {
            memory_budget_bytes: Some(bytes),
            ..Default::default()
        }
    }
}

/// What the tiled run did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct TileStats {
    /// Tiles processed (tiles with at least one block to march or compute).
    pub tiles: usize,
    /// Tile edge, blocks (0 when untiled).
    pub tile_blocks: u32,
    /// Memory budget the tile size was checked against, bytes.
    pub memory_budget_bytes: Option<u64>,
    /// Estimated peak memory of the run (model of the module docs), bytes.
    pub estimated_peak_bytes: u64,
    /// Whether the run kept the big buffers it freed for reuse instead of returning them
    /// to the system: only in a program that opted in (`meniscus::tune_allocator`, as the
    /// CLI does), and only untiled with a quarter of the estimate spare under the budget
    /// (faster: fewer fresh pages; costs about a tenth more peak memory).
    pub kept_freed_memory: bool,
    /// Bytes of particle records written to the spill file (0 when untiled).
    pub spill_bytes: u64,
    /// Largest particle count one tile loaded (own + ghosts).
    pub max_tile_particles: usize,
    /// Largest field memory of one tile, bytes.
    pub max_tile_field_bytes: usize,
    /// Bytes of the gathered block surfaces before stitching (0 when decimated in tiles).
    pub surface_bytes: usize,
    /// Seconds spent on the two passes over the input (checking, counting, spilling).
    pub spill_seconds: f64,
    /// Seconds spent loading tile particles and finding isolated particles.
    pub neighbour_seconds: f64,
    /// Seconds spent computing anisotropic kernels (0 with isotropic ones).
    pub kernel_seconds: f64,
    /// Seconds spent computing field blocks (with coverage).
    pub field_seconds: f64,
    /// Seconds spent in marching cubes (per-block extraction).
    pub marching_seconds: f64,
    /// Seconds spent stitching block surfaces (or decimated tile pieces) into one mesh.
    pub stitch_seconds: f64,
    /// Seconds spent decimating tiles and the seam band (0 unless decimated in tiles).
    pub decimation_seconds: f64,
}

impl TileStats {
    /// The tiles' time as the stages of the paper's Table 1: neighbours (the passes over
    /// the input, loading the tiles' particles, isolation, and whatever `elapsed` seconds
    /// hold beyond the timed parts), kernels (with anisotropic ones), field, and marching
    /// cubes with the stitching; decimation in tiles is its own stage.
    pub(crate) fn stage_seconds(&self, elapsed: f64, kernels: bool) -> Vec<(&'static str, f64)> {
        let timed = self.kernel_seconds
            + self.field_seconds
            + self.marching_seconds
            + self.stitch_seconds
            + self.decimation_seconds;
        let mut stages = vec![("neighbours", elapsed - timed)];
        if kernels {
            stages.push(("kernels", self.kernel_seconds));
        }
        stages.push(("field", self.field_seconds));
        stages.push((
            "marching cubes",
            self.marching_seconds + self.stitch_seconds,
        ));
        stages
    }
}

/// Where the tile loop hands each tile's marching-cubes output.
pub(crate) trait TileSink {
    /// The blocks to march for a tile owning the blocks `own`.
    fn march_range(&self, own: BlockRange) -> BlockRange;
    /// Takes the block surfaces of the tile owning `own`.
    fn take(&mut self, own: BlockRange, surfaces: Vec<BlockSurface>) -> Result<()>;
}

/// The plain sink: gathers every tile's block surfaces and stitches them into one mesh,
/// bit-identical for every tiling.
#[derive(Default)]
pub(crate) struct StitchSink {
    surfaces: Vec<BlockSurface>,
}

impl StitchSink {
    /// The stitched mesh, its figures, and the bytes the block surfaces took.
    pub fn finish(self) -> (TriMesh, MarchingCubesStats, usize) {
        let bytes = self.surfaces.iter().map(|s| s.memory_bytes()).sum();
        let (mesh, stats) = stitch(self.surfaces);
        (mesh, stats, bytes)
    }
}

impl TileSink for StitchSink {
    fn march_range(&self, own: BlockRange) -> BlockRange {
        own
    }
    fn take(&mut self, _own: BlockRange, surfaces: Vec<BlockSurface>) -> Result<()> {
        self.surfaces.extend(surfaces);
        Ok(())
    }
}

/// The isolated particles, in input order.
#[derive(Default)]
pub(crate) struct Isolated {
    /// Their input indices.
    pub indices: Vec<u32>,
    /// Their centres, world units.
    pub centres: Vec<Vec3>,
}

/// What the tile loop found besides the surfaces it handed to its sink.
pub(crate) struct TileRun {
    /// The isolated particles, in input order.
    pub isolated: Isolated,
    /// Field figures summed over tiles (particles counts the field particles once).
    pub field: FieldStats,
}

/// Runs isolation, field and marching cubes tile by tile over the particles of `store`,
/// as `plan` cuts them, and hands every tile's block surfaces to `sink`.
/// `isolation_radius` (world units) is `None` to keep isolated particles in the field.
/// `sizes`: the particles' own radii by input index, when they carry them.
/// `on_tile(n, tiles)` is told before each tile; `stats` gets the loop's times.
#[allow(clippy::too_many_arguments)]
pub(crate) fn run_tiles<S: ParticleSource>(
    store: &ParticleStore<S>,
    plan: &TilePlan,
    field_options: &FieldOptions,
    sizes: Option<Sizes<'_>>,
    isolation_radius: Option<f32>,
    sink: &mut dyn TileSink,
    stats: &mut TileStats,
    cancel: &CancelToken,
    on_tile: &dyn Fn(usize, usize),
) -> Result<TileRun> {
    let reach = plan.reach;
    let mut isolated: Vec<(u32, Vec3)> = Vec::new();
    let mut field_stats = FieldStats::default();
    // Particles of the current tile: (home half-block, input index, position).
    let mut loaded: Vec<(BlockKey, u32, Vec3)> = Vec::new();
    for (n, &tile) in plan.tiles.iter().enumerate() {
        cancel.check()?;
        on_tile(n, plan.tiles.len());
        let clock = Instant::now();
        let own = plan.own_blocks(tile);
        // Field blocks: the marching layer above, plus one block all round for coverage
        // (uncovered particles within c·r + 2h of the blocks whose values are used).
        let coverage = coverage_blocks(field_options, sizes);
        let field_range = own.grown(coverage, coverage + 1);
        let zone1 = field_range.grown(reach, reach);
        let zone2 = zone1.grown(reach, reach);

        // Load zone 2 in the canonical order (home half-block, input index): spatially
        // coherent, the same in every tiling, and the field's own summation order, so the
        // field takes its particles as they come, with their home half-blocks.
        store.load(plan, zone2, &mut loaded)?;
        stats.max_tile_particles = stats.max_tile_particles.max(loaded.len());
        let local: Vec<Vec3> = loaded.iter().map(|r| r.2).collect();
        let ratios: Option<Vec<f32>> =
            sizes.map(|s| loaded.iter().map(|r| s.ratios[r.1 as usize]).collect());
        let largest = largest_ratio(sizes);

        // Flags are needed for zone 1 only; zone 2 is there to complete their neighbours.
        let in_zone1: Vec<bool> = loaded
            .iter()
            .map(|r| zone1.contains(block_of_half(r.0)))
            .collect();
        // `loaded` is sorted by home half-block: the half-blocks are the cells of the search.
        let lonely = match isolation_radius {
            Some(radius) => {
                let half_edge = (field_options.cell_size_world() * HALF_BLOCK_EDGE as f64) as f32;
                let halves: Vec<BlockKey> = loaded.iter().map(|r| r.0).collect();
                let tile_sizes = ratios.as_deref().map(|r| (r, largest));
                find_isolated_sorted(&local, &halves, half_edge, radius, tile_sizes, &in_zone1)
            }
            None => vec![false; local.len()],
        };
        let in_field: Vec<bool> = (0..loaded.len())
            .map(|k| in_zone1[k] && !lonely[k])
            .collect();
        for (k, &(h, gi, p)) in loaded.iter().enumerate() {
            if lonely[k] && own.contains(block_of_half(h)) {
                isolated.push((gi, p));
            }
        }
        let halves: Vec<BlockKey> = loaded.iter().map(|r| r.0).collect();
        if n + 1 == plan.tiles.len() {
            // The last tile (an untiled run's only one) frees the loading buffer, kept
            // otherwise for the next tile: 28 bytes a particle that would sit beside the
            // field (112 MB on 4M particles, at the run's peak).
            loaded = Vec::new();
        }
        stats.neighbour_seconds += clock.elapsed().as_secs_f64();
        // The field of the particles that enter it; the anisotropic kernels from all their
        // neighbours (zone 2 holds every particle within R of zone 1).
        let particles = TileParticles {
            positions: local,
            halves,
            in_field,
            ratios: ratios.map(|r| (r, largest)),
        };
        let tile_field = compute_tile(particles, field_options, Some(field_range), Some(own));
        stats.kernel_seconds += tile_field.kernel_seconds;
        stats.field_seconds += tile_field.field_seconds;
        let (field, fs) = (tile_field.field, tile_field.stats);
        stats.max_tile_field_bytes = stats.max_tile_field_bytes.max(fs.block_bytes);
        field_stats.uncovered_particles += fs.uncovered_particles;
        field_stats.blocks += fs.blocks;
        field_stats.vertices_in_band += fs.vertices_in_band;
        field_stats.block_bytes = field_stats.block_bytes.max(fs.block_bytes);
        let clock = Instant::now();
        let surfaces = march_blocks(&field, Some(sink.march_range(own)));
        drop(field);
        stats.marching_seconds += clock.elapsed().as_secs_f64();
        sink.take(own, surfaces)?;
    }
    drop(loaded);
    isolated.sort_unstable_by_key(|r| r.0);
    field_stats.particles = plan.particles - isolated.len();
    Ok(TileRun {
        isolated: Isolated {
            indices: isolated.iter().map(|r| r.0).collect(),
            centres: isolated.into_iter().map(|r| r.1).collect(),
        },
        field: field_stats,
    })
}

#[cfg(test)]
mod tests {
    use super::store::load_in_canonical_order;
    use super::*;
    use crate::grid::home_half_block;
    #[test]
    fn particles_load_by_home_half_block_then_input_index_in_any_record_order() {
        let mut rng = crate::test_rng::TestRng::new(11);
        // Few half-blocks (edge 4 cells of 0.1), so that many particles share one.
        let inv_h = 10.0;
        let particles: Vec<(Vec3, u32)> = (0..20_000u32)
            .map(|i| {
                let p = Vec3::new(rng.unit_f32(), rng.unit_f32(), rng.unit_f32()) * 2.0 - 1.0;
                (p, i * 3)
            })
            .collect();
        let mut expected: Vec<(BlockKey, u32, Vec3)> = particles
            .iter()
            .map(|&(p, i)| (home_half_block(p, inv_h), i, p))
            .collect();
        expected.sort_by_key(|&(h, i, _)| (h[2], h[1], h[0], i));
        // In input order (an unspilled tile) and reversed (records out of input order).
        let mut reversed = particles.clone();
        reversed.reverse();
        for records in [particles, reversed] {
            let homes: Vec<BlockKey> = records
                .iter()
                .map(|&(p, _)| home_half_block(p, inv_h))
                .collect();
            let mut loaded = vec![(BlockKey::default(), 0, Vec3::ZERO); 3];
            load_in_canonical_order(&homes, |k| records[k], &mut loaded);
            assert_eq!(loaded, expected);
        }
    }
}
