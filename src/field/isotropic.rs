//! The Solenthaler et al. 2007 field ([`Kernel::Isotropic`](super::Kernel), the paper's):
//! spherical kernels of radius `R`, `phi(v) = |v − vbar(v)| − r·f(v)` (see the formulas in
//! [`super`]). Particles of several sizes each weigh with their own `R_i = R·ρ_i`
//! and the surface lies at `rbar·f` with `rbar = Σ w_i r_i / Σ w_i` (one more sum).

use super::candidates::candidate_blocks;
use super::concavity::{concavity_factor, largest_eigenvalue_real_part_lanes};
use super::evaluate::{evaluate_blocks, BlockEvaluator, ROW, ROWS};
use super::rows::{row_mask, transpose_bits, HalfRowIndex, RowLists};
use super::{FieldOptions, FieldStats, Sizes};
use crate::grid::{
    home_half_block, BlockKey, BlockRange, BlockValues, SparseField, BLOCK_EDGE, HALF_BLOCK_EDGE,
};
use glam::Vec3;
use rayon::prelude::*;
use std::borrow::Cow;

/// Computes the blocks of the pure Solenthaler field within `range` (all blocks when
/// `None`) from `positions`, which must include every particle within `R` of those blocks,
/// in a canonical order (the same relative order in every tiling). Coverage is applied
/// afterwards by [`apply_coverage`]. Options must be valid. `sizes`: each particle's
/// radius in multiples of r, for particles of several sizes.
pub(crate) fn compute_blocks(
    positions: &[Vec3],
    sizes: Option<Sizes<'_>>,
    options: &FieldOptions,
    range: Option<BlockRange>,
) -> (SparseField, FieldStats) {
    compute_blocks_with(positions, sizes, options, range, true)
}

/// [`compute_blocks`]; `simd`: the AVX2 copy of the kernel may be used (the values are the
/// same either way, which the tests check).
fn compute_blocks_with(
    positions: &[Vec3],
    sizes: Option<Sizes<'_>>,
    options: &FieldOptions,
    range: Option<BlockRange>,
    simd: bool,
) -> (SparseField, FieldStats) {
    let h = options.cell_size_world();
    let inv_h = 1.0 / h;
    let radius_cells = options.influence_radius / options.cell_size;

    // Particles sorted by (home half-block, index) in (z, y, x) order, copied into that
    // order: a block then scans the particles of the half-blocks within reach, not of whole
    // neighbour blocks (with R = 4 h, 512 particle slots instead of 1728, most of which
    // would be out of reach), and the half-blocks of one (y, z) half-row within reach are
    // one contiguous run of the copy. Particles already in that order (a tile's) are
    // taken as they are: sorting them would not move any.
    let halves: Vec<BlockKey> = positions
        .par_iter()
        .map(|p| home_half_block(*p, inv_h))
        .collect();
    let zyx = |k: &BlockKey| [k[2], k[1], k[0]];
    let ratios = sizes.map(|s| s.ratios);
    let (runs, sorted, ratios) = if halves.par_windows(2).all(|w| zyx(&w[0]) <= zyx(&w[1])) {
        let runs = crate::grid::key_runs(halves.iter().copied());
        (runs, Cow::Borrowed(positions), ratios.map(Cow::Borrowed))
    } else {
        let order = crate::grid::sort_by_key_zyx(&halves);
        let runs = crate::grid::key_runs(order.iter().map(|&i| halves[i as usize]));
        let sorted: Vec<Vec3> = order.par_iter().map(|&i| positions[i as usize]).collect();
        let ratios = ratios.map(|r| Cow::Owned(order.iter().map(|&i| r[i as usize]).collect()));
        (runs, Cow::Owned(sorted), ratios)
    };
    drop(halves);
    let reach_cells = radius_cells * super::largest_ratio(sizes);
    let half_reach = (reach_cells / HALF_BLOCK_EDGE as f32).ceil() as i32;
    let candidates = candidate_blocks(runs.iter().map(|r| r.0), half_reach, range);
    let index = HalfRowIndex::new(&runs);
    drop(runs);

    match ratios.as_deref() {
        None => {
            let kernel = BlockKernel::<false> {
                sorted: &sorted,
                ratios: &[],
                index: &index,
                half_reach,
                inv_h,
                radius_cells,
                h,
                options,
            };
            evaluate_blocks(&kernel, &candidates, positions.len(), options, simd)
        }
        Some(ratios) => {
            let kernel = BlockKernel::<true> {
                sorted: &sorted,
                ratios,
                index: &index,
                half_reach,
                inv_h,
                radius_cells,
                h,
                options,
            };
            evaluate_blocks(&kernel, &candidates, positions.len(), options, simd)
        }
    }
}

