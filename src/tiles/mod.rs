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
//!   ([`crate::field::block_reach`]), in (home half-block, global index) order — the
//!   tile loads every particle within `reach` of its field blocks ("zone 1") sorted in
//!   that order, which is also the order the tile's isolation search sees, and the field
//!   takes them without sorting again;
//! * the isolation flag of a zone-1 particle depends on the particles within `R` of it, so
//!   the tile also loads a second ghost ring of `reach` blocks ("zone 2");
//! * coverage ([`crate::field::apply_coverage`]) reads the field around particles within
//!   `c·r + 2h` of the used blocks, so field blocks are computed one block further all
//!   round;
//! * [`crate::marching_cubes::stitch`] numbers vertices in global block order.
//!
//! **Out of core.** A tiled run never holds the scene: a first pass over the
//! [`ParticleSource`] checks the positions and counts particles per block; a second bins
//! them into a spill file on disk ([`spill`]), after which the source is dropped; each
//! tile then reads back the spill cells its zones overlap. Tiles run one after another,
//! each parallel inside.
//!
//! **Memory budget.** [`TileOptions::memory_budget_bytes`] picks the tile size (the largest
//! power-of-two number of blocks whose densest tile fits next to the expected output) or
//! refuses, before any work, a run whose smallest tile cannot fit. The estimate is a
//! per-particle model calibrated on real frames ([`budget`]). An untiled run whose
//! estimate leaves a quarter of it spare keeps the buffers it frees for reuse, in a
//! program that allows it ([`TileStats::kept_freed_memory`]): 9–11 % more peak memory,
//! fewer fresh pages.
//!
//! **Decimation in tiles.** With decimation requested and more than one tile, every tile
//! decimates its own piece of the marching-cubes mesh as soon as it is meshed, the
//! vertices on its border locked ([`crate::marching_cubes::stitch_range`]); the reduced
//! pieces are joined by the global key of the border vertices and one pass over the band
//! around the seams ([`crate::decimation::decimate_band`]) finishes the job. The raw
//! surface is then never whole in memory: memory follows the output. The result is
//! deterministic and independent of the thread count, but depends on the tile size;
//! without decimation the stitched marching-cubes mesh is bit-identical for every tiling.

pub mod budget;
pub mod source;
pub mod spill;

use crate::decimation::{
    decimate_band, decimate_locked, place_survivors, DecimateOptions, DecimateStats,
};
use crate::error::{Error, Result};
use crate::field::{
    apply_coverage, apply_iso_offset, block_of_half, block_reach, check_positions_from,
    compute_blocks, home_block, home_half_block, BlockRange, FieldOptions, FieldStats,
    HALF_BLOCK_EDGE,
};
use crate::grid::BlockKey;
use crate::marching_cubes::{
    march_blocks, stitch, stitch_range, BlockSurface, MarchingCubesStats, VertexKey,
};
use crate::mesh::TriMesh;
use crate::neighbors::find_isolated_sorted;
use budget::choose_tile_blocks;
pub use budget::{default_memory_budget, output_bytes_per_particle, parse_memory_size};
use glam::Vec3;
use hashbrown::{HashMap, HashSet};
use rayon::prelude::*;
pub use source::{MappedXyz, ParticleSource, SpooledXyz};
use spill::SpillFile;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// Set (by the CLI's Ctrl-C handler) to stop a run between tiles with
/// [`Error::Interrupted`]; temporary files are removed as the error unwinds.
pub static INTERRUPTED: AtomicBool = AtomicBool::new(false);

/// Error bound of collapses in tiles and in the seam pass when the decimation options set
/// none, multiples of r. Measured on `dambreak_small` frame 25 in 64-cell tiles: without
/// it 18 of 41 912 particles end up just outside the surface, with it none, at the same
/// 80 % and a lower flat-region bumpiness (0.0092 r instead of 0.0097 r); 0.05 r misses
/// the fraction on `double_dambreak`.
pub const TILE_ERROR_CAP: f32 = 0.1;

/// How the lattice is cut.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
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
    /// Seconds spent computing field blocks (with coverage).
    pub field_seconds: f64,
    /// Seconds spent in marching cubes (per-block extraction).
    pub marching_seconds: f64,
    /// Seconds spent stitching block surfaces (or decimated tile pieces) into one mesh.
    pub stitch_seconds: f64,
    /// Seconds spent decimating tiles and the seam band (0 unless decimated in tiles).
    pub decimation_seconds: f64,
}

