//! The field of anisotropic kernels ([`super::kernels`]): the same sparse lattice,
//! blocks and evaluation order as the isotropic field (`super`), each particle weighted
//! by its own ellipsoid.
//!
//! With `M_i` the quadratic form of particle `i`'s ellipsoid around its centre `c_i`,
//! `s_i² = (v − c_i)ᵀ M_i (v − c_i)` and `w_i = max(0, 1 − s_i²)³`:
//! * `vbar(v) = Σ w_i c_i / Σ w_i`,
//! * `n(v)` the unit vector along `−∇Σ w_i = 6 Σ (1 − s_i²)² M_i (v − c_i)`, the direction
//!   in which the particles thin out,
//! * `phi(v) = (v − vbar(v))·n(v) − ρ_s·r`, `ρ_s` =
//!   [`super::AnisotropyOptions::surface_distance`] (`|v − vbar(v)| − ρ_s·r`
//!   where the gradient vanishes).
//!
//! This is the field of Zhu and Bridson 2005 that Solenthaler et al. build on, with Yu and
//! Turk's kernels as the weights, chosen over Yu and Turk's density field by measurement
//! (`docs/quality.md`): the weighted mean averages the heights of the outer particles
//! over a disc along the surface, where a sum of densities follows each particle's
//! ellipsoid (dimpled faces, ridges along edges). Zhu and Bridson take the whole length
//! of `v − vbar`; near an edge of the fluid the disc is cut off and `vbar` moves along the
//! surface, away from the edge, which counts as depth and rounds the edge over about 5 r.
//! Only the part of `v − vbar` across the surface counts here (flatter faces and sharper
//! edges, measured in `docs/quality.md`). The concavity factor of the isotropic field is
//! not needed: the stretched kernels do not pull `vbar` into concave corners the
//! way spheres of radius `R` do. `phi` is a distance, so coverage and the iso offset work
//! as with the isotropic field.
//!
//! **Particles of several sizes** (a radius attribute): each kernel was built at its own
//! radius `r_i` ([`super::kernels`]), and the surface distance is `ρ_s·rbar(v)` with
//! `rbar(v) = Σ w_i r_i / Σ w_i`, the weighted mean radius of the particles at `v` (one more
//! running sum, `Σ w·ρ_i` with `ρ_i = r_i / r`).
//!
//! **Evaluation order:** kernels binned by the home half-block of their *centre*, in
//! (z, y, x) order, then in the order given (the canonical order of the tile engine), as
//! the isotropic field does; sums in f32 on block-local coordinates.

use super::candidates::candidate_blocks;
use super::evaluate::{evaluate_blocks, BlockEvaluator, ROW, ROWS};
use super::kernels::ParticleKernel;
use super::rows::{transpose_bits, HalfRowIndex};
use super::{kernel_reach, FieldOptions, FieldStats, Sizes};
use crate::grid::{
    home_half_block, BlockKey, BlockRange, BlockValues, SparseField, BLOCK_EDGE, HALF_BLOCK_EDGE,
};
use rayon::prelude::*;

/// A kernel ready for the lattice: centre, quadratic form and bounding box. 48 bytes,
/// held beside the field's blocks while they are evaluated (the 4M still run's peak):
/// the centre stays in world units (f32) and is taken to cells (f64) where it is read,
/// the same product as before, and the radii of sized particles are a separate array.
#[derive(Clone, Copy)]
struct Prepared {
    /// Centre, world units (the kernel's own).
    centre: [f32; 3],
    /// Quadratic form in cells⁻², `[xx, xy, xz, yy, yz, zz]`.
    form: [f32; 6],
    /// Half-extents of the bounding box, cells.
    extent: [f32; 3],
}

/// Number of running sums per vertex: Σw, Σw·r (3) and Σ(1 − s²)²·M r (3), with
/// `r = v − c` in cells, and for particles of several sizes Σw·ρ (left at 0 otherwise).
const SUMS: usize = 8;

/// Computes the blocks of the anisotropic field within `range` (all blocks when `None`)
/// from `kernels`, which must include every kernel that reaches those blocks, in a
/// canonical order. Coverage and the iso offset are applied afterwards, as for the
/// isotropic field. Options must be valid. The kernels are dropped once prepared for the
/// lattice, before the blocks are evaluated: the kernels (64 bytes a particle) never sit
/// beside the field's blocks, only the prepared copy (48 bytes) does. `sizes`: each kernel's
/// particle radius, multiples of r, for particles of several sizes.
pub(crate) fn compute_blocks(
    kernels: Vec<ParticleKernel>,
    sizes: Option<Sizes<'_>>,
    options: &FieldOptions,
    range: Option<BlockRange>,
) -> (SparseField, FieldStats) {
    compute_blocks_with(kernels, sizes, options, range, true)
}