/// `SIZED`: particles of several sizes (`ratios`).
struct BlockKernel<'a, const SIZED: bool> {
    /// Particle positions (world units) sorted by home half-block (see [`HalfRowIndex`]).
    sorted: &'a [Vec3],
    /// Their radii, multiples of r (`SIZED` only).
    ratios: &'a [f32],
    index: &'a HalfRowIndex,
    /// Half-blocks, per axis, beyond a block's own two whose particles can reach it
    /// (`⌈R / 4h⌉`).
    half_reach: i32,
    inv_h: f64,
    radius_cells: f32,
    h: f64,
    options: &'a FieldOptions,
}

impl<const SIZED: bool> BlockEvaluator for BlockKernel<'_, SIZED> {
    type Scratch = RowLists;

    fn scratch(&self) -> RowLists {
        RowLists::new()
    }

    /// Two steps: the particles within reach are listed (in scan order) with the set of
    /// rows of vertices each one meets, a 64-bit mask, and the masks of every 64 particles
    /// are transposed into per-row sets of particles; then each row sums its particles
    /// with its running sums in registers and is finalised at once. Each vertex adds its
    /// particles in scan order, whatever the steps.
    // Index loops over lanes on purpose: they inline into (and vectorize within) the AVX2
    // copy, where iterator adaptors' closures may not.
    #[allow(clippy::needless_range_loop)]
    #[inline(always)]
    fn evaluate_block(
        &self,
        key: BlockKey,
        lists: &mut RowLists,
        values: &mut BlockValues,
    ) -> Option<usize> {
        lists.particles.clear();
        lists.rows.clear();
        lists.sizes.clear();
        let origin = [0, 1, 2].map(|a| key[a] as f64 * BLOCK_EDGE as f64);
        let rc = self.radius_cells;
        let rc2 = rc * rc;
        let inv_rc2 = 1.0 / rc2;
        // A particle of half-block j lies in cells [4j, 4j + 4): it reaches the block's
        // vertices [8k, 8k + 7] only for 2k − ⌈R/4h⌉ ≤ j ≤ 2k + 1 + ⌈R/4h⌉.
        let (first, last) = (
            key.map(|k| 2 * k - self.half_reach),
            key.map(|k| 2 * k + 1 + self.half_reach),
        );
        for hz in first[2]..=last[2] {
            for hy in first[1]..=last[1] {
                let run = self.index.run(hy, hz, first[0], last[0]);
                for (k, p) in self.sorted[run.clone()].iter().enumerate() {
                    let (rc, inv_rc2) = if SIZED {
                        let rc = self.radius_cells * self.ratios[run.start + k];
                        (rc, 1.0 / (rc * rc))
                    } else {
                        (rc, inv_rc2)
                    };
                    let p = p.as_dvec3() * self.inv_h;
                    // Particle in block-local cell units.
                    let x = [
                        (p.x - origin[0]) as f32,
                        (p.y - origin[1]) as f32,
                        (p.z - origin[2]) as f32,
                    ];
                    let lo = x.map(|c| ((c - rc).ceil() as i32).max(0));
                    let hi = x.map(|c| ((c + rc).floor() as i32).min(BLOCK_EDGE - 1));
                    if lo[0] > hi[0] || lo[1] > hi[1] || lo[2] > hi[2] {
                        continue;
                    }
                    let index = lists.particles.len();
                    if index % 64 == 0 {
                        lists.rows.push([0; ROWS]);
                    }
                    let group = lists.rows.last_mut().expect("a group");
                    group[index % 64] = row_mask(x, lo, hi, inv_rc2);
                    lists.particles.push(x);
                    if SIZED {
                        lists.sizes.push([inv_rc2, self.ratios[run.start + k]]);
                    }
                }
            }
        }
        let n = lists.particles.len();
        if n == 0 {
            return None;
        }
        for group in &mut lists.rows {
            transpose_bits(group);
        }
        let mut in_band = 0;
        for row in 0..ROWS {
            if lists.rows.iter().all(|group| group[row] == 0) {
                // No particle within reach of the row: outside the band.
                values[row * ROW..][..ROW].fill(self.options.outside_value());
                continue;
            }
            let (b, c) = ((row % ROW) as f32, (row / ROW) as f32);
            let mut sums = [[0.0f32; ROW]; SUMS];
            for (g, (group, members)) in lists.particles.chunks(64).zip(&lists.rows).enumerate() {
                let mut bits = members[row];
                while bits != 0 {
                    let k = bits.trailing_zeros() as usize;
                    let x = group[k];
                    let [inv_rc2, ratio] = if SIZED {
                        lists.sizes[g * 64 + k]
                    } else {
                        [inv_rc2, 1.0]
                    };
                    accumulate_row::<SIZED>(&mut sums, x[0], b - x[1], c - x[2], inv_rc2, ratio);
                    bits &= bits - 1;
                }
            }
            in_band += self.finalize_row(&sums, row, values);
        }
        Some(in_band)
    }
}

