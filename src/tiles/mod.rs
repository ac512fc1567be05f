//! The tiled engine: the lattice cut into cubic tiles of blocks, each reconstructed from
//! its own particles plus a ghost margin, the block surfaces stitched into one mesh.
//!
//! **Input:** particle centres (world units), field options, [`TileOptions`].
//! **Output:** the marching-cubes mesh and the isolated-particle centres — *identical*,
//! bit for bit, whatever the tile size and thread count (a tile larger than the scene is
//! the untiled run).
//!
//! Why the result does not depend on the tiling:
//! * tile `t` owns blocks `T·t ..= T·t + T − 1` (`T` blocks per axis); it marches its own
//!   blocks only (reading the field one block further up), and every mesh vertex is owned
//!   by exactly one block;
//! * a field block sums over the particles whose home block is within `reach` blocks
//!   ([`crate::field::block_reach`]), in (home block, global index) order — the tile loads
//!   every particle within `reach` of its field blocks ("zone 1") in that order, which is
//!   also the order every neighbour search of the tile sees;
//! * the isolation flag of a zone-1 particle depends on the particles within `R` of it, so
//!   the tile also loads a second ghost ring of `reach` blocks ("zone 2");
//! * coverage ([`crate::field::apply_coverage`]) reads the field around particles within
//!   `c·r + 2h` of the used blocks, so field blocks are computed one block further all
//!   round;
//! * [`crate::marching_cubes::stitch`] numbers vertices in global block order.
//!
//! Tiles run one after another, each parallel inside, so peak memory is one tile's field
//! plus the block surfaces gathered so far.

use crate::error::Result;
use crate::field::{
    apply_coverage, block_reach, check_positions, compute_blocks, home_blocks, BlockRange,
    FieldOptions, FieldStats,
};
use crate::grid::{BlockKey, BLOCK_EDGE};
use crate::marching_cubes::{march_blocks, stitch, BlockSurface, MarchingCubesStats};
use crate::mesh::TriMesh;
use crate::neighbors::find_isolated_where;
use glam::Vec3;
use hashbrown::{HashMap, HashSet};
use rayon::prelude::*;
use std::time::Instant;

/// How the lattice is cut.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TileOptions {
    /// Tile edge in marching-cubes cells, rounded up to whole 8-cell blocks. `None`: one
    /// tile holds the whole scene. Default `None`.
    pub tile_size_cells: Option<u32>,
}

/// What the tiled run did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct TileStats {
    /// Tiles processed (tiles with at least one block to march or compute).
    pub tiles: usize,
    /// Tile edge, blocks (0 when untiled).
    pub tile_blocks: u32,
    /// Largest particle count one tile loaded (own + ghosts).
    pub max_tile_particles: usize,
    /// Largest field memory of one tile, bytes.
    pub max_tile_field_bytes: usize,
    /// Bytes of the gathered block surfaces before stitching.
    pub surface_bytes: usize,
    /// Seconds spent loading tile particles and finding isolated particles.
    pub neighbour_seconds: f64,
    /// Seconds spent computing field blocks (with coverage).
    pub field_seconds: f64,
    /// Seconds spent in marching cubes (per-block extraction).
    pub marching_seconds: f64,
    /// Seconds spent stitching block surfaces into one mesh.
    pub stitch_seconds: f64,
}

/// The result of the field and marching-cubes stages over all tiles.
pub struct TiledSurface {
    /// The stitched marching-cubes mesh.
    pub mesh: TriMesh,
    /// Centres of isolated particles, in input order.
    pub isolated: Vec<Vec3>,
    /// Field figures summed over tiles (particles counts the field particles once).
    pub field: FieldStats,
    /// Marching-cubes figures of the stitched mesh.
    pub marching_cubes: MarchingCubesStats,
    /// Tiling figures.
    pub tiles: TileStats,
}

