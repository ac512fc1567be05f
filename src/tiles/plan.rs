//! The plan of a run: one pass over the input that checks every position and counts
//! particles per home block, then the memory model ([`super::budget`]) picks the tile
//! size and the tiles to process.

use super::budget::{choose_tile_blocks, BudgetInput};
use super::TileOptions;
use crate::cancel::CancelToken;
use crate::error::{Error, Result};
use crate::field::{block_reach, FieldOptions, Sizes};
use crate::grid::BlockKey;
use crate::grid::{check_positions, home_block, BlockRange};
use crate::io::particles::ParticleSource;
use hashbrown::{HashMap, HashSet};
use rayon::prelude::*;

/// Spill cell edge, blocks: the granularity at which a tile reads back particles.
pub(crate) const SPILL_CELL_BLOCKS: i32 = 4;

/// What the counting pass decided: the tiles, their size, and the memory estimate.
#[derive(Clone, Debug)]
pub(crate) struct TilePlan {
    /// Particles in the input.
    pub particles: usize,
    /// Floats of payload per particle (the selected attributes).
    pub payload_width: usize,
    /// Tile edge, blocks; `None`: one tile holding the whole scene, in memory.
    pub tile_blocks: Option<i32>,
    /// Estimated peak memory of the run, bytes.
    pub estimated_peak_bytes: u64,
    /// What the memory budget leaves above the estimate, bytes (`None`: no budget); the
    /// tiles' decimation spends it on more regions at once.
    pub(crate) spare_bytes: Option<u64>,
    /// Whether the run keeps the big buffers it frees ([`super::TileStats::kept_freed_memory`]).
    pub kept_freed_memory: bool,
    /// Blocks between a block and the farthest block a particle of it reaches.
    pub(crate) reach: i32,
    /// 1 / cell size, world units.
    pub(crate) inv_h: f64,
    /// The lowest block any tile processes.
    pub(crate) origin: BlockKey,
    /// Tiles to process, in (z, y, x) order.
    pub(crate) tiles: Vec<BlockKey>,
    /// Particles per spill cell (tiled runs only).
    pub(crate) spill_cells: HashMap<BlockKey, u64>,
}

impl TilePlan {
    /// True when the scene is cut into tiles (and spilled to disk).
    pub fn is_tiled(&self) -> bool {
        self.tile_blocks.is_some()
    }

    /// Tiles to process.
    pub fn tile_count(&self) -> usize {
        self.tiles.len()
    }

    /// The blocks tile `tile` owns (everything when untiled).
    pub(crate) fn own_blocks(&self, tile: BlockKey) -> BlockRange {
        match self.tile_blocks {
            Some(t) => BlockRange {
                lo: [0, 1, 2].map(|a| self.origin[a] + tile[a] * t),
                hi: [0, 1, 2].map(|a| self.origin[a] + tile[a] * t + t - 1),
            },
            None => BlockRange {
                lo: [i32::MIN / 4; 3],
                hi: [i32::MAX / 4; 3],
            },
        }
    }

    /// The tile owning block `b`.
    pub(crate) fn tile_of(&self, b: BlockKey) -> BlockKey {
        match self.tile_blocks {
            Some(t) => [0, 1, 2].map(|a| (b[a] - self.origin[a]).div_euclid(t)),
            None => [0, 0, 0],
        }
    }
}

/// The spill cell of block `b`.
pub(crate) fn cell_of(b: BlockKey) -> BlockKey {
    b.map(|c| c.div_euclid(SPILL_CELL_BLOCKS))
}

/// Particles per piece of the parallel count of home blocks.
const COUNT_PIECE: usize = 1 << 14;

/// Checks every position of `source`, counts particles per home block and plans the
/// tiles: the memory budget of `tile_options` picks their size, counting
/// `output_cost` for the surface after the tiles and the payload the source carries.
/// Options must be valid. `sizes`: the particles' own radii (by input index), when they
/// carry them: reaches grow with the largest, and the budget counts the column.
pub(crate) fn plan_tiles<S: ParticleSource + ?Sized>(
    source: &S,
    field_options: &FieldOptions,
    sizes: Option<Sizes<'_>>,
    tile_options: &TileOptions,
    output_cost: super::OutputCost,
    decimated_in_tiles: bool,
    cancel: &CancelToken,
) -> Result<TilePlan> {
    let reach = block_reach(field_options, sizes);
    let inv_h = 1.0 / field_options.cell_size_world();
    let particles = source.particle_count();
    if particles > u32::MAX as usize {
        return Err(Error::InvalidOption {
            option: "input",
            message: format!("{particles} particles: at most 2^32 − 1 per frame"),
        });
    }
    let payload_width = crate::attributes::payload_width(&source.attribute_layout());
    let (block_counts, large) = count_home_blocks(source, field_options, sizes, cancel)?;
    let origin = tile_origin(&block_counts, reach);
    // Counted up to the blocks the budget (or, without one, 64 GiB) holds.
    let cap = tile_options.memory_budget_bytes.unwrap_or(64 << 30)
        / super::budget::LARGE_SUPPORT_BYTES_PER_BLOCK;
    let budget = BudgetInput {
        block_counts: &block_counts,
        origin,
        reach,
        output_cost,
        payload_width,
        kernel_bytes_per_particle: field_options.kernel_bytes_per_particle(),
        decimated_in_tiles,
        radius_column: sizes.is_some(),
        large_support_blocks: super::budget::large_support_blocks(&large, cap),
    };
    let (tile_blocks, estimated_peak_bytes) = choose_tile_blocks(&budget, tile_options)?;
    crate::allocator::fit_retention_to_budget(tile_options.memory_budget_bytes);
    let kept_freed_memory =
        crate::allocator::keep_freed_memory(crate::allocator::may_keep_freed_memory(
            estimated_peak_bytes,
            tile_options.memory_budget_bytes,
            tile_blocks.is_some(),
        ));
    // Tiles are counted from the lowest block the field reaches, so a tile larger than
    // the scene is one tile wherever the scene lies.
    let mut plan = TilePlan {
        particles,
        payload_width,
        tile_blocks,
        estimated_peak_bytes,
        spare_bytes: tile_options
            .memory_budget_bytes
            .map(|budget| budget.saturating_sub(estimated_peak_bytes)),
        kept_freed_memory,
        reach,
        inv_h,
        origin,
        tiles: Vec::new(),
        spill_cells: HashMap::new(),
    };
    plan.list_tiles(&block_counts);
    Ok(plan)
}