impl<const SIZED: bool> BlockKernel<'_, SIZED> {
    /// Turns one row's running sums into field values; returns how many of its vertices
    /// are in the band (`Σw > 0`).
    #[allow(clippy::needless_range_loop)]
    #[inline(always)]
    fn finalize_row(
        &self,
        row_sums: &[[f32; ROW]; SUMS],
        row: usize,
        values: &mut BlockValues,
    ) -> usize {
        let r = self.options.particle_radius as f64;
        let (t_low, t_high) = (self.options.t_low as f64, self.options.t_high as f64);
        // Each quantity as a lane array, so that the Jacobians and their eigenvalues run
        // as vector instructions. Lanes outside the band (Σw = 0) compute garbage that is
        // not stored. (Plain loops rather than closures: they stay inside the AVX2 copy of
        // the kernel.)
        let mut sums = [[0.0f64; ROW]; SUMS];
        for k in 0..SUMS {
            for i in 0..ROW {
                sums[k][i] = row_sums[k][i] as f64;
            }
        }
        let w = sums[0];
        // One division per vertex, then products, instead of twelve f64 divisions (4M
        // scene: field 2.02–2.07 → 1.99–2.00 s; the outputs of the eight reference runs
        // and of the 4M scene stayed byte for byte the same).
        let mut inv_w = [0.0f64; ROW];
        for i in 0..ROW {
            inv_w[i] = 1.0 / w[i];
        }
        // v − vbar = Σ w r / Σ w.
        let mut d = [[0.0f64; ROW]; 3];
        for a in 0..3 {
            for i in 0..ROW {
                d[a][i] = sums[1 + a][i] * inv_w[i];
            }
        }
        // x_i = v − r_i gives J_ab = ((v − vbar)_a Σ∂_b w − Σ g r_a r_b) / Σ w, with
        // Σ∂_b w = sums[4 + b] and the symmetric Σ g r_a r_b in sums[7..13].
        const SYMMETRIC: [usize; 9] = [7, 8, 9, 8, 10, 11, 9, 11, 12];
        let mut jac = [[0.0f64; ROW]; 9];
        for a in 0..3 {
            for b in 0..3 {
                for i in 0..ROW {
                    jac[a * 3 + b][i] =
                        (d[a][i] * sums[4 + b][i] - sums[SYMMETRIC[a * 3 + b]][i]) * inv_w[i];
                }
            }
        }
        let ev = largest_eigenvalue_real_part_lanes(&jac);
        let mut in_band = 0;
        for i in 0..ROW {
            let idx = row * ROW + i;
            if w[i] <= 0.0 {
                values[idx] = self.options.outside_value();
                continue;
            }
            in_band += 1;
            let f = concavity_factor(ev[i], t_low, t_high);
            let dist_cells = (d[0][i] * d[0][i] + d[1][i] * d[1][i] + d[2][i] * d[2][i]).sqrt();
            let r = if SIZED {
                r * (sums[13][i] * inv_w[i])
            } else {
                r
            };
            values[idx] = (dist_cells * self.h - r * f) as f32;
        }
        in_band
    }
}

/// Number of running sums per vertex: Σw, Σw·r (3), Σ∇w (3), Σ g·r⊗r (6, symmetric),
/// with `r = v − x_i` (cells) and `∇w_i = g·r`, `g = −6 (1 − s²)² / R²`; and for
/// particles of several sizes Σw·ρ (left at 0 otherwise).
const SUMS: usize = 14;

