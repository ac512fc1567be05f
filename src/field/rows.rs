//! Which particles reach which rows of vertices of one block, for the field kernel
//! (`super::isotropic`): the sorted particles indexed by half-row of home half-blocks,
//! and per block the particles within reach with the set of rows each one meets, as bit
//! masks transposed into per-row particle sets.

use super::evaluate::{ROW, ROWS};
use crate::grid::{BlockKey, BLOCK_EDGE};
use hashbrown::HashMap;

/// Per-thread scratch of one block: the particles within reach and, per row of vertices,
/// the set of those that have a weight somewhere on it.
pub(super) struct RowLists {
    /// Block-local particle positions (cells), in scan order.
    pub(super) particles: Vec<[f32; 3]>,
    /// Per group of 64 particles (in scan order), per row: a bit per particle of the
    /// group that meets the row. Built as one row mask per particle (bit `k` = row `k`)
    /// and transposed in place.
    pub(super) rows: Vec<[u64; ROWS]>,
    /// For particles of several sizes: each one's `1 / R_i²` (cells) and radius in
    /// multiples of r, in scan order.
    pub(super) sizes: Vec<[f32; 2]>,
}

impl RowLists {
    pub(super) fn new() -> Self {
        RowLists {
            particles: Vec::new(),
            rows: Vec::new(),
            sizes: Vec::new(),
        }
    }
}

/// Transposes a 64×64 bit matrix in place: bit `j` of `m[i]` becomes bit `i` of `m[j]`
/// (block swaps of halves, quarters, …, bits).
pub(super) fn transpose_bits(m: &mut [u64; 64]) {
    let mut width = 32;
    let mut low: u64 = 0x0000_0000_FFFF_FFFF;
    while width != 0 {
        let mut k = 0;
        while k < 64 {
            // Row k's high half (of each 2·width-bit pair) swaps with row k + width's
            // low half.
            let t = ((m[k] >> width) ^ m[k + width]) & low;
            m[k + width] ^= t;
            m[k] ^= t << width;
            k = (k + width + 1) & !width;
        }
        width >>= 1;
        low ^= low << width;
    }
}

/// One populated home half-block of a [`HalfRowIndex`].
#[derive(Clone, Copy)]
struct HalfBlockRun {
    /// Half-block x coordinate.
    x: i32,
    /// Its particles: `start..end` of the sorted positions.
    start: u32,
    end: u32,
}

/// The populated home half-blocks, in (z, y, x) order, grouped by half-row (the
/// half-blocks of one y and z): a block finds the particles of the four half-blocks of a
/// half-row within its reach with one lookup, as one contiguous run.
pub(super) struct HalfRowIndex {
    /// Per half-row `[y, z]`: the range of `cells` holding its half-blocks.
    rows: HashMap<[i32; 2], (u32, u32)>,
    cells: Vec<HalfBlockRun>,
}

impl HalfRowIndex {
    /// The index of the runs of sorted particles sharing a home half-block
    /// ([`crate::grid::key_runs`], in (z, y, x) order).
    pub(super) fn new(runs: &[(BlockKey, u32, u32)]) -> HalfRowIndex {
        let cells = runs
            .iter()
            .map(|&(half, start, end)| HalfBlockRun {
                x: half[0],
                start,
                end,
            })
            .collect();
        let rows = crate::grid::row_ranges(runs.iter().map(|r| r.0));
        HalfRowIndex { rows, cells }
    }

    /// The particles (a range of the sorted positions) of the half-blocks `x0..=x1` of
    /// half-row `[y, z]`.
    #[inline(always)]
    pub(super) fn run(&self, y: i32, z: i32, x0: i32, x1: i32) -> std::ops::Range<usize> {
        let Some(&(a, b)) = self.rows.get(&[y, z]) else {
            return 0..0;
        };
        let row = &self.cells[a as usize..b as usize];
        let first = row.partition_point(|c| c.x < x0);
        let last = row.partition_point(|c| c.x <= x1);
        if first >= last {
            return 0..0;
        }
        row[first].start as usize..row[last - 1].end as usize
    }
}

/// The rows of a block (bit `8z + y`) on which a particle at block-local `x` (cells) has a
/// weight: the rows within the block extent `lo..=hi` (`[x, y, z]` vertex coordinates)
/// where the weight at the row's vertex nearest to the particle, by the test
/// [`super::accumulate_row`] makes, is not zero (the weight falls with the distance, so no other
/// vertex of the row has one where that one has none). Rows the influence sphere meets
/// only beyond the block's ends are left out: their terms would all be zero.
#[inline(always)]
pub(super) fn row_mask(x: [f32; 3], lo: [i32; 3], hi: [i32; 3], inv_rc2: f32) -> u64 {
    let nearest = x[0].round().clamp(0.0, (ROW - 1) as f32);
    let rx = nearest - x[0];
    let rx2 = rx * rx;
    let mut mask = 0u64;
    for c in 0..ROW {
        let rz = c as f32 - x[2];
        let mut byte = 0u64;
        for b in 0..ROW {
            let ry = b as f32 - x[1];
            byte |= (((rx2 + (ry * ry + rz * rz)) * inv_rc2 < 1.0) as u64) << b;
        }
        mask |= byte << (ROW * c);
    }
    // The extent: rows lo[1]..=hi[1] of the planes lo[2]..=hi[2].
    let y_bits = (1u64 << (hi[1] + 1)) - (1u64 << lo[1]);
    let z_bytes =
        (u64::MAX >> (ROW as i32 * (BLOCK_EDGE - 1 - hi[2]))) & (u64::MAX << (ROW as i32 * lo[2]));
    mask & (y_bits * 0x0101_0101_0101_0101) & z_bytes
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bit_matrices_transpose() {
        let mut rng = crate::test_rng::TestRng::new(11);
        let mut m = [0u64; 64];
        for row in &mut m {
            let seed = rng.next_u64();
            *row = seed ^ (seed >> 29);
        }
        let original = m;
        transpose_bits(&mut m);
        for (i, row) in original.iter().enumerate() {
            for (j, column) in m.iter().enumerate() {
                assert_eq!((column >> i) & 1, (row >> j) & 1, "bit {j} of row {i}");
            }
        }
        transpose_bits(&mut m);
        assert_eq!(m, original);
    }
}