/// The result of the field and marching-cubes stages over all tiles.
pub struct TiledSurface {
    /// The stitched mesh: marching cubes, decimated when [`TiledSurface::decimation`] is
    /// `Some`.
    pub mesh: TriMesh,
    /// Centres of isolated particles, in input order.
    pub isolated: Vec<Vec3>,
    /// Field figures summed over tiles (particles counts the field particles once).
    pub field: FieldStats,
    /// Marching-cubes figures (summed over tiles when decimated in tiles).
    pub marching_cubes: MarchingCubesStats,
    /// Decimation figures when the tiles were decimated as they were meshed.
    pub decimation: Option<DecimateStats>,
    /// Tiling figures.
    pub tiles: TileStats,
}

/// Spill cell edge, blocks: the granularity at which a tile reads back particles.
const SPILL_CELL_BLOCKS: i32 = 4;

/// Runs isolation, field and marching cubes tile by tile and stitches the result.
/// `isolation_radius` (world units) is `None` to keep isolated particles in the field;
/// `decimation` asks for decimation in tiles (used only when there is more than one
/// tile: check [`TiledSurface::decimation`]). `output_bytes_per_particle` is what the
/// surface will need after the tiles ([`output_bytes_per_particle`]), for the memory
/// budget. `on_tile(n, tiles)` is told before each tile.
pub fn reconstruct_tiled<S: ParticleSource>(
    source: S,
    field_options: &FieldOptions,
    isolation_radius: Option<f32>,
    tile_options: &TileOptions,
    decimation: Option<&DecimateOptions>,
    output_bytes_per_particle: u64,
    on_tile: &dyn Fn(usize, usize),
) -> Result<TiledSurface> {
    field_options.validate()?;
    let reach = block_reach(field_options);
    let inv_h = 1.0 / field_options.cell_size_world();
    let clock = Instant::now();
    let particle_count = source.particle_count();
    if particle_count > u32::MAX as usize {
        return Err(Error::InvalidOption {
            option: "INPUT",
            message: format!("{particle_count} particles: at most 2^32 − 1 per frame"),
        });
    }

    // Pass 1: check every position, count particles per home block.
    let mut block_counts: HashMap<BlockKey, u64> = HashMap::new();
    source.visit_chunks(&mut |first, chunk| {
        check_positions_from(first, chunk, field_options)?;
        // Counted in parallel pieces (runs of equal home blocks, then one map per piece),
        // the maps added up after: counts do not depend on the order of the additions.
        let counts = chunk
            .par_chunks(COUNT_PIECE)
            .map(|piece| {
                let mut counts: HashMap<BlockKey, u64> = HashMap::new();
                let mut homes = piece.iter().map(|p| home_block(*p, inv_h));
                let Some(mut run) = homes.next().map(|h| (h, 1u64)) else {
                    return counts;
                };
                for h in homes {
                    if h == run.0 {
                        run.1 += 1;
                    } else {
                        *counts.entry(run.0).or_default() += run.1;
                        run = (h, 1);
                    }
                }
                *counts.entry(run.0).or_default() += run.1;
                counts
            })
            .reduce(HashMap::new, add_counts);
        block_counts = add_counts(std::mem::take(&mut block_counts), counts);
        Ok(())
    })?;
    let (tile_blocks, estimated_peak_bytes) = choose_tile_blocks(
        &block_counts,
        particle_count as u64,
        reach,
        output_bytes_per_particle,
        decimation.is_some(),
        tile_options,
    )?;
    let kept_freed_memory =
        crate::allocator::keep_freed_memory(crate::allocator::may_keep_freed_memory(
            estimated_peak_bytes,
            tile_options.memory_budget_bytes,
            tile_blocks.is_some(),
        ));
    // Tiles are counted from the lowest block the field reaches, so a tile larger than
    // the scene is one tile wherever the scene lies.
    let origin = tile_origin(&block_counts, reach);
    let tile_of = |b: BlockKey| -> BlockKey {
        match tile_blocks {
            Some(t) => [0, 1, 2].map(|a| (b[a] - origin[a]).div_euclid(t)),
            None => [0, 0, 0],
        }
    };

    // Pass 2 (tiled): bin into the spill file; the source is no longer needed after it.
    // Untiled: the one tile is the whole scene, kept in memory.
    let mut stats = TileStats {
        tile_blocks: tile_blocks.unwrap_or(0) as u32,
        memory_budget_bytes: tile_options.memory_budget_bytes,
        estimated_peak_bytes,
        kept_freed_memory,
        ..TileStats::default()
    };
    let cell_of = |b: BlockKey| b.map(|c| c.div_euclid(SPILL_CELL_BLOCKS));
    let spilled: Option<SpillFile> = match tile_blocks {
        Some(_) => {
            let mut cell_counts: HashMap<BlockKey, u64> = HashMap::new();
            for (b, n) in &block_counts {
                *cell_counts.entry(cell_of(*b)).or_default() += n;
            }
            let temp = tile_options
                .temp_dir
                .clone()
                .unwrap_or_else(std::env::temp_dir);
            let spill = SpillFile::create(&temp, &cell_counts)?;
            let mut writer = spill.writer();
            source.visit_chunks(&mut |first, chunk| {
                for (k, p) in chunk.iter().enumerate() {
                    writer.push(cell_of(home_block(*p, inv_h)), *p, (first + k) as u32)?;
                }
                interrupted()
            })?;
            writer.finish()?;
            stats.spill_bytes = spill.bytes();
            Some(spill)
        }
        None => None,
    };
    let mut copied: Vec<Vec3> = Vec::new();
    let all: &[Vec3] = if spilled.is_some() {
        drop(source);
        &[]
    } else if let Some(slice) = source.as_slice() {
        slice
    } else {
        copied.reserve_exact(particle_count);
        source.visit_chunks(&mut |_, chunk| {
            copied.extend_from_slice(chunk);
            Ok(())
        })?;
        &copied
    };
    stats.spill_seconds = clock.elapsed().as_secs_f64();

    // Tiles to process: those holding a block within reach (+1 for the marching layer)
    // of a populated home block.
    let mut tiles: HashSet<BlockKey> = HashSet::new();
    if tile_blocks.is_some() {
        for b in block_counts.keys() {
            for dz in -reach - 1..=reach {
                for dy in -reach - 1..=reach {
                    for dx in -reach - 1..=reach {
                        tiles.insert(tile_of([b[0] + dx, b[1] + dy, b[2] + dz]));
                    }
                }
            }
        }
    } else if particle_count > 0 {
        tiles.insert([0, 0, 0]);
    }
    drop(block_counts);
    let mut tiles: Vec<BlockKey> = tiles.into_iter().collect();
    tiles.sort_unstable_by_key(|k| [k[2], k[1], k[0]]);
    stats.tiles = tiles.len();
    let decimation = decimation.filter(|_| tile_blocks.is_some());

    // Each tile must reach the fraction on its own; the error cap keeps a tile of mostly
    // curved surface from forcing large collapses to get there (the seam pass, capped
    // too, makes up the rest where it can).
    let tile_decimation = decimation
        .map(|d| DecimateOptions {
            max_error: d
                .max_error
                .or(Some(TILE_ERROR_CAP * field_options.particle_radius)),
            ..d.clone()
        })
        .unwrap_or_default();
    let mut surfaces: Vec<BlockSurface> = Vec::new();
    let mut joined = JoinedPieces::default();
    let mut isolated: Vec<(u32, Vec3)> = Vec::new();
    let mut field_stats = FieldStats::default();
    let mut mc_stats = MarchingCubesStats::default();
    let mut decimate_stats = DecimateStats::default();
    // Particles of the current tile: (home half-block, input index, position).
    let mut loaded: Vec<(BlockKey, u32, Vec3)> = Vec::new();
    for (n, &tile) in tiles.iter().enumerate() {
        interrupted()?;
        on_tile(n, tiles.len());
        let clock = Instant::now();
        let own = match tile_blocks {
            Some(t) => BlockRange {
                lo: [0, 1, 2].map(|a| origin[a] + tile[a] * t),
                hi: [0, 1, 2].map(|a| origin[a] + tile[a] * t + t - 1),
            },
            None => BlockRange {
                lo: [i32::MIN / 4; 3],
                hi: [i32::MAX / 4; 3],
            },
        };
        // Field blocks: the marching layer above, plus one block all round for coverage
        // (uncovered particles within c·r + 2h of the blocks whose values are used).
        let field_range = own.grown(1, 2);
        let zone1 = field_range.grown(reach, reach);
        let zone2 = zone1.grown(reach, reach);

        // Load zone 2 in the canonical order (home half-block, input index): spatially
        // coherent, the same in every tiling, and the field's own summation order, so the
        // field takes its particles as they come, with their home half-blocks.
        let home_of = |p: &Vec3| home_half_block(*p, inv_h);
        match &spilled {
            Some(spill) => {
                let mut records = Vec::new();
                spill.read_cells(cell_of(zone2.lo), cell_of(zone2.hi), &mut records)?;
                let mut homes: Vec<BlockKey> = records.par_iter().map(|r| home_of(&r.0)).collect();
                // The spill cells reach past zone 2: keep the records (and homes) inside it.
                let in_zone2 = |h: &BlockKey| zone2.contains(block_of_half(*h));
                let mut record_homes = homes.iter();
                records.retain(|_| record_homes.next().is_some_and(in_zone2));
                homes.retain(in_zone2);
                load_in_canonical_order(&homes, |k| records[k], &mut loaded);
            }
            None => {
                let homes: Vec<BlockKey> = all.par_iter().map(home_of).collect();
                load_in_canonical_order(&homes, |i| (all[i], i as u32), &mut loaded);
            }
        }
        stats.max_tile_particles = stats.max_tile_particles.max(loaded.len());
        let local: Vec<Vec3> = loaded.iter().map(|r| r.2).collect();

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
                find_isolated_sorted(&local, &halves, half_edge, radius, &in_zone1)
            }
            None => vec![false; local.len()],
        };
        let mut field_particles = Vec::new();
        for (k, &(h, gi, p)) in loaded.iter().enumerate() {
            if lonely[k] {
                if own.contains(block_of_half(h)) {
                    isolated.push((gi, p));
                }
            } else if in_zone1[k] {
                field_particles.push(p);
            }
        }
        drop(local);
        stats.neighbour_seconds += clock.elapsed().as_secs_f64();
        let clock = Instant::now();
        let (mut field, fs) = compute_blocks(&field_particles, field_options, Some(field_range));
        field_stats.uncovered_particles +=
            apply_coverage(&mut field, &field_particles, field_options, Some(own));
        apply_iso_offset(&mut field, field_options);
        stats.max_tile_field_bytes = stats.max_tile_field_bytes.max(fs.block_bytes);
        field_stats.blocks += fs.blocks;
        field_stats.vertices_in_band += fs.vertices_in_band;
        field_stats.block_bytes = field_stats.block_bytes.max(fs.block_bytes);
        drop(field_particles);
        stats.field_seconds += clock.elapsed().as_secs_f64();
        let clock = Instant::now();
        match decimation {
            None => {
                let tile_surfaces = march_blocks(&field, Some(own));
                drop(field);
                surfaces.extend(tile_surfaces);
                stats.marching_seconds += clock.elapsed().as_secs_f64();
            }
            Some(_) => {
                // The tile's own blocks and the layer above (owners of its upper border
                // vertices), as one mesh whose border vertices are keyed.
                let tile_surfaces = march_blocks(&field, Some(own.grown(0, 1)));
                drop(field);
                let piece = stitch_range(&tile_surfaces, own);
                drop(tile_surfaces);
                mc_stats.triangles += piece.mesh.triangle_count();
                stats.marching_seconds += clock.elapsed().as_secs_f64();
                let clock = Instant::now();
                let tile_stats = decimate_piece(piece, &tile_decimation, &mut joined);
                decimate_stats.add_work(&tile_stats);
                decimate_stats.regions += 1;
                stats.decimation_seconds += clock.elapsed().as_secs_f64();
            }
        }
    }
    drop(spilled);
    drop(loaded);

    let clock = Instant::now();
    let (mesh, decimation_stats) = match decimation {
        None => {
            stats.surface_bytes = surfaces.iter().map(|s| s.memory_bytes()).sum();
            let (mesh, mcs) = stitch(surfaces);
            mc_stats = mcs;
            stats.stitch_seconds = clock.elapsed().as_secs_f64();
            (mesh, None)
        }
        Some(options) => {
            let mut mesh = TriMesh {
                positions: joined.positions,
                triangles: joined.triangles,
                normals: Vec::new(),
                attributes: Vec::new(),
            };
            drop(joined.seam_index);
            let target = options.target_triangles(mc_stats.triangles);
            let band = decimate_band(
                &mut mesh,
                &joined.was_seam,
                target,
                tile_decimation.max_error,
            );
            decimate_stats.add_work(&band);
            decimate_stats.triangles_before = mc_stats.triangles;
            decimate_stats.triangles_after = mesh.triangle_count();
            stats.decimation_seconds += clock.elapsed().as_secs_f64();
            (mesh, Some(decimate_stats))
        }
    };

    isolated.sort_unstable_by_key(|r| r.0);
    field_stats.particles = particle_count - isolated.len();
    Ok(TiledSurface {
        mesh,
        isolated: isolated.into_iter().map(|r| r.1).collect(),
        field: field_stats,
        marching_cubes: mc_stats,
        decimation: decimation_stats,
        tiles: stats,
    })
}