/// Adds one particle's terms to one row of vertices' running sums (`x`: the particle's
/// block-local x (cells), `ry`, `rz`: the row's offsets from it, `inv_rc2 = 1 / R²` in
/// cells; `ratio`: its radius in multiples of r, summed when `SIZED`). Lanes outside the
/// influence sphere get `q = 0`, hence
/// zero weight and zero gradient: adding them leaves every sum as it was.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn accumulate_row<const SIZED: bool>(
    sums: &mut [[f32; ROW]; SUMS],
    x: f32,
    ry: f32,
    rz: f32,
    inv_rc2: f32,
    ratio: f32,
) {
    let ryz2 = ry * ry + rz * rz;
    let g_scale = -6.0 * inv_rc2;
    let [s0, s1, s2, s3, s4, s5, s6, s7, s8, s9, s10, s11, s12, s13] = sums;
    for i in 0..ROW {
        let rx = i as f32 - x;
        let q = (1.0 - (rx * rx + ryz2) * inv_rc2).max(0.0);
        let q2 = q * q;
        let w = q2 * q;
        let g = q2 * g_scale;
        let (gx, gy, gz) = (g * rx, g * ry, g * rz);
        s0[i] += w;
        s1[i] = w.mul_add(rx, s1[i]);
        s2[i] = w.mul_add(ry, s2[i]);
        s3[i] = w.mul_add(rz, s3[i]);
        s4[i] += gx;
        s5[i] += gy;
        s6[i] += gz;
        s7[i] = gx.mul_add(rx, s7[i]);
        s8[i] = gx.mul_add(ry, s8[i]);
        s9[i] = gx.mul_add(rz, s9[i]);
        s10[i] = gy.mul_add(ry, s10[i]);
        s11[i] = gy.mul_add(rz, s11[i]);
        s12[i] = gz.mul_add(rz, s12[i]);
        if SIZED {
            s13[i] = w.mul_add(ratio, s13[i]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_vector_kernel_gives_the_portable_kernel_values_bit_for_bit() {
        // A jittered block of particles with a loose film and a few strays: every branch
        // of the eigenvalue (one or three real roots, flat and sharp neighbourhoods).
        let r = 0.01f32;
        let mut rng = crate::test_rng::TestRng::new(5);
        let mut jitter = || (rng.unit_f32() - 0.5) * r;
        let mut positions = Vec::new();
        for z in 0..10 {
            for y in 0..14 {
                for x in 0..12 {
                    let p = Vec3::new(x as f32, y as f32, z as f32) * 2.0 * r;
                    positions.push(p + Vec3::new(jitter(), jitter(), jitter()));
                }
            }
        }
        for k in 0..40 {
            let t = k as f32 * 0.7;
            positions.push(Vec3::new(t.sin(), 0.3 * t.cos(), 0.6) * 0.3 + Vec3::splat(0.12));
        }
        let options = FieldOptions::new(r);
        let ratios: Vec<f32> = (0..positions.len())
            .map(|i| 0.5 + 1.5 * (i % 7) as f32 / 6.0)
            .collect();
        let sized = Sizes {
            ratios: &ratios,
            largest: 2.0,
        };
        for sizes in [None, Some(sized)] {
            let (portable, _) = compute_blocks_with(&positions, sizes, &options, None, false);
            let (vector, _) = compute_blocks_with(&positions, sizes, &options, None, true);
            assert_same_blocks_bit_for_bit(&portable, &vector);
        }
    }

    /// Both fields hold the same blocks (more than 10) with bit-identical values.
    fn assert_same_blocks_bit_for_bit(a: &SparseField, b: &SparseField) {
        assert!(a.blocks().count() > 10);
        assert_eq!(a.blocks().count(), b.blocks().count());
        for (key, values) in a.blocks() {
            let other = b.block(key).expect("same blocks");
            for (x, y) in values.iter().zip(other.iter()) {
                assert_eq!(x.to_bits(), y.to_bits(), "block {key:?}");
            }
        }
    }

    #[test]
    fn particles_already_in_half_block_order_give_the_sorted_values() {
        // A shuffled cloud, and the same cloud sorted as the field sorts it (home
        // half-block, then index): the second is taken as it is, the first is sorted
        // into the second, and the values must agree bit for bit.
        let r = 0.01f32;
        let mut rng = crate::test_rng::TestRng::new(17);
        let shuffled: Vec<Vec3> = (0..3000)
            .map(|_| Vec3::new(rng.unit_f32(), rng.unit_f32(), rng.unit_f32()) * 0.3 - 0.1)
            .collect();
        let options = FieldOptions::new(r);
        let inv_h = 1.0 / options.cell_size_world();
        let mut order: Vec<usize> = (0..shuffled.len()).collect();
        order.sort_by_key(|&i| {
            let k = home_half_block(shuffled[i], inv_h);
            (k[2], k[1], k[0], i)
        });
        let sorted: Vec<Vec3> = order.iter().map(|&i| shuffled[i]).collect();
        let (from_shuffled, _) = compute_blocks(&shuffled, None, &options, None);
        let (from_sorted, _) = compute_blocks(&sorted, None, &options, None);
        assert_same_blocks_bit_for_bit(&from_shuffled, &from_sorted);
    }
}