/// [`compute_blocks`]; `simd`: the AVX2 copy of the kernel may be used (the values are
/// the same either way).
fn compute_blocks_with(
    kernels: Vec<ParticleKernel>,
    sizes: Option<Sizes<'_>>,
    options: &FieldOptions,
    range: Option<BlockRange>,
    simd: bool,
) -> (SparseField, FieldStats) {
    let h = options.cell_size_world();
    let inv_h = 1.0 / h;
    let halves: Vec<BlockKey> = kernels
        .par_iter()
        .map(|k| home_half_block(k.centre, inv_h))
        .collect();
    let order = crate::grid::sort_by_key_zyx(&halves);
    let runs = crate::grid::key_runs(order.iter().map(|&i| halves[i as usize]));
    drop(halves);
    let sorted: Vec<Prepared> = order
        .par_iter()
        .map(|&i| {
            let k = &kernels[i as usize];
            Prepared {
                centre: k.centre.to_array(),
                form: k.quadratic_form(h).map(|v| v as f32),
                extent: k.half_extents(h).map(|v| v as f32),
            }
        })
        .collect();
    // The radius of each of `sorted`, multiples of r (sized particles only).
    let ratios: Vec<f32> = match sizes {
        Some(s) => order.par_iter().map(|&i| s.ratios[i as usize]).collect(),
        None => Vec::new(),
    };
    drop(order);
    let particles = kernels.len();
    drop(kernels);
    let reach_cells = kernel_reach(options, sizes) / options.cell_size;
    let half_reach = (reach_cells / HALF_BLOCK_EDGE as f32).ceil() as i32;
    let candidates = candidate_blocks(runs.iter().map(|r| r.0), half_reach, range);
    let index = HalfRowIndex::new(&runs);
    drop(runs);
    let surface = options.anisotropy.surface_distance as f64 * options.particle_radius as f64;
    let outside = options.outside_value();
    match sizes {
        None => {
            let evaluator = Evaluator::<false> {
                sorted: &sorted,
                ratios: &ratios,
                index: &index,
                half_reach,
                h,
                inv_h,
                outside,
                surface,
            };
            evaluate_blocks(&evaluator, &candidates, particles, options, simd)
        }
        Some(_) => {
            let evaluator = Evaluator::<true> {
                sorted: &sorted,
                ratios: &ratios,
                index: &index,
                half_reach,
                h,
                inv_h,
                outside,
                surface,
            };
            evaluate_blocks(&evaluator, &candidates, particles, options, simd)
        }
    }
}

/// Per-thread scratch of one block.
#[derive(Default)]
struct Scratch {
    /// Block-local centres (cells) and forms of the kernels within reach, in scan order.
    particles: Vec<([f32; 3], [f32; 6])>,
    /// Per group of 64 particles, per row: a bit per particle of the group whose
    /// bounding box meets the row.
    rows: Vec<[u64; ROWS]>,
    /// The radius of each of `particles`, multiples of r (sized only).
    ratios: Vec<f32>,
}

/// `SIZED`: particles of several sizes (the mean radius is summed).
struct Evaluator<'a, const SIZED: bool> {
    sorted: &'a [Prepared],
    /// The radius of each of `sorted`, multiples of r (`SIZED` only).
    ratios: &'a [f32],
    index: &'a HalfRowIndex,
    /// Half-blocks, per axis, beyond a block's own two whose kernels can reach it.
    half_reach: i32,
    h: f64,
    /// `1 / h`.
    inv_h: f64,
    outside: f32,
    /// `ρ_s·r`, world units.
    surface: f64,
}