/// Particles per piece of the parallel count of home blocks.
const COUNT_PIECE: usize = 1 << 14;

/// Replaces `loaded` with the particles that `particle(k)` gives (position, input index),
/// each with its home half-block `homes[k]`, in the canonical order (home half-block,
/// input index). The home half-blocks are sorted by a stable radix sort; equal ones keep
/// the order of `particle`, which is by input index except perhaps for spilled records,
/// whose runs are then put in input order.
fn load_in_canonical_order(
    homes: &[BlockKey],
    particle: impl Fn(usize) -> (Vec3, u32) + Sync,
    loaded: &mut Vec<(BlockKey, u32, Vec3)>,
) {
    let order = crate::grid::sort_by_key_zyx(homes);
    loaded.clear();
    loaded.par_extend(order.par_iter().map(|&k| {
        let (p, i) = particle(k as usize);
        (homes[k as usize], i, p)
    }));
    loaded
        .par_chunk_by_mut(|a, b| a.0 == b.0)
        .filter(|run| !run.is_sorted_by_key(|r| r.1))
        .for_each(|run| run.sort_unstable_by_key(|r| r.1));
}

/// The sum of two maps of counts (the larger one is kept and the other added to it).
fn add_counts(a: HashMap<BlockKey, u64>, b: HashMap<BlockKey, u64>) -> HashMap<BlockKey, u64> {
    let (mut big, small) = if a.len() >= b.len() { (a, b) } else { (b, a) };
    for (k, n) in small {
        *big.entry(k).or_default() += n;
    }
    big
}