impl TilePlan {
    /// Lists the tiles to process: those holding a block within reach (+1 for the
    /// marching layer) of a populated home block; counts the particles per spill cell.
    fn list_tiles(&mut self, block_counts: &HashMap<BlockKey, u64>) {
        let reach = self.reach;
        let mut tiles: HashSet<BlockKey> = HashSet::new();
        if self.is_tiled() {
            for (b, n) in block_counts {
                *self.spill_cells.entry(cell_of(*b)).or_default() += n;
                for dz in -reach - 1..=reach {
                    for dy in -reach - 1..=reach {
                        for dx in -reach - 1..=reach {
                            tiles.insert(self.tile_of([b[0] + dx, b[1] + dy, b[2] + dz]));
                        }
                    }
                }
            }
        } else if self.particles > 0 {
            tiles.insert([0, 0, 0]);
        }
        self.tiles = tiles.into_iter().collect();
        self.tiles.sort_unstable_by_key(|k| [k[2], k[1], k[0]]);
    }
}

/// One pass over `source`: checks every position and counts the particles per home
/// block, in parallel pieces (runs of equal home blocks, then one map per piece), the maps
/// added up after: counts do not depend on the order of the additions. With `sizes`, also
/// the home blocks of the particles that reach more blocks than one of the reference
/// radius, with the most blocks one of each reaches (for the memory model).
#[allow(clippy::type_complexity)]
fn count_home_blocks<S: ParticleSource + ?Sized>(
    source: &S,
    field_options: &FieldOptions,
    sizes: Option<Sizes<'_>>,
    cancel: &CancelToken,
) -> Result<(HashMap<BlockKey, u64>, HashMap<BlockKey, i32>)> {
    let inv_h = 1.0 / field_options.cell_size_world();
    let mut block_counts: HashMap<BlockKey, u64> = HashMap::new();
    let mut large: HashMap<BlockKey, i32> = HashMap::new();
    // A particle of ratio ρ reaches ⌈ρ·unit⌉ blocks.
    let unit = crate::field::kernel_reach(field_options, None)
        / field_options.cell_size
        / crate::grid::BLOCK_EDGE as f32;
    let base = unit.ceil() as i32;
    source.visit_chunks(&mut |chunk| {
        check_positions(
            chunk.first,
            chunk.positions,
            field_options.cell_size_world(),
            field_options.particle_radius,
        )?;
        if let Some(sizes) = sizes {
            let ratios = &sizes.ratios[chunk.first..chunk.first + chunk.positions.len()];
            for (p, &rho) in chunk.positions.iter().zip(ratios) {
                let k = (rho * unit).ceil() as i32;
                if k > base {
                    let e = large.entry(home_block(*p, inv_h)).or_default();
                    *e = (*e).max(k);
                }
            }
        }
        let counts = chunk
            .positions
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
        cancel.check()
    })?;
    Ok((block_counts, large))
}

/// The sum of two maps of counts (the larger one is kept and the other added to it).
fn add_counts(a: HashMap<BlockKey, u64>, b: HashMap<BlockKey, u64>) -> HashMap<BlockKey, u64> {
    let (mut big, small) = if a.len() >= b.len() { (a, b) } else { (b, a) };
    for (k, n) in small {
        *big.entry(k).or_default() += n;
    }
    big
}

/// The lowest block any tile processes: the lowest populated block, less the field's
/// reach and the marching layer.
pub(crate) fn tile_origin(block_counts: &HashMap<BlockKey, u64>, reach: i32) -> BlockKey {
    block_counts
        .keys()
        .fold([i32::MAX; 3], |o, b| [0, 1, 2].map(|a| o[a].min(b[a])))
        .map(|c| c.saturating_sub(reach + 1))
}