impl<const SIZED: bool> BlockEvaluator for Evaluator<'_, SIZED> {
    type Scratch = Scratch;

    fn scratch(&self) -> Scratch {
        Scratch::default()
    }

    /// The kernels whose bounding boxes meet the block, with the rows each one meets as a
    /// bit mask, transposed into per-row sets; then each row sums its kernels in scan
    /// order and is finalised.
    #[inline(always)]
    fn evaluate_block(
        &self,
        key: BlockKey,
        scratch: &mut Scratch,
        values: &mut BlockValues,
    ) -> Option<usize> {
        scratch.particles.clear();
        scratch.rows.clear();
        scratch.ratios.clear();
        let origin = [0, 1, 2].map(|a| key[a] as f64 * BLOCK_EDGE as f64);
        let (first, last) = (
            key.map(|k| 2 * k - self.half_reach),
            key.map(|k| 2 * k + 1 + self.half_reach),
        );
        for hz in first[2]..=last[2] {
            for hy in first[1]..=last[1] {
                let run = self.index.run(hy, hz, first[0], last[0]);
                for (n, p) in self.sorted[run.clone()].iter().enumerate() {
                    let x = [0, 1, 2].map(|a| (p.centre[a] as f64 * self.inv_h - origin[a]) as f32);
                    let lo = [0, 1, 2].map(|a| ((x[a] - p.extent[a]).ceil() as i32).max(0));
                    let hi = [0, 1, 2]
                        .map(|a| ((x[a] + p.extent[a]).floor() as i32).min(BLOCK_EDGE - 1));
                    if lo[0] > hi[0] || lo[1] > hi[1] || lo[2] > hi[2] {
                        continue;
                    }
                    let index = scratch.particles.len();
                    if index % 64 == 0 {
                        scratch.rows.push([0; ROWS]);
                    }
                    // The rows lo[1]..=hi[1] of the planes lo[2]..=hi[2].
                    let y_bits = (1u64 << (hi[1] + 1)) - (1u64 << lo[1]);
                    let z_bytes = (u64::MAX >> (ROW as i32 * (BLOCK_EDGE - 1 - hi[2])))
                        & (u64::MAX << (ROW as i32 * lo[2]));
                    let group = scratch.rows.last_mut().expect("a group");
                    group[index % 64] = (y_bits * 0x0101_0101_0101_0101) & z_bytes;
                    scratch.particles.push((x, p.form));
                    if SIZED {
                        scratch.ratios.push(self.ratios[run.start + n]);
                    }
                }
            }
        }
        if scratch.particles.is_empty() {
            return None;
        }
        for group in &mut scratch.rows {
            transpose_bits(group);
        }
        let mut in_band = 0;
        for row in 0..ROWS {
            if scratch.rows.iter().all(|group| group[row] == 0) {
                values[row * ROW..][..ROW].fill(self.outside);
                continue;
            }
            let (b, c) = ((row % ROW) as f32, (row / ROW) as f32);
            let mut sums = [[0.0f32; ROW]; SUMS];
            for (g, (group, members)) in scratch.particles.chunks(64).zip(&scratch.rows).enumerate()
            {
                let mut bits = members[row];
                while bits != 0 {
                    let k = bits.trailing_zeros() as usize;
                    let (x, form) = &group[k];
                    let ratio = if SIZED {
                        scratch.ratios[g * 64 + k]
                    } else {
                        1.0
                    };
                    accumulate_row::<SIZED>(&mut sums, x, b, c, form, ratio);
                    bits &= bits - 1;
                }
            }
            in_band += self.finalize_row(&sums, row, values);
        }
        Some(in_band)
    }
}

impl<const SIZED: bool> Evaluator<'_, SIZED> {
    /// Turns one row's sums into field values; returns how many of its vertices are in
    /// the band (`Σw > 0`).
    #[allow(clippy::needless_range_loop)]
    #[inline(always)]
    fn finalize_row(
        &self,
        sums: &[[f32; ROW]; SUMS],
        row: usize,
        values: &mut BlockValues,
    ) -> usize {
        let mut in_band = 0;
        for i in 0..ROW {
            let idx = row * ROW + i;
            let w = sums[0][i] as f64;
            if w <= 0.0 {
                values[idx] = self.outside;
                continue;
            }
            in_band += 1;
            let inv_w = 1.0 / w;
            let d = [1, 2, 3].map(|k| sums[k][i] as f64 * inv_w);
            let g = [4, 5, 6].map(|k| sums[k][i] as f64);
            let g_len = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
            let dist_cells = if g_len > 0.0 {
                (d[0] * g[0] + d[1] * g[1] + d[2] * g[2]) / g_len
            } else {
                (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
            };
            let surface = if SIZED {
                self.surface * (sums[7][i] as f64 * inv_w)
            } else {
                self.surface
            };
            values[idx] = (dist_cells * self.h - surface) as f32;
        }
        in_band
    }
}