/// Runs isolation, field and marching cubes tile by tile and stitches the result.
/// `isolation_radius` (world units) is `None` to keep isolated particles in the field.
pub fn reconstruct_tiled(
    positions: &[Vec3],
    field_options: &FieldOptions,
    isolation_radius: Option<f32>,
    tile_options: &TileOptions,
    on_tile: &dyn Fn(usize, usize),
) -> Result<TiledSurface> {
    field_options.validate()?;
    check_positions(positions, field_options)?;
    let reach = block_reach(field_options);
    let home = home_blocks(positions, field_options);
    let tile_blocks = tile_options
        .tile_size_cells
        .map(|cells| (cells.max(1) as i32 + BLOCK_EDGE - 1) / BLOCK_EDGE);
    let tile_of = |b: BlockKey| -> BlockKey {
        match tile_blocks {
            Some(t) => b.map(|c| c.div_euclid(t)),
            None => [0, 0, 0],
        }
    };

    // Bin particle indices by home tile, in input order.
    let mut bins: HashMap<BlockKey, Vec<u32>> = HashMap::new();
    for (i, b) in home.iter().enumerate() {
        bins.entry(tile_of(*b)).or_default().push(i as u32);
    }
    // Tiles to process: those holding a block within reach (+1 for the marching layer)
    // of a populated home block.
    let mut tiles: HashSet<BlockKey> = HashSet::new();
    if tile_blocks.is_some() {
        let populated: HashSet<BlockKey> = home.iter().copied().collect();
        for b in &populated {
            for dz in -reach - 1..=reach {
                for dy in -reach - 1..=reach {
                    for dx in -reach - 1..=reach {
                        tiles.insert(tile_of([b[0] + dx, b[1] + dy, b[2] + dz]));
                    }
                }
            }
        }
    } else if !positions.is_empty() {
        tiles.insert([0, 0, 0]);
    }
    let mut tiles: Vec<BlockKey> = tiles.into_iter().collect();
    tiles.sort_unstable_by_key(|k| [k[2], k[1], k[0]]);

    let mut surfaces: Vec<BlockSurface> = Vec::new();
    let mut isolated_indices: Vec<u32> = Vec::new();
    let mut field_stats = FieldStats::default();
    let mut stats = TileStats {
        tiles: tiles.len(),
        tile_blocks: tile_blocks.unwrap_or(0) as u32,
        ..TileStats::default()
    };
    for (n, &tile) in tiles.iter().enumerate() {
        on_tile(n, tiles.len());
        let clock = Instant::now();
        let own = match tile_blocks {
            Some(t) => BlockRange {
                lo: tile.map(|c| c * t),
                hi: tile.map(|c| c * t + t - 1),
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

        // Load zone 2 from the bins of every tile it overlaps, in the canonical order
        // (home block, input index): spatially coherent, and the same in every tiling.
        let mut loaded: Vec<u32> = Vec::new();
        if tile_blocks.is_some() {
            let (tlo, thi) = (tile_of(zone2.lo), tile_of(zone2.hi));
            for tz in tlo[2]..=thi[2] {
                for ty in tlo[1]..=thi[1] {
                    for tx in tlo[0]..=thi[0] {
                        if let Some(bin) = bins.get(&[tx, ty, tz]) {
                            loaded.extend(
                                bin.iter()
                                    .copied()
                                    .filter(|&i| zone2.contains(home[i as usize])),
                            );
                        }
                    }
                }
            }
        } else {
            loaded = (0..positions.len() as u32).collect();
        }
        loaded.par_sort_unstable_by_key(|&i| {
            let h = home[i as usize];
            (h[2], h[1], h[0], i)
        });
        stats.max_tile_particles = stats.max_tile_particles.max(loaded.len());
        let local: Vec<Vec3> = loaded.iter().map(|&i| positions[i as usize]).collect();

        // Flags are needed for zone 1 only; zone 2 is there to complete their neighbours.
        let in_zone1: Vec<bool> = loaded
            .iter()
            .map(|&i| zone1.contains(home[i as usize]))
            .collect();
        let isolated = match isolation_radius {
            Some(radius) => find_isolated_where(&local, radius, &in_zone1),
            None => vec![false; local.len()],
        };
        let mut field_particles = Vec::new();
        for (k, &gi) in loaded.iter().enumerate() {
            let h = home[gi as usize];
            if isolated[k] {
                if own.contains(h) {
                    isolated_indices.push(gi);
                }
            } else if zone1.contains(h) {
                field_particles.push(local[k]);
            }
        }
        drop(local);
        stats.neighbour_seconds += clock.elapsed().as_secs_f64();
        let clock = Instant::now();
        let (mut field, fs) = compute_blocks(&field_particles, field_options, Some(field_range));
        field_stats.uncovered_particles +=
            apply_coverage(&mut field, &field_particles, field_options, Some(own));
        stats.max_tile_field_bytes = stats.max_tile_field_bytes.max(fs.block_bytes);
        field_stats.blocks += fs.blocks;
        field_stats.vertices_in_band += fs.vertices_in_band;
        field_stats.block_bytes = field_stats.block_bytes.max(fs.block_bytes);
        stats.field_seconds += clock.elapsed().as_secs_f64();
        let clock = Instant::now();
        let tile_surfaces = march_blocks(&field, Some(own));
        drop(field);
        surfaces.extend(tile_surfaces);
        stats.marching_seconds += clock.elapsed().as_secs_f64();
    }
    stats.surface_bytes = surfaces.iter().map(|s| s.memory_bytes()).sum();
    let clock = Instant::now();
    let (mesh, mc_stats) = stitch(surfaces);
    stats.stitch_seconds = clock.elapsed().as_secs_f64();

    isolated_indices.sort_unstable();
    field_stats.particles = positions.len() - isolated_indices.len();
    Ok(TiledSurface {
        mesh,
        isolated: isolated_indices
            .iter()
            .map(|&i| positions[i as usize])
            .collect(),
        field: field_stats,
        marching_cubes: mc_stats,
        tiles: stats,
    })
}
