//! Where a tile's particles come from: the source itself when it is in memory, a copy,
//! or the spill file of a tiled run ([`super::spill`]), always handed out in the
//! canonical load order (home half-block, input index), with the payload (the selected
//! attributes) as rows beside the positions when asked for.

use super::plan::{cell_of, TilePlan, SPILL_CELL_BLOCKS};
use super::spill::SpillFile;
use crate::cancel::CancelToken;
use crate::error::Result;
use crate::grid::{block_of_half, home_block, home_half_block, BlockRange};
use crate::grid::{BlockKey, BLOCK_EDGE};
use crate::io::particles::ParticleSource;
use glam::Vec3;
use rayon::prelude::*;
use std::path::Path;

/// The particles of a run, held for the tiles (and for the attribute stage).
pub(crate) enum ParticleStore<S> {
    /// The source, whose positions and payload are in memory.
    Source(S),
    /// A copy of a source that is not (a mapped file, a spooled one, columns).
    Copied {
        positions: Vec<Vec3>,
        payload: Vec<f32>,
    },
    /// Binned on disk by spill cell: a tiled run.
    Spilled {
        spill: SpillFile,
        /// Inverse cell edge of the plan that binned it (spill cells group home blocks).
        inv_h: f64,
    },
}

/// Particles of a zone with their payload, in the canonical order.
#[derive(Default)]
pub(crate) struct LoadedParticles {
    /// Home half-block of each.
    pub halves: Vec<BlockKey>,
    /// Input index of each.
    pub indices: Vec<u32>,
    /// Positions.
    pub positions: Vec<Vec3>,
    /// Payload rows (`width` floats each).
    pub payload: Vec<f32>,
}

impl<S: ParticleSource> ParticleStore<S> {
    /// Holds `source` as `plan` says: binned into a spill file in `temp_dir` (a tiled run;
    /// the source is dropped after), or in memory.
    pub(crate) fn build(
        source: S,
        plan: &TilePlan,
        temp_dir: Option<&Path>,
        cancel: &CancelToken,
    ) -> Result<Self> {
        if plan.is_tiled() {
            let temp = temp_dir
                .map(Path::to_path_buf)
                .unwrap_or_else(std::env::temp_dir);
            let spill = SpillFile::create(&temp, &plan.spill_cells, plan.payload_width)?;
            let mut writer = spill.writer();
            let width = plan.payload_width;
            source.visit_chunks(&mut |chunk| {
                for (k, p) in chunk.positions.iter().enumerate() {
                    let row = &chunk.payload[k * width..(k + 1) * width];
                    writer.push(
                        cell_of(home_block(*p, plan.inv_h)),
                        *p,
                        (chunk.first + k) as u32,
                        row,
                    )?;
                }
                cancel.check()
            })?;
            writer.finish()?;
            return Ok(ParticleStore::Spilled {
                spill,
                inv_h: plan.inv_h,
            });
        }
        if source.as_slices().is_some() {
            return Ok(ParticleStore::Source(source));
        }
        let mut positions = Vec::with_capacity(plan.particles);
        let mut payload = Vec::with_capacity(plan.particles * plan.payload_width);
        source.visit_chunks(&mut |chunk| {
            positions.extend_from_slice(chunk.positions);
            payload.extend_from_slice(chunk.payload);
            Ok(())
        })?;
        Ok(ParticleStore::Copied { positions, payload })
    }

    /// Bytes of particle records on disk (0 in memory).
    pub(crate) fn spill_bytes(&self) -> u64 {
        match self {
            ParticleStore::Spilled { spill, .. } => spill.bytes(),
            _ => 0,
        }
    }

    /// Calls `visit(positions, input indices, payload rows)` for every stored particle,
    /// a spill cell at a time (all at once in memory).
    #[allow(clippy::type_complexity)]
    pub(crate) fn for_each_stored(
        &self,
        visit: &mut dyn FnMut(&[Vec3], &[u32], &[f32]) -> Result<()>,
    ) -> Result<()> {
        self.for_each_stored_where(&|_| true, true, visit)
    }