/// Adds one kernel's terms to one row of vertices' running sums (`x`: the kernel's
/// block-local centre, cells; `b`, `c`: the row's y and z; `m`: its quadratic form;
/// `ratio`: its radius in multiples of r, summed when `SIZED`).
/// Lanes outside the ellipsoid get zero weight, which leaves every sum as it was.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn accumulate_row<const SIZED: bool>(
    sums: &mut [[f32; ROW]; SUMS],
    x: &[f32; 3],
    b: f32,
    c: f32,
    m: &[f32; 6],
    ratio: f32,
) {
    let (ry, rz) = (b - x[1], c - x[2]);
    // s² = m0 rx² + 2 (m1 ry + m2 rz) rx + (m3 ry² + 2 m4 ry rz + m5 rz²);
    // M r = (m0 rx + a_x, m1 rx + a_y, m2 rx + a_z).
    let a_x = m[1] * ry + m[2] * rz;
    let a_y = m[3] * ry + m[4] * rz;
    let a_z = m[4] * ry + m[5] * rz;
    let s_yz = m[3] * ry * ry + 2.0 * m[4] * ry * rz + m[5] * rz * rz;
    let s_x = 2.0 * a_x;
    let [s0, s1, s2, s3, g0, g1, g2, s4] = sums;
    for i in 0..ROW {
        let rx = i as f32 - x[0];
        let s2_ = m[0].mul_add(rx, s_x).mul_add(rx, s_yz);
        let q = (1.0 - s2_).max(0.0);
        let q2 = q * q;
        let w = q2 * q;
        s0[i] += w;
        s1[i] = w.mul_add(rx, s1[i]);
        s2[i] = w.mul_add(ry, s2[i]);
        s3[i] = w.mul_add(rz, s3[i]);
        g0[i] = q2.mul_add(m[0].mul_add(rx, a_x), g0[i]);
        g1[i] = q2.mul_add(m[1].mul_add(rx, a_y), g1[i]);
        g2[i] = q2.mul_add(m[2].mul_add(rx, a_z), g2[i]);
        if SIZED {
            s4[i] = w.mul_add(ratio, s4[i]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::Kernel;

    #[test]
    fn the_vector_kernel_gives_the_portable_kernel_values_bit_for_bit() {
        let r = 0.01f32;
        let mut rng = crate::test_rng::TestRng::new(5);
        let mut jitter = || (rng.unit_f32() - 0.5) * r;
        let mut positions = Vec::new();
        for z in 0..10 {
            for y in 0..8 {
                for x in 0..12 {
                    let p = glam::Vec3::new(x as f32, y as f32, z as f32) * 2.0 * r;
                    positions.push(p + glam::Vec3::new(jitter(), jitter(), jitter()));
                }
            }
        }
        let options = FieldOptions {
            kernel: Kernel::Anisotropic,
            ..FieldOptions::new(r)
        };
        let (kernels, stats) = crate::field::compute_kernels(&positions, &options).unwrap();
        assert!(stats.mean_stretch > 1.05, "{stats:?}");
        // Plain, and with radii of 0.5–2 r (particles of several sizes).
        let ratios: Vec<f32> = (0..kernels.len())
            .map(|i| 0.5 + 1.5 * (i % 7) as f32 / 6.0)
            .collect();
        let sized = Sizes {
            ratios: &ratios,
            largest: 2.0,
        };
        for sizes in [None, Some(sized)] {
            let (portable, _) = compute_blocks_with(kernels.clone(), sizes, &options, None, false);
            let (vector, _) = compute_blocks_with(kernels.clone(), sizes, &options, None, true);
            assert!(portable.blocks().count() > 10);
            assert_eq!(portable.blocks().count(), vector.blocks().count());
            for (key, values) in portable.blocks() {
                let other = vector.block(key).expect("same blocks");
                for (x, y) in values.iter().zip(other.iter()) {
                    assert_eq!(x.to_bits(), y.to_bits(), "block {key:?}");
                }
            }
        }
    }

    /// Radii all equal to r through the sized evaluation give the plain field's values
    /// (the mean radius of equal radii is r to within f32 rounding).
    #[test]
    fn ratios_of_one_give_the_plain_field() {
        let r = 0.01f32;
        let positions: Vec<glam::Vec3> = (0..600)
            .map(|i| {
                glam::Vec3::new((i % 10) as f32, (i / 10 % 6) as f32, (i / 60) as f32) * 2.0 * r
            })
            .collect();
        let options = FieldOptions {
            kernel: Kernel::Anisotropic,
            ..FieldOptions::new(r)
        };
        let (kernels, _) = crate::field::compute_kernels(&positions, &options).unwrap();
        let ones = vec![1.0f32; kernels.len()];
        let sized = Sizes {
            ratios: &ones,
            largest: 1.0,
        };
        let (plain, _) = compute_blocks(kernels.clone(), None, &options, None);
        let (same, _) = compute_blocks(kernels, Some(sized), &options, None);
        assert_eq!(plain.blocks().count(), same.blocks().count());
        for (key, values) in plain.blocks() {
            let other = same.block(key).expect("same blocks");
            for (x, y) in values.iter().zip(other.iter()) {
                assert!((x - y).abs() <= 1e-6 * r, "block {key:?}: {x} vs {y}");
            }
        }
    }
}
