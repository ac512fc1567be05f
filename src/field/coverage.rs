//! Particle coverage (see [`FieldOptions::particle_coverage`]): the particles the
//! Solenthaler surface would leave outside (its field, interpolated at the particle, above
//! `−r/4`) are enclosed by `phi ← min(phi, |v − x| − c·r)` around them.
//!
//! **Input:** the field's blocks and the particles that made them. **Output:** the same
//! blocks, lowered around uncovered particles; every other value unchanged. A minimum
//! does not depend on order, so neither the thread count nor the tiling changes it.

use super::{FieldOptions, Sizes};
use crate::grid::BlockRange;
use crate::grid::{local_index, split_coordinate, SparseField, BLOCK_EDGE};
use glam::{DVec3, Vec3};
use rayon::prelude::*;

/// Value, in multiples of `r`, below which a particle's interpolated field value counts
/// as covered.
const UNCOVERED_MARGIN: f64 = 0.25;

/// Applies particle coverage (see [`FieldOptions::particle_coverage`]) to `field`: finds
/// the uncovered particles among `positions` (those with all eight cell corners stored in
/// `field`; a particle whose corners are not all stored is skipped) and lowers the stored
/// values within `c·r` of them, only inside `range` when given. Returns the number of
/// uncovered particles whose home block lies in `count_range` (all when `None`).
///
/// Taking a minimum is order-independent, so the result does not depend on the order of
/// `positions` or on the thread count. Vertices within `c·r + h` are lowered (one ring
/// beyond the sphere, so that its crossings interpolate the sphere on both ends). For
/// exact tiling, `field` must hold every block within `c·r + 2h` of the blocks whose
/// values are used. With `sizes` (aligned with `positions`), particle i is uncovered above
/// `−r_i/4` and its ball has the radius `c·r_i`.
pub(crate) fn apply_coverage(
    field: &mut SparseField,
    positions: &[Vec3],
    sizes: Option<Sizes<'_>>,
    options: &FieldOptions,
    count_range: Option<BlockRange>,
) -> usize {
    if options.particle_coverage <= 0.0 {
        return 0;
    }
    let h = field.cell_size;
    let reference = options.particle_radius as f64;
    let radius_of = |k: usize| match sizes {
        None => reference,
        Some(s) => reference * s.ratios[k] as f64,
    };
    let uncovered: Vec<(Vec3, f64)> = positions
        .par_iter()
        .enumerate()
        .map(|(k, p)| (*p, radius_of(k)))
        .filter(|(p, r)| {
            let threshold = -UNCOVERED_MARGIN * r;
            let g = p.as_dvec3() / h;
            let base = [g.x.floor(), g.y.floor(), g.z.floor()];
            let t = [g.x - base[0], g.y - base[1], g.z - base[2]];
            let b = base.map(|c| c as i32);
            // The cell's corners, from one block lookup when they share a block (7 cells
            // of 8 per axis), else one lookup per corner.
            let (home, local) = (
                b.map(|c| split_coordinate(c).0),
                b.map(|c| split_coordinate(c).1),
            );
            let one_block = local.iter().all(|&l| l + 1 < BLOCK_EDGE);
            let home_values = if one_block {
                let Some(values) = field.block(&home) else {
                    return false;
                };
                Some(values)
            } else {
                None
            };
            let mut value = 0.0;
            for corner in 0..8 {
                let o = [corner & 1, (corner >> 1) & 1, (corner >> 2) & 1];
                let v = match home_values {
                    Some(values) => {
                        values[local_index(local[0] + o[0], local[1] + o[1], local[2] + o[2])]
                    }
                    None => match stored_value(field, [b[0] + o[0], b[1] + o[1], b[2] + o[2]]) {
                        Some(v) => v,
                        None => return false,
                    },
                };
                let weight: f64 = (0..3)
                    .map(|a| if o[a] == 1 { t[a] } else { 1.0 - t[a] })
                    .product();
                value += weight * v as f64;
            }
            value > threshold
        })
        .collect();
    let mut counted = 0;
    for (p, r) in &uncovered {
        let radius = options.particle_coverage as f64 * r;
        let reach_cells = (radius / h).ceil() as i32 + 1;
        let g = p.as_dvec3() / h;
        let home = [g.x, g.y, g.z].map(|c| (c.floor() as i32).div_euclid(BLOCK_EDGE));
        if count_range.is_none_or(|range| range.contains(home)) {
            counted += 1;
        }
        let lo = [g.x, g.y, g.z].map(|c| c.floor() as i32 - reach_cells);
        for k in lo[2]..=lo[2] + 2 * reach_cells + 1 {
            for j in lo[1]..=lo[1] + 2 * reach_cells + 1 {
                for i in lo[0]..=lo[0] + 2 * reach_cells + 1 {
                    let d = (DVec3::new(i as f64, j as f64, k as f64) - g).length() * h;
                    if d >= radius + h {
                        continue;
                    }
                    let (bx, a) = split_coordinate(i);
                    let (by, b) = split_coordinate(j);
                    let (bz, c) = split_coordinate(k);
                    if let Some(block) = field.block_mut(&[bx, by, bz]) {
                        let slot = &mut block[local_index(a, b, c)];
                        *slot = slot.min((d - radius) as f32);
                    }
                }
            }
        }
    }
    counted
}

fn stored_value(field: &SparseField, g: [i32; 3]) -> Option<f32> {
    let (bx, a) = split_coordinate(g[0]);
    let (by, b) = split_coordinate(g[1]);
    let (bz, c) = split_coordinate(g[2]);
    field
        .block(&[bx, by, bz])
        .map(|block| block[local_index(a, b, c)])
}
