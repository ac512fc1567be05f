//! Which blocks the field evaluates: every block with a vertex within reach of a
//! populated home half-block (`super::isotropic`, `super::anisotropic`), found from the half-blocks alone
//! before any particle is read.

use crate::grid::{block_of_half, BlockKey, BlockRange};
use hashbrown::HashMap;
use rayon::prelude::*;

/// The blocks a particle may reach, in (z, y, x) order: those with a vertex within
/// `half_reach` half-blocks (per axis) of a populated half-block (`halves`). A particle is
/// within R of a vertex only if their half-blocks are that close (`half_reach =
/// ⌈R / 4h⌉`), so every block in the band is a candidate; a candidate no particle
/// reaches is dropped after its evaluation. Half-blocks, not whole home blocks: the
/// outer shell of candidates is half as thick, and a third of the candidates of whole
/// blocks were empty (4M scene).
pub(super) fn candidate_blocks(
    halves: impl IntoIterator<Item = BlockKey>,
    half_reach: i32,
    range: Option<BlockRange>,
) -> Vec<BlockKey> {
    // The populated halves of every home block, as a mask (bit x + 2y + 4z).
    let mut homes: HashMap<BlockKey, u8> = HashMap::new();
    for half in halves {
        let bit = half[0].rem_euclid(2) | half[1].rem_euclid(2) << 1 | half[2].rem_euclid(2) << 2;
        *homes.entry(block_of_half(half)).or_default() |= 1 << bit;
    }
    // Per block offset `d`, the halves (bits) within reach of it: along an axis, half
    // offset `o` (0 or 1) reaches the blocks b with [2b, 2b + 1] within half_reach of half
    // 2B + o, i.e. ⌈(o − 1 − half_reach) / 2⌉ ≤ b − B ≤ ⌊(o + half_reach) / 2⌋, so no
    // offset exceeds ⌊(1 + half_reach) / 2⌋.
    let span = |o: i32| -(1 + half_reach - o).div_euclid(2)..=(o + half_reach).div_euclid(2);
    let reach = (1 + half_reach).div_euclid(2);
    let offsets: Vec<([i32; 3], u8)> = (-reach..=reach)
        .flat_map(|dz| {
            (-reach..=reach).flat_map(move |dy| (-reach..=reach).map(move |dx| [dx, dy, dz]))
        })
        .map(|d| {
            let reached = (0..8u8)
                .filter(|&bit| (0..3).all(|a| span(((bit >> a) & 1) as i32).contains(&d[a])))
                .fold(0u8, |mask, bit| mask | 1 << bit);
            (d, reached)
        })
        .filter(|&(_, reached)| reached != 0)
        .collect();
    // Every home block is a candidate (its own halves reach it); the others are the
    // blocks around the homes, found in parallel, most of them many times over.
    let home_list: Vec<(BlockKey, u8)> = homes.iter().map(|(k, &m)| (*k, m)).collect();
    let mut candidates: Vec<BlockKey> = home_list
        .par_iter()
        .flat_map_iter(|&(key, mask)| {
            offsets
                .iter()
                .filter(move |&&(_, reached)| reached & mask != 0)
                .map(move |(d, _)| [0, 1, 2].map(|a| key[a] + d[a]))
                .filter(|c| !homes.contains_key(c))
        })
        .collect();
    candidates.extend(home_list.iter().map(|(k, _)| *k));
    candidates.retain(|&c| range.is_none_or(|r| r.contains(c)));
    candidates.par_sort_unstable_by_key(|k| [k[2], k[1], k[0]]);
    candidates.dedup();
    candidates.shrink_to_fit();
    candidates
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::BLOCK_EDGE;
    use crate::grid::{home_half_block, HALF_BLOCK_EDGE};
    use glam::Vec3;
    use hashbrown::HashSet;

    #[test]
    fn every_block_a_particle_reaches_is_a_candidate() {
        let mut rng = crate::test_rng::TestRng::new(9);
        let mut next = || rng.unit_f32();
        // Particles around the origin (negative keys too), in cells of h = 1.
        let positions: Vec<Vec3> = (0..60)
            .map(|_| Vec3::new(next(), next(), next()) * 40.0 - 20.0)
            .collect();
        for influence in [1.5f32, 4.0, 7.0, 16.0] {
            let half_reach = (influence / HALF_BLOCK_EDGE as f32).ceil() as i32;
            let halves = positions.iter().map(|p| home_half_block(*p, 1.0));
            let candidates: HashSet<BlockKey> = candidate_blocks(halves, half_reach, None)
                .into_iter()
                .collect();
            // Brute force: blocks with a vertex within R of a particle.
            let mut reached = 0;
            for p in &positions {
                let lo = (*p - influence).floor().as_ivec3();
                let hi = (*p + influence).ceil().as_ivec3();
                for z in lo.z..=hi.z {
                    for y in lo.y..=hi.y {
                        for x in lo.x..=hi.x {
                            let v = Vec3::new(x as f32, y as f32, z as f32);
                            if (v - *p).length() < influence {
                                let key = [x, y, z].map(|c| c.div_euclid(BLOCK_EDGE));
                                assert!(candidates.contains(&key), "R = {influence}: {key:?}");
                                reached += 1;
                            }
                        }
                    }
                }
            }
            assert!(reached > 0);
        }
    }
}
