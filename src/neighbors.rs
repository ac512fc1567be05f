//! Neighbour search with a cell hash: particles binned into cubic cells of edge equal to
//! the search radius, cells kept in a hashbrown map (no dense grid), so a query visits the
//! 27 cells around a point. Particles that are already grouped by a cubic bin (the tiles
//! sort theirs by home block) are searched through those bins instead
//! ([`find_isolated_binned`]), with no second binning.

use glam::Vec3;
use hashbrown::HashMap;
use rayon::prelude::*;

/// Particles binned into cells of a fixed edge length (world units).
pub struct CellHash {
    cell_size: f32,
    /// Particle indices sorted by cell, ascending index within a cell.
    order: Vec<u32>,
    /// Cell key → range in `order`.
    cells: HashMap<[i32; 3], (u32, u32)>,
}

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

    /// Calls `visit(j)` for every particle `j` within the 27 cells around `p` (a superset of
    /// the particles within one cell size of `p`), cells in (z, y, x) order, particles of a
    /// cell in ascending index.
    pub fn for_each_candidate(&self, p: Vec3, mut visit: impl FnMut(u32)) {
        let c = cell_of(p, 1.0 / self.cell_size);
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    if let Some(&(s, e)) = self.cells.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                        for &j in &self.order[s as usize..e as usize] {
                            visit(j);
                        }
                    }
                }
            }
        }
    }
}

fn cell_of(p: Vec3, inv: f32) -> [i32; 3] {
    [
        (p.x * inv).floor() as i32,
        (p.y * inv).floor() as i32,
        (p.z * inv).floor() as i32,
    ]
}

/// Marks the particles that have no other particle strictly closer than `radius` (world
/// units). Output is independent of thread count.
pub fn find_isolated(positions: &[Vec3], radius: f32) -> Vec<bool> {
    find_isolated_where(positions, radius, &vec![true; positions.len()])
}

/// [`find_isolated`] evaluated only where `wanted` is true (`false` elsewhere).
pub fn find_isolated_where(positions: &[Vec3], radius: f32, wanted: &[bool]) -> Vec<bool> {
    let hash = CellHash::new(positions, radius);
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

/// [`find_isolated_where`] for positions already grouped by a cubic bin of edge `bin_edge`
/// (world units): `bins[i]` is the bin of `positions[i]` (as `floor(p / bin_edge)`, in
/// any rounding that keeps a point within one bin edge of its bin), equal bins
/// contiguous. The bins serve as the search cells, so no second binning is needed; the
/// flags are those of [`find_isolated_where`] (the same test on the same pairs).
pub fn find_isolated_binned(
    positions: &[Vec3],
    bins: &[[i32; 3]],
    bin_edge: f32,
    radius: f32,
    wanted: &[bool],
) -> Vec<bool> {
    assert_eq!(positions.len(), bins.len(), "one bin per position");
    let mut ranges: HashMap<[i32; 3], (u32, u32)> = HashMap::new();
    let mut start = 0;
    while start < bins.len() {
        let mut end = start + 1;
        while end < bins.len() && bins[end] == bins[start] {
            end += 1;
        }
        let previous = ranges.insert(bins[start], (start as u32, end as u32));
        assert!(previous.is_none(), "equal bins must be contiguous");
        start = end;
    }
    // Two points closer than d lie at most ⌊d / edge⌋ + 1 bins apart on every axis (a
    // hair more for d, against the rounding of their bins).
    let reach = (radius as f64 / bin_edge as f64 * (1.0 + 1e-6)).floor() as i32 + 1;
    let r2 = radius * radius;
    positions
        .par_iter()
        .enumerate()
        .map(|(i, &p)| {
            if !wanted[i] {
                return false;
            }
            let close = |range: Option<&(u32, u32)>| {
                range.is_some_and(|&(s, e)| {
                    (s as usize..e as usize)
                        .any(|j| j != i && (positions[j] - p).length_squared() < r2)
                })
            };
            let own = bins[i];
            if close(ranges.get(&own)) {
                return false;
            }
            for dz in -reach..=reach {
                for dy in -reach..=reach {
                    for dx in -reach..=reach {
                        if (dx, dy, dz) != (0, 0, 0)
                            && close(ranges.get(&[own[0] + dx, own[1] + dy, own[2] + dz]))
                        {
                            return false;
                        }
                    }
                }
            }
            true
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lcg(seed: &mut u64) -> f32 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*seed >> 40) as f32) / ((1u64 << 24) as f32)
    }

    #[test]
    fn isolation_matches_brute_force() {
        let mut seed = 7;
        let pts: Vec<Vec3> = (0..600)
            .map(|_| Vec3::new(lcg(&mut seed), lcg(&mut seed), lcg(&mut seed)) * 4.0 - 2.0)
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
    fn isolation_from_bins_matches_the_cell_hash() {
        // Clusters and strays, binned by cubes smaller and larger than the radius.
        let mut seed = 11;
        let mut pts: Vec<Vec3> = (0..800)
            .map(|_| Vec3::new(lcg(&mut seed), lcg(&mut seed), lcg(&mut seed)) * 6.0 - 3.0)
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
            let bins: Vec<[i32; 3]> = sorted.iter().map(bin).collect();
            let sorted_wanted: Vec<bool> = order.iter().map(|&i| wanted[i]).collect();
            let flags = find_isolated_binned(&sorted, &bins, edge, radius, &sorted_wanted);
            for (k, &i) in order.iter().enumerate() {
                assert_eq!(flags[k], expected[i], "particle {i}, bin edge {edge}");
            }
        }
    }
}