    /// Calls `visit(positions, input indices)` for the stored particles whose coordinate
    /// `axis` lies from `lo` to `hi`, and some others: spilled, only the spill cells that
    /// reach that range are read.
    #[allow(clippy::type_complexity)]
    pub(crate) fn for_each_stored_between(
        &self,
        axis: usize,
        lo: f32,
        hi: f32,
        visit: &mut dyn FnMut(&[Vec3], &[u32]) -> Result<()>,
    ) -> Result<()> {
        let inv_h = match self {
            ParticleStore::Spilled { inv_h, .. } => *inv_h,
            _ => 1.0,
        };
        // A spill cell holds the particles whose home blocks it groups: world
        // coordinates from `c·edge` to `(c + 1)·edge`, widened by a block for rounding.
        let edge = (SPILL_CELL_BLOCKS * BLOCK_EDGE) as f64 / inv_h;
        let block = BLOCK_EDGE as f64 / inv_h;
        let reaches = |cell: BlockKey| {
            let start = cell[axis] as f64 * edge - block;
            let end = (cell[axis] + 1) as f64 * edge + block;
            end >= lo as f64 && start <= hi as f64
        };
        self.for_each_stored_where(&reaches, false, &mut |positions, indices, _| {
            visit(positions, indices)
        })
    }

    /// Calls `visit(positions, input indices, payload rows)` for the particles of every
    /// spill cell `keep` accepts (every particle, in memory), with their payload rows
    /// when `rows` (else none).
    #[allow(clippy::type_complexity)]
    fn for_each_stored_where(
        &self,
        keep: &dyn Fn(BlockKey) -> bool,
        rows: bool,
        visit: &mut dyn FnMut(&[Vec3], &[u32], &[f32]) -> Result<()>,
    ) -> Result<()> {
        let ParticleStore::Spilled { spill, .. } = self else {
            let (all, payload) = self.in_memory().expect("in memory");
            let indices: Vec<u32> = (0..all.len() as u32).collect();
            return visit(all, &indices, if rows { payload } else { &[] });
        };
        let (mut records, mut payload) = (Vec::new(), Vec::new());
        for cell in spill.cells().into_iter().filter(|&c| keep(c)) {
            records.clear();
            payload.clear();
            spill.read_cell(cell, &mut records, rows.then_some(&mut payload))?;
            let (positions, indices): (Vec<Vec3>, Vec<u32>) = records.iter().copied().unzip();
            visit(&positions, &indices, &payload)?;
        }
        Ok(())
    }

    /// Positions and payload rows, when in memory.
    fn in_memory(&self) -> Option<(&[Vec3], &[f32])> {
        match self {
            ParticleStore::Source(source) => source.as_slices(),
            ParticleStore::Copied { positions, payload } => Some((positions, payload)),
            ParticleStore::Spilled { .. } => None,
        }
    }

    /// Replaces `loaded` with the particles whose home block lies in `zone` (every
    /// particle, in memory) as (home half-block, input index, position), in the canonical
    /// order.
    pub(crate) fn load(
        &self,
        plan: &TilePlan,
        zone: BlockRange,
        loaded: &mut Vec<(BlockKey, u32, Vec3)>,
    ) -> Result<()> {
        let home_of = |p: &Vec3| home_half_block(*p, plan.inv_h);
        match self {
            ParticleStore::Spilled { spill, .. } => {
                let mut records = Vec::new();
                spill.read_cells(cell_of(zone.lo), cell_of(zone.hi), &mut records, None)?;
                let mut homes: Vec<BlockKey> = records.par_iter().map(|r| home_of(&r.0)).collect();
                // The spill cells reach past the zone: keep the records (and homes) inside it.
                let inside = |h: &BlockKey| zone.contains(block_of_half(*h));
                let mut record_homes = homes.iter();
                records.retain(|_| record_homes.next().is_some_and(inside));
                homes.retain(inside);
                load_in_canonical_order(&homes, |k| records[k], loaded);
            }
            _ => {
                let (all, _) = self.in_memory().expect("in memory");
                let homes: Vec<BlockKey> = all.par_iter().map(home_of).collect();
                load_in_canonical_order(&homes, |i| (all[i], i as u32), loaded);
            }
        }
        Ok(())
    }

