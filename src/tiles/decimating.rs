//! Decimation of a tiled run, tile by tile as each is meshed, so that the raw surface is
//! never whole in memory.
//!
//! **The locked-seam contract.** A tile hands its piece of the marching-cubes mesh: its
//! own blocks and the layer above, stitched so that the vertices on its border carry
//! their global [`VertexKey`] ([`crate::marching_cubes::stitch_range`]). The piece is
//! decimated to the options' fraction with every border vertex *locked*: not moved, not
//! removed, at its exact input position. A large piece is decimated region by region as
//! an untiled mesh is ([`crate::decimation::decimate`]), the border still locked: whole,
//! a piece's state falls out of cache (4M-particle splash under a 1 GiB budget, 13 tiles:
//! decimation 22.3 s → 13.6 s, peak 478 → 379 MiB). Locked vertices are therefore identical in the
//! two tiles that share them, and the reduced pieces join by key into one closed mesh.
//! Once every tile is in, one pass over the band around the seams ([`decimate_band`], the
//! former border vertices and rings around them) reaches the overall target. The result
//! is deterministic and independent of the thread count, but depends on the tile size.

use super::TileSink;
use crate::decimation::{
    decimate_band, decimate_keeping, place_survivors, DecimateOptions, DecimateStats, Remap,
    REGION_BYTES_PER_TRIANGLE,
};
use crate::error::Result;
use crate::grid::BlockRange;
use crate::marching_cubes::{stitch_range, BlockSurface, VertexKey};
use crate::mesh::TriMesh;
use glam::Vec3;
use hashbrown::HashMap;
use std::time::Instant;

/// Error bound of collapses in tiles and in the seam pass when the decimation options set
/// none, multiples of r. Measured on `dambreak_small` frame 25 in 64-cell tiles: without
/// it 18 of 41 912 particles end up just outside the surface, with it none, at the same
/// 80 % and a lower flat-region bumpiness (0.0092 r instead of 0.0097 r); 0.05 r misses
/// the fraction on `double_dambreak`.
pub(crate) const TILE_ERROR_CAP: f32 = 0.1;

/// A [`TileSink`] that decimates every tile's piece with its border locked and joins the
/// pieces; [`TileDecimation::finish`] decimates the seam band.
pub(crate) struct TileDecimation {
    /// The options, with the error bound capped ([`TILE_ERROR_CAP`]).
    options: DecimateOptions,
    /// Regions decimated at once in a piece.
    in_flight: usize,
    joined: JoinedPieces,
    stats: DecimateStats,
    /// Marching-cubes triangles of all pieces.
    marching_triangles: usize,
    /// Seconds spent stitching pieces (part of marching cubes).
    pub stitch_seconds: f64,
    /// Seconds spent decimating pieces and the band.
    pub decimation_seconds: f64,
}

impl TileDecimation {
    /// A sink decimating with `options` for particles of radius `particle_radius` (world
    /// units). Each tile must reach the fraction on its own; the error cap keeps a tile of
    /// mostly curved surface from forcing large collapses to get there (the seam pass,
    /// capped too, makes up the rest where it can).
    ///
    /// A large piece is decimated region by region, two regions at once (what the memory
    /// model's tile figures were measured with) and one more for each
    /// [`REGION_BYTES_PER_TRIANGLE`] × region triangles of `spare_bytes` (what the budget
    /// leaves above the plan's estimate; `None`: no budget, no limit). Without the cap each
    /// thread decimates a region of its own: 16 threads took the 4M splash to 1.2 GiB under
    /// a 1 GiB budget.
    pub fn new(options: &DecimateOptions, particle_radius: f32, spare_bytes: Option<u64>) -> Self {
        let region_bytes = (options.region_triangles as u64 * REGION_BYTES_PER_TRIANGLE).max(1);
        TileDecimation {
            options: DecimateOptions {
                max_error: options.max_error.or(Some(TILE_ERROR_CAP * particle_radius)),
                ..options.clone()
            },
            in_flight: spare_bytes.map_or(usize::MAX, |spare| {
                usize::try_from(spare / region_bytes)
                    .unwrap_or(usize::MAX)
                    .saturating_add(2)
            }),
            joined: JoinedPieces::default(),
            stats: DecimateStats::default(),
            marching_triangles: 0,
            stitch_seconds: 0.0,
            decimation_seconds: 0.0,
        }
    }

    /// Marching-cubes triangles of all pieces.
    pub fn marching_triangles(&self) -> usize {
        self.marching_triangles
    }

    /// The joined mesh, its seam band decimated to the overall target.
    pub fn finish(mut self) -> (TriMesh, DecimateStats, f64) {
        let clock = Instant::now();
        let joined = self.joined;
        let mut mesh = TriMesh {
            positions: joined.positions,
            triangles: joined.triangles,
            ..TriMesh::default()
        };
        drop(joined.seam_index);
        let target = self.options.target_triangles(self.marching_triangles);
        let (band, _) = decimate_band(
            &mut mesh,
            &joined.was_seam,
            &[],
            target,
            self.options.max_error,
            Remap::Drop,
        );
        self.stats.add_work(&band);
        self.stats.triangles_before = self.marching_triangles;
        self.stats.triangles_after = mesh.triangle_count();
        let seconds = self.decimation_seconds + clock.elapsed().as_secs_f64();
        (mesh, self.stats, seconds)
    }
}

impl TileSink for TileDecimation {
    /// The tile's own blocks and the layer above (owners of its upper border vertices).
    fn march_range(&self, own: BlockRange) -> BlockRange {
        own.grown(0, 1)
    }

    fn take(&mut self, own: BlockRange, surfaces: Vec<BlockSurface>) -> Result<()> {
        let clock = Instant::now();
        let piece = stitch_range(&surfaces, own);
        drop(surfaces);
        self.marching_triangles += piece.mesh.triangle_count();
        self.stitch_seconds += clock.elapsed().as_secs_f64();
        let clock = Instant::now();
        let tile_stats = decimate_piece(piece, &self.options, self.in_flight, &mut self.joined);
        self.stats.add_work(&tile_stats);
        self.stats.regions += tile_stats.regions.max(1);
        self.decimation_seconds += clock.elapsed().as_secs_f64();
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
    in_flight: usize,
    joined: &mut JoinedPieces,
) -> DecimateStats {
    let mut mesh = piece.mesh;
    let locked: Vec<bool> = piece.seam_keys.iter().map(Option::is_some).collect();
    // Border vertices keep their exact input position (decimation rescales internally).
    let original = mesh.positions.clone();
    let (stats, remap) = decimate_keeping(&mut mesh, options, &locked, in_flight);
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