/// [`Error::Interrupted`] once [`INTERRUPTED`] is set (checked between tiles and stages).
pub fn interrupted() -> Result<()> {
    if INTERRUPTED.load(Ordering::Relaxed) {
        Err(Error::Interrupted)
    } else {
        Ok(())
    }
}

/// Decimated tile pieces joined so far.
#[derive(Default)]
struct JoinedPieces {
    positions: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    /// Per vertex: it lay on a tile border (it stayed locked in its tiles).
    was_seam: Vec<bool>,
    /// Border vertex → its index.
    seam_index: HashMap<VertexKey, u32>,
}

/// Decimates one tile's piece with its border locked, to the options' fraction of its
/// triangles, and joins the result.
fn decimate_piece(
    piece: crate::marching_cubes::RangeMesh,
    options: &DecimateOptions,
    joined: &mut JoinedPieces,
) -> DecimateStats {
    let mut mesh = piece.mesh;
    let locked: Vec<bool> = piece.seam_keys.iter().map(Option::is_some).collect();
    let target = options.target_triangles(mesh.triangle_count());
    // Border vertices keep their exact input position (decimation rescales internally).
    let original = mesh.positions.clone();
    let (stats, remap) = decimate_locked(&mut mesh, target, options.max_error, &locked);
    let (seam_index, was_seam) = (&mut joined.seam_index, &mut joined.was_seam);
    let output_of = place_survivors(
        &mesh,
        &remap,
        |old, positions| {
            piece.seam_keys[old].map(|key| {
                *seam_index.entry(key).or_insert_with(|| {
                    positions.push(original[old]);
                    was_seam.push(true);
                    (positions.len() - 1) as u32
                })
            })
        },
        &mut joined.positions,
    );
    // The piece's own vertices, appended after its new border vertices.
    joined.was_seam.resize(joined.positions.len(), false);
    joined.triangles.extend(
        mesh.triangles
            .iter()
            .map(|t| t.map(|v| output_of[v as usize])),
    );
    stats
}

/// The lowest block any tile processes: the lowest populated block, less the field's
/// reach and the marching layer.
pub(crate) fn tile_origin(block_counts: &HashMap<BlockKey, u64>, reach: i32) -> BlockKey {
    block_counts
        .keys()
        .fold([i32::MAX; 3], |o, b| [0, 1, 2].map(|a| o[a].min(b[a])))
        .map(|c| c.saturating_sub(reach + 1))
}

#[cfg(test)]
mod tests {
    use super::*;

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