    /// The particles whose home block lies in `zone` (every particle, in memory) with
    /// their payload, in the canonical order.
    pub(crate) fn load_with_payload(
        &self,
        plan: &TilePlan,
        zone: BlockRange,
        out: &mut LoadedParticles,
    ) -> Result<()> {
        let width = plan.payload_width;
        let home_of = |p: &Vec3| home_half_block(*p, plan.inv_h);
        let mut gather =
            |positions: &[Vec3], indices: &(dyn Fn(usize) -> u32 + Sync), payload: &[f32]| {
                let homes: Vec<BlockKey> = positions.par_iter().map(home_of).collect();
                let mut order = canonical_order(&homes, indices);
                order.retain(|&k| zone.contains(block_of_half(homes[k as usize])));
                out.halves = order.par_iter().map(|&k| homes[k as usize]).collect();
                drop(homes);
                out.indices = order.par_iter().map(|&k| indices(k as usize)).collect();
                out.positions = order.par_iter().map(|&k| positions[k as usize]).collect();
                out.payload.clear();
                out.payload.reserve_exact(order.len() * width);
                for &k in &order {
                    let k = k as usize;
                    out.payload
                        .extend_from_slice(&payload[k * width..(k + 1) * width]);
                }
            };
        match self {
            ParticleStore::Spilled { spill, .. } => {
                let mut records = Vec::new();
                let mut rows = Vec::new();
                spill.read_cells(
                    cell_of(zone.lo),
                    cell_of(zone.hi),
                    &mut records,
                    Some(&mut rows),
                )?;
                let (positions, indices): (Vec<Vec3>, Vec<u32>) = records.into_iter().unzip();
                gather(&positions, &|k| indices[k], &rows);
            }
            _ => {
                let (all, rows) = self.in_memory().expect("in memory");
                gather(all, &|k| k as u32, rows);
            }
        }
        Ok(())
    }
}

/// The order (home half-block, input index) of particles with home half-blocks `homes`
/// and input indices `index(k)`: a stable radix sort of the half-blocks, then runs of
/// equal half-blocks not already in input order sorted by index.
fn canonical_order(homes: &[BlockKey], index: &(dyn Fn(usize) -> u32 + Sync)) -> Vec<u32> {
    let mut order = crate::grid::sort_by_key_zyx(homes);
    order
        .par_chunk_by_mut(|&a, &b| homes[a as usize] == homes[b as usize])
        .filter(|run| !run.is_sorted_by_key(|&k| index(k as usize)))
        .for_each(|run| run.sort_unstable_by_key(|&k| index(k as usize)));
    order
}

/// Replaces `loaded` with the particles that `particle(k)` gives (position, input index),
/// each with its home half-block `homes[k]`, in the canonical order (home half-block,
/// input index). The home half-blocks are sorted by a stable radix sort; equal ones keep
/// the order of `particle`, which is by input index except perhaps for spilled records,
/// whose runs are then put in input order.
pub(crate) fn load_in_canonical_order(
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
/// The stored particles are the centres containment measures, read back cell by cell.
impl<S: ParticleSource> crate::containment::Centres for ParticleStore<S> {
    fn visit_between(
        &self,
        axis: usize,
        lo: f32,
        hi: f32,
        visit: &mut crate::containment::VisitChunk<'_>,
    ) -> Result<()> {
        self.for_each_stored_between(axis, lo, hi, visit)
    }
}
