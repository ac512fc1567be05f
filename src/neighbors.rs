//! Neighbour search for the isolation test. A tile's particles, sorted by a cubic cell
//! (their home half-block), are searched as they lie ([`find_isolated_sorted`]): the cells
//! of one row are one run of them. The tests' oracle bins particles in any order into
//! cubic cells of edge equal to the search radius kept in a hashbrown map, so a query
//! visits the 27 cells around a point (`CellHash`).

use glam::Vec3;
#[cfg(test)]
use hashbrown::HashMap;
use rayon::prelude::*;

#[cfg(test)]
/// Particles binned into cells of a fixed edge length (world units).
pub struct CellHash {
    cell_size: f32,
    /// Particle indices sorted by cell, ascending index within a cell.
    order: Vec<u32>,
    /// Cell key → range in `order`.
    cells: HashMap<[i32; 3], (u32, u32)>,
}

#[cfg(test)]
impl CellHash {
    /// Bins `positions` into cells of edge `cell_size` (world units, > 0).
    pub fn new(positions: &[Vec3], cell_size: f32) -> Self {
        let inv = 1.0 / cell_size;
        let keys: Vec<[i32; 3]> = positions.par_iter().map(|p| cell_of(*p, inv)).collect();
        let (order, cells) = crate::grid::bin_by_key(&keys);
        CellHash {
            cell_size,
            order,
            cells,
        }
    }

    /// True when `stop(j)` holds for some particle `j` in the 27 cells around `p`; the
    /// point's own cell is searched first and the search ends at the first hit.
    pub fn any_candidate(&self, p: Vec3, mut stop: impl FnMut(u32) -> bool) -> bool {
        let c = cell_of(p, 1.0 / self.cell_size);
        let own = self.cells.get(&c).copied();
        if let Some((s, e)) = own {
            if self.order[s as usize..e as usize].iter().any(|&j| stop(j)) {
                return true;
            }
        }
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    if (dx, dy, dz) == (0, 0, 0) {
                        continue;
                    }
                    if let Some(&(s, e)) = self.cells.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                        if self.order[s as usize..e as usize].iter().any(|&j| stop(j)) {
                            return true;
                        }
                    }
                }
            }
        }
        false
    }
}

#[cfg(test)]
fn cell_of(p: Vec3, inv: f32) -> [i32; 3] {
    [
        (p.x * inv).floor() as i32,
        (p.y * inv).floor() as i32,
        (p.z * inv).floor() as i32,
    ]
}

#[cfg(test)]
/// Marks the particles that have no other particle strictly closer than `radius` (world
/// units). Output is independent of thread count.
pub fn find_isolated(positions: &[Vec3], radius: f32) -> Vec<bool> {
    find_isolated_where(positions, radius, &vec![true; positions.len()])
}

#[cfg(test)]
/// [`find_isolated`] evaluated only where `wanted` is true (`false` elsewhere).
pub fn find_isolated_where(positions: &[Vec3], radius: f32, wanted: &[bool]) -> Vec<bool> {
    isolated_in(&CellHash::new(positions, radius), positions, radius, wanted)
}

/// Particles on either side of a particle in the sorted order that
/// [`find_isolated_sorted`] tries before any lookup.
const NEXT_IN_ORDER: usize = 4;

/// [`find_isolated_where`] for positions sorted by a cubic cell of edge `cell_size`
/// (world units): `cells[i]` is the cell of particle `i` (`floor(p / cell_size)`, in any
/// rounding that keeps a point within one cell edge of its cell), in (z, y, x) order. No
/// second binning and no hash of cells: the cells of one (y, z) row are one run of the
/// particles, found by one lookup and two binary searches. The same test on the same
/// pairs, so the same flags.
///
/// With `sizes` (the particles' radius ratios and the largest, for particles of several
/// sizes) particle i is isolated when no other lies within its own reach
/// `radius·ratios[i]`: a small particle beside a large one can be isolated while the
/// large one is not.
pub(crate) fn find_isolated_sorted(
    positions: &[Vec3],
    cells: &[[i32; 3]],
    cell_size: f32,
    radius: f32,
    sizes: Option<(&[f32], f32)>,
    wanted: &[bool],
) -> Vec<bool> {
    // The particles of every row of cells.
    let rows = crate::grid::row_ranges(cells.iter().copied());
    let largest = sizes.map_or(radius, |(_, largest)| radius * largest.max(1.0));
    // Two points closer than d lie at most ⌊d / edge⌋ + 1 cells apart on every axis (a
    // hair more for d, against the rounding of their cells).
    let reach = (largest as f64 / cell_size as f64 * (1.0 + 1e-6)).floor() as i32 + 1;
    // The rows searched, (dy, dz) from the particle's: its own row first, where most
    // particles have a neighbour.
    let row_offsets: Vec<(i32, i32)> = std::iter::once((0, 0))
        .chain(
            (-reach..=reach)
                .flat_map(|dz| (-reach..=reach).map(move |dy| (dy, dz)))
                .filter(|&d| d != (0, 0)),
        )
        .collect();
    let r2 = radius * radius;
    positions
        .par_iter()
        .zip(cells)
        .enumerate()
        .map(|(i, (&p, c))| {
            if !wanted[i] {
                return false;
            }
            let r2 = match sizes {
                None => r2,
                Some((ratios, _)) => (radius * ratios[i]) * (radius * ratios[i]),
            };
            let close = |j: usize| j != i && (positions[j] - p).length_squared() < r2;
            // The particles next to it in the sorted order first (mostly of its own cell),
            // then the rows.
            let mut near =
                i.saturating_sub(NEXT_IN_ORDER)..(i + NEXT_IN_ORDER + 1).min(cells.len());
            if near.any(close) {
                return false;
            }
            !row_offsets.iter().any(|&(dy, dz)| {
                let Some(&(a, b)) = rows.get(&[c[1] + dy, c[2] + dz]) else {
                    return false;
                };
                let row = &cells[a as usize..b as usize];
                let lo = a as usize + row.partition_point(|k| k[0] < c[0] - reach);
                let hi = a as usize + row.partition_point(|k| k[0] <= c[0] + reach);
                (lo..hi).any(close)
            })
        })
        .collect()
}

#[cfg(test)]
/// The isolation flags of `positions` with `hash` as the search structure.
fn isolated_in(hash: &CellHash, positions: &[Vec3], radius: f32, wanted: &[bool]) -> Vec<bool> {
    let r2 = radius * radius;
    positions
        .par_iter()
        .enumerate()
        .map(|(i, &p)| {
            if !wanted[i] {
                return false;
            }
            !hash.any_candidate(p, |j| {
                j as usize != i && (positions[j as usize] - p).length_squared() < r2
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_rng::TestRng;

    #[test]
    fn isolation_matches_brute_force() {
        let mut rng = TestRng::new(7);
        let pts: Vec<Vec3> = (0..600)
            .map(|_| Vec3::new(rng.unit_f32(), rng.unit_f32(), rng.unit_f32()) * 4.0 - 2.0)
            .collect();
        let radius = 0.3;
        let fast = find_isolated(&pts, radius);
        for (i, p) in pts.iter().enumerate() {
            let brute = pts
                .iter()
                .enumerate()
                .all(|(j, q)| j == i || (*q - *p).length_squared() >= radius * radius);
            assert_eq!(fast[i], brute, "particle {i}");
        }
        assert!(fast.iter().any(|&b| b) && fast.iter().any(|&b| !b));
    }

    #[test]
    fn isolation_from_sorted_cells_matches_the_binned_search() {
        // Clusters and strays, binned by cubes smaller and larger than the radius.
        let mut rng = TestRng::new(11);
        let mut pts: Vec<Vec3> = (0..800)
            .map(|_| Vec3::new(rng.unit_f32(), rng.unit_f32(), rng.unit_f32()) * 6.0 - 3.0)
            .collect();
        pts.extend((0..200).map(|k| Vec3::splat(0.7) + Vec3::new(k as f32 * 0.01, 0.0, 0.0)));
        let radius = 0.35;
        let wanted: Vec<bool> = (0..pts.len()).map(|i| i % 7 != 3).collect();
        let expected = find_isolated_where(&pts, radius, &wanted);
        assert!(expected.iter().filter(|&&b| b).count() > 20);
        for edge in [0.1f32, 0.35, 1.0] {
            let bin = |p: &Vec3| (*p / edge).floor().as_ivec3().to_array();
            let mut order: Vec<usize> = (0..pts.len()).collect();
            order.sort_by_key(|&i| {
                let b = bin(&pts[i]);
                (b[2], b[1], b[0], i)
            });
            let sorted: Vec<Vec3> = order.iter().map(|&i| pts[i]).collect();
            let sorted_wanted: Vec<bool> = order.iter().map(|&i| wanted[i]).collect();
            let cells: Vec<[i32; 3]> = sorted.iter().map(bin).collect();
            let flags = find_isolated_sorted(&sorted, &cells, edge, radius, None, &sorted_wanted);
            for (k, &i) in order.iter().enumerate() {
                assert_eq!(flags[k], expected[i], "particle {i}, bin edge {edge}");
            }
        }
    }
}
