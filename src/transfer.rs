//! The attribute stage, after the surface is final: each vertex's value from the payload
//! of the particles near it, tile by tile.
//!
//! **Input:** the particles' selected attributes
//! (the payload the tile engine carries beside the positions) and the final surface.
//! **Output:** one value per surface vertex, the normalized kernel-weighted mean of the
//! particles within the influence radius `R` of the vertex, with the field's kernel
//! `k(s) = max(0, (1 − s²)³)`, `s = |x − x_i| / R`:
//!
//! ```text
//! a(x) = Σ_i k(|x − x_i| / R) · a_i  /  Σ_i k(|x − x_i| / R)
//! ```
//!
//! evaluated at the **final** vertex positions (after decimation and subdivision), so the
//! value is a function of the position alone: the particles within `R` are summed in the
//! engine's canonical order (home half-block, input index) in f64, the same in every
//! tiling and for every thread count, bit for bit. A vertex with no particle within `R`
//! takes the value of its nearest particle (the lowest input index on a tie). An isolated
//! particle's sphere takes its particle's value.
//!
//! A constant attribute is reproduced exactly (to f32 rounding); a linear one,
//! `a(x) = A·x + b`, comes out as `A·x̄ + b` with `x̄` the kernel-weighted mean position,
//! which lies within `R` of the vertex: the error is at most `‖A‖·R`.

use crate::attributes::{Attribute, AttributeLayout};
use crate::cancel::CancelToken;
use crate::error::Result;
use crate::grid::BlockKey;
use crate::grid::{home_block, HALF_BLOCK_EDGE};
use crate::tiles::store::{LoadedParticles, ParticleStore};
use crate::tiles::TilePlan;
use glam::Vec3;
use hashbrown::HashMap;
use rayon::prelude::*;

/// The attributes of `layout`, from the payload of the particles in `store`, at the
/// points of each of `sets` (world units): the kernel-weighted mean of the particles
/// within `radius` (world units) of each point, or its nearest particle's value when none
/// is that close (see the module docs). Points are taken tile by tile as `plan` cuts the
/// lattice; the result does not depend on the tiling or the thread count. One list of
/// attributes per set.
pub(crate) fn transfer<S: crate::io::particles::ParticleSource>(
    store: &ParticleStore<S>,
    plan: &TilePlan,
    layout: &[AttributeLayout],
    sets: &[&[Vec3]],
    radius: f64,
    cancel: &CancelToken,
) -> Result<Vec<Vec<Attribute>>> {
    let points = Points { sets };
    let width = plan.payload_width;
    if width == 0 {
        return Ok(sets.iter().map(|_| Vec::new()).collect());
    }
    let mut rows = Rows {
        width,
        values: vec![0f32; points.len() * width],
        resolved: vec![false; points.len()],
    };
    let search = Search::new(plan, radius);
    let (order, groups) = points_by_tile(&points, plan);
    let mut loaded = LoadedParticles::default();
    for &(tile, start, end) in groups.iter().filter(|g| g.1 < g.2) {
        cancel.check()?;
        let own = plan.own_blocks(tile);
        store.load_with_payload(plan, own.grown(plan.reach, plan.reach), &mut loaded)?;
        if loaded.positions.is_empty() {
            continue;
        }
        let group = &order[start as usize..end as usize];
        evaluate_tile(&points, group, &loaded, &search, &mut rows);
    }
    drop(loaded);
    nearest_over_store(&points, store, &mut rows, cancel)?;
    Ok(rows.into_attributes(sets, layout))
}

/// The payload rows of every point, and whether each has its value yet.
struct Rows {
    /// Floats per row.
    width: usize,
    values: Vec<f32>,
    resolved: Vec<bool>,
}

impl Rows {
    /// Sets point `k`'s row.
    fn set(&mut self, k: usize, value: &[f32]) {
        self.values[k * self.width..(k + 1) * self.width].copy_from_slice(value);
        self.resolved[k] = true;
    }

    /// The rows as one attribute per layout entry, per set.
    fn into_attributes(self, sets: &[&[Vec3]], layout: &[AttributeLayout]) -> Vec<Vec<Attribute>> {
        let width = self.width;
        let mut out = Vec::with_capacity(sets.len());
        let mut first = 0;
        for set in sets {
            let rows = &self.values[first * width..(first + set.len()) * width];
            first += set.len();
            let mut attributes: Vec<Attribute> = layout
                .iter()
                .map(|l| Attribute {
                    name: l.name.clone(),
                    components: l.components,
                    values: Vec::with_capacity(set.len() * l.components),
                })
                .collect();
            for row in rows.chunks_exact(width) {
                let mut at = 0;
                for a in &mut attributes {
                    a.values.extend_from_slice(&row[at..at + a.components]);
                    at += a.components;
                }
            }
            out.push(attributes);
        }
        out
    }
}

/// The points in tile order, and per tile its run of them: tiles in (z, y, x) order
/// (untiled: one tile of all).
fn points_by_tile(points: &Points, plan: &TilePlan) -> (Vec<u32>, Vec<(BlockKey, u32, u32)>) {
    if plan.is_tiled() {
        let tiles: Vec<BlockKey> = (0..points.len())
            .into_par_iter()
            .map(|k| plan.tile_of(home_block(points.get(k), plan.inv_h)))
            .collect();
        let order = crate::grid::sort_by_key_zyx(&tiles);
        let groups = crate::grid::key_runs(order.iter().map(|&k| tiles[k as usize]));
        (order, groups)
    } else {
        let n = points.len() as u32;
        ((0..n).collect(), vec![([0; 3], 0, n)])
    }
}

/// The values of one tile's points (`group`) from its `loaded` particles: the weighted
/// mean within the radius, or the nearest particle in the tile's window.
fn evaluate_tile(
    points: &Points,
    group: &[u32],
    loaded: &LoadedParticles,
    search: &Search,
    rows: &mut Rows,
) {
    let width = rows.width;
    let rows_of_tile = crate::grid::row_ranges(loaded.halves.iter().copied());
    // The tile's points in (z, y, x) order of their half-blocks, so that neighbouring
    // evaluations read the same particles (a mesh's vertex order is not spatial after
    // subdivision); each point's value is its own, whatever the order.
    let halves: Vec<BlockKey> = group
        .par_iter()
        .map(|&k| search.half_block_of(points.get(k as usize).as_dvec3()))
        .collect();
    let order = crate::grid::sort_by_key_zyx(&halves);
    let group: Vec<u32> = order.iter().map(|&i| group[i as usize]).collect();
    let halves: Vec<BlockKey> = order.iter().map(|&i| halves[i as usize]).collect();
    drop(order);
    // Points of one half-block share the particles they search: gathered once per run
    // of them (each parallel piece keeps the last half-block's).
    let mut values = vec![0f32; group.len() * width];
    let found: Vec<bool> = values
        .par_chunks_mut(width)
        .zip(group.par_iter().zip(halves.par_iter()))
        .map_init(
            || (Near::with_width(width), None::<BlockKey>),
            |(near, gathered), (out, (&k, &half))| {
                if *gathered != Some(half) {
                    search.gather_near(half, loaded, &rows_of_tile, near);
                    *gathered = Some(half);
                }
                let p = points.get(k as usize);
                search.weighted_mean(p, loaded, near, out)
                    || search.nearest_in_window(p, loaded, &rows_of_tile, out)
            },
        )
        .collect();
    for ((&k, value), found) in group.iter().zip(values.chunks_exact(width)).zip(found) {
        if found {
            rows.set(k as usize, value);
        }
    }
}

/// Points far from every particle: the nearest one over the whole store (the lowest
/// input index on a tie).
fn nearest_over_store<S: crate::io::particles::ParticleSource>(
    points: &Points,
    store: &ParticleStore<S>,
    rows: &mut Rows,
    cancel: &CancelToken,
) -> Result<()> {
    let width = rows.width;
    let far: Vec<usize> = (0..points.len()).filter(|&k| !rows.resolved[k]).collect();
    if far.is_empty() {
        return Ok(());
    }
    let mut best: Vec<(f64, u32, Vec<f32>)> =
        vec![(f64::INFINITY, u32::MAX, Vec::new()); far.len()];
    store.for_each_stored(&mut |positions, indices, payload| {
        cancel.check()?;
        best.par_iter_mut().zip(&far).for_each(|(b, &k)| {
            let p = points.get(k).as_dvec3();
            for (j, x) in positions.iter().enumerate() {
                let d2 = (x.as_dvec3() - p).length_squared();
                if (d2, indices[j]) < (b.0, b.1) {
                    *b = (d2, indices[j], payload[j * width..(j + 1) * width].to_vec());
                }
            }
        });
        Ok(())
    })?;
    for (&k, (_, _, value)) in far.iter().zip(best) {
        if value.len() == width {
            rows.set(k, &value);
        }
    }
    Ok(())
}

/// The points of several sets, numbered one after the other.
struct Points<'a> {
    sets: &'a [&'a [Vec3]],
}

impl Points<'_> {
    fn len(&self) -> usize {
        self.sets.iter().map(|s| s.len()).sum()
    }

    fn get(&self, mut k: usize) -> Vec3 {
        for set in self.sets {
            if k < set.len() {
                return set[k];
            }
            k -= set.len();
        }
        panic!("point {k} past the sets")
    }
}

/// The particles near one half-block, as columns (positions in f32 for a vectorized
/// distance test, index into the tile), with scratch for one point.
struct Near {
    x: Vec<f32>,
    y: Vec<f32>,
    z: Vec<f32>,
    index: Vec<u32>,
    d2: Vec<f32>,
    hits: Vec<u32>,
    sum: Vec<f64>,
}

impl Near {
    fn with_width(width: usize) -> Self {
        Near {
            x: Vec::new(),
            y: Vec::new(),
            z: Vec::new(),
            index: Vec::new(),
            d2: Vec::new(),
            hits: Vec::new(),
            sum: vec![0.0; width],
        }
    }

    fn clear(&mut self) {
        self.x.clear();
        self.y.clear();
        self.z.clear();
        self.index.clear();
    }
}

/// The neighbourhood search of [`transfer`] over a tile's particles, sorted in the
/// canonical order with their home half-blocks as cells.
struct Search {
    radius: f64,
    radius2: f64,
    inv_radius2: f64,
    /// Half-block edge, world units.
    half_edge: f64,
    /// 1 / cell size.
    inv_h: f64,
    /// Distance up to which a tile's zone holds every particle (tiled runs), world units.
    zone_margin: f64,
}

impl Search {
    fn new(plan: &TilePlan, radius: f64) -> Self {
        let half_edge = HALF_BLOCK_EDGE as f64 / plan.inv_h;
        Search {
            radius,
            radius2: radius * radius,
            inv_radius2: 1.0 / (radius * radius),
            half_edge,
            inv_h: plan.inv_h,
            zone_margin: if plan.is_tiled() {
                plan.reach as f64 * 2.0 * half_edge
            } else {
                f64::INFINITY
            },
        }
    }

    /// Calls `visit(k)` for the particles whose home half-block may hold a point within
    /// `extent` (world units) of `p`, in the canonical order: the half-blocks of the box
    /// around `p`, less the rows and the ends of rows that lie farther than `extent`.
    fn for_each_near(
        &self,
        p: Vec3,
        extent: f64,
        loaded: &LoadedParticles,
        rows: &HashMap<[i32; 2], (u32, u32)>,
        mut visit: impl FnMut(usize),
    ) {
        // A hair more than `extent`, against the rounding of the particles' half-blocks.
        let e = extent * (1.0 + 1e-6) + 1e-6 * self.half_edge;
        let x = p.as_dvec3();
        let lo = self.half_block_of(x - e);
        let hi = self.half_block_of(x + e);
        // Distance from `c` to the half-block span `[k·edge, (k + 1)·edge)` on one axis.
        let gap = |c: f64, k: i32| {
            let (a, b) = (k as f64 * self.half_edge, (k + 1) as f64 * self.half_edge);
            (a - c).max(c - b).max(0.0)
        };
        for z in lo[2]..=hi[2] {
            let dz = gap(x.z, z);
            for y in lo[1]..=hi[1] {
                let dy = gap(x.y, y);
                let left = e * e - dz * dz - dy * dy;
                if left < 0.0 {
                    continue;
                }
                let Some(&(a, b)) = rows.get(&[y, z]) else {
                    continue;
                };
                let reach_x = left.sqrt();
                let x_lo = self.half_block_of(glam::DVec3::splat(x.x - reach_x))[0];
                let x_hi = self.half_block_of(glam::DVec3::splat(x.x + reach_x))[0];
                let row = &loaded.halves[a as usize..b as usize];
                let first = a as usize + row.partition_point(|k| k[0] < x_lo);
                let end = a as usize + row.partition_point(|k| k[0] <= x_hi);
                (first..end).for_each(&mut visit);
            }
        }
    }

    /// The half-block holding `x` (as [`home_half_block`] does for a particle).
    fn half_block_of(&self, x: glam::DVec3) -> BlockKey {
        let c = x * self.inv_h;
        [c.x, c.y, c.z].map(|v| (v.floor() as i32).div_euclid(HALF_BLOCK_EDGE))
    }

    /// Gathers into `near` the particles that may lie within the radius of a point of
    /// half-block `c`, in the canonical order: the half-blocks within reach of `c`'s box,
    /// less the rows farther than the radius from it.
    fn gather_near(
        &self,
        c: BlockKey,
        loaded: &LoadedParticles,
        rows: &HashMap<[i32; 2], (u32, u32)>,
        near: &mut Near,
    ) {
        near.clear();
        // Half-blocks whose span lies within the radius of the box: a particle closer
        // than the radius to a point lies in one of them, up to the rounding of a home
        // half-block at its border, which could only drop a particle at the radius
        // itself (weight ≈ 0), and drops it alike in every tiling.
        let e = self.radius;
        let reach = (e / self.half_edge - 1e-9).ceil() as i32;
        // Distance between the spans of half-blocks `a` and `b` on one axis.
        let gap = |a: i32, b: i32| ((a - b).abs() - 1).max(0) as f64 * self.half_edge;
        // The half-block's box, a hair larger, and the squared radius, a hair larger.
        let corner = |k: [i32; 3]| glam::DVec3::from(k.map(|v| v as f64)) * self.half_edge;
        let box_lo = (corner(c) - 1e-6 * self.half_edge).as_vec3();
        let box_hi = (corner(c.map(|v| v + 1)) + 1e-6 * self.half_edge).as_vec3();
        let reach2 = (e * e * (1.0 + 1e-4)) as f32;
        for z in c[2] - reach..=c[2] + reach {
            for y in c[1] - reach..=c[1] + reach {
                let (dy, dz) = (gap(y, c[1]), gap(z, c[2]));
                if dy * dy + dz * dz >= e * e {
                    continue;
                }
                let Some(&(a, b)) = rows.get(&[y, z]) else {
                    continue;
                };
                let row = &loaded.halves[a as usize..b as usize];
                let start = a as usize + row.partition_point(|k| k[0] < c[0] - reach);
                let end = a as usize + row.partition_point(|k| k[0] <= c[0] + reach);
                for k in start..end {
                    // Only particles within the radius of the half-block's box.
                    let q = loaded.positions[k];
                    let d = (box_lo - q).max(q - box_hi).max(glam::Vec3::ZERO);
                    if d.length_squared() > reach2 {
                        continue;
                    }
                    near.x.push(q.x);
                    near.y.push(q.y);
                    near.z.push(q.z);
                    near.index.push(k as u32);
                }
            }
        }
    }

    /// Writes to `out` the kernel-weighted mean of the payload of the particles within the
    /// radius of `p`, summed in f64 in the canonical order; false when there is none.
    /// `near` holds the particles near `p`'s half-block ([`Search::gather_near`]).
    ///
    /// On x86-64 CPUs with AVX2 the same code is compiled a second time with AVX2 enabled
    /// and picked at run time (the distance loop then takes eight particles per
    /// instruction). Rust never contracts `a * b + c`, so both copies round identically.
    fn weighted_mean(
        &self,
        p: Vec3,
        loaded: &LoadedParticles,
        near: &mut Near,
        out: &mut [f32],
    ) -> bool {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports the feature the function is compiled for.
            return unsafe { self.weighted_mean_avx2(p, loaded, near, out) };
        }
        self.weighted_mean_portable(p, loaded, near, out)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn weighted_mean_avx2(
        &self,
        p: Vec3,
        loaded: &LoadedParticles,
        near: &mut Near,
        out: &mut [f32],
    ) -> bool {
        self.weighted_mean_portable(p, loaded, near, out)
    }

    // Index loops on purpose: they inline into (and vectorize within) the AVX2 copy.
    #[allow(clippy::needless_range_loop)]
    #[inline(always)]
    fn weighted_mean_portable(
        &self,
        p: Vec3,
        loaded: &LoadedParticles,
        near: &mut Near,
        out: &mut [f32],
    ) -> bool {
        let width = out.len();
        let n = near.x.len();
        near.d2.resize(n, 0.0);
        near.hits.resize(n, 0);
        // Squared distances in f32 for all, in a loop without branches (vectorized).
        let (xs, ys, zs, d2s) = (&near.x[..n], &near.y[..n], &near.z[..n], &mut near.d2[..n]);
        for j in 0..n {
            let (dx, dy, dz) = (xs[j] - p.x, ys[j] - p.y, zs[j] - p.z);
            d2s[j] = dx * dx + dy * dy + dz * dz;
        }
        // The candidates within the radius, listed without a branch (about half of them
        // are: a branch per candidate would be mispredicted half the time).
        let radius2 = self.radius2 as f32;
        let hits = &mut near.hits[..n];
        let mut count = 0;
        for j in 0..n {
            hits[count] = j as u32;
            count += (d2s[j] < radius2) as usize;
        }
        // Their weights, summed in f64.
        let inv_radius2 = self.inv_radius2 as f32;
        let sum = &mut near.sum;
        sum.fill(0.0);
        let mut weights = 0f64;
        for &j in &hits[..count] {
            let (d2, k) = (d2s[j as usize], near.index[j as usize] as usize);
            let q = (1.0 - d2 * inv_radius2) as f64;
            let w = q * q * q;
            weights += w;
            for (s, v) in sum
                .iter_mut()
                .zip(&loaded.payload[k * width..(k + 1) * width])
            {
                *s += w * *v as f64;
            }
        }
        if weights > 0.0 {
            for (o, s) in out.iter_mut().zip(sum.iter()) {
                *o = (s / weights) as f32;
            }
        }
        weights > 0.0
    }

    /// Writes to `out` the payload of the particle nearest to `p` (lowest input index on
    /// a tie) when it lies within twice the radius and the tile's zone holds every
    /// particle as close: then it is the nearest of all. False otherwise.
    fn nearest_in_window(
        &self,
        p: Vec3,
        loaded: &LoadedParticles,
        rows: &HashMap<[i32; 2], (u32, u32)>,
        out: &mut [f32],
    ) -> bool {
        let width = out.len();
        let x = p.as_dvec3();
        let window = (2.0 * self.radius).min(self.zone_margin);
        let mut best: Option<(f64, u32, usize)> = None;
        self.for_each_near(p, window, loaded, rows, |k| {
            let d2 = (loaded.positions[k].as_dvec3() - x).length_squared();
            let candidate = (d2, loaded.indices[k], k);
            if best.is_none_or(|b| (candidate.0, candidate.1) < (b.0, b.1)) {
                best = Some(candidate);
            }
        });
        // Every particle within `window` of `p` was seen (and, tiled, is in the zone).
        match best {
            Some((d2, _, k)) if d2.sqrt() <= window => {
                out.copy_from_slice(&loaded.payload[k * width..(k + 1) * width]);
                true
            }
            _ => false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::FieldOptions;
    use crate::io::particles::{ParticleSource, Particles};
    use crate::tiles::{plan_tiles, TileOptions};

    /// Values at `points` from `particles`, untiled or in tiles of `tile` cells (the
    /// points handed over as two sets, the results joined).
    fn values_at(particles: &Particles, points: &[Vec3], tile: Option<u32>) -> Vec<Attribute> {
        let field = FieldOptions::new(0.025);
        let options = TileOptions {
            tile_size_cells: tile,
            ..TileOptions::default()
        };
        let cancel = CancelToken::new();
        let plan = plan_tiles(
            particles,
            &field,
            None,
            &options,
            crate::tiles::OutputCost::NONE,
            false,
            &cancel,
        )
        .unwrap();
        assert_eq!(plan.is_tiled(), tile.is_some());
        let layout = particles.attribute_layout();
        let store = ParticleStore::build(particles.clone(), &plan, None, &cancel).unwrap();
        let (a, b) = points.split_at(points.len() / 2);
        let mut sets = transfer(
            &store,
            &plan,
            &layout,
            &[a, b],
            field.influence_radius_world(),
            &cancel,
        )
        .unwrap();
        assert_eq!(sets.len(), 2);
        let second = sets.pop().unwrap();
        let mut joined = sets.pop().unwrap();
        for (j, s) in joined.iter_mut().zip(second) {
            assert_eq!(j.len(), a.len());
            assert_eq!(s.len(), b.len());
            j.values.extend(s.values);
        }
        joined
    }

    #[test]
    fn points_beyond_r_take_the_nearest_particle_lowest_index_on_a_tie() {
        // A block of particles, each with its index as value, and two coincident ones.
        let mut positions = Vec::new();
        for k in 0..6 {
            for j in 0..6 {
                for i in 0..6 {
                    positions.push(Vec3::new(i as f32, j as f32, k as f32) * 0.05);
                }
            }
        }
        positions.push(Vec3::new(2.0, 2.0, 2.0));
        positions.push(Vec3::new(2.0, 2.0, 2.0));
        let n = positions.len();
        let particles = Particles {
            positions: positions.clone(),
            attributes: vec![Attribute {
                name: "id".into(),
                components: 1,
                values: (0..n).map(|i| i as f32).collect(),
            }],
        };
        // Points at 1.5 R to 40 R from every particle, and one inside.
        let points = [
            Vec3::new(-0.15, 0.1, 0.1),
            Vec3::new(0.1, 0.45, 0.1),
            Vec3::new(1.0, 1.0, 1.0),
            Vec3::new(2.3, 2.0, 2.0),
            Vec3::new(-4.0, 0.0, 0.0),
            Vec3::new(0.12, 0.12, 0.12),
        ];
        let nearest = |x: Vec3| -> f32 {
            let mut best = (f64::INFINITY, 0);
            for (i, p) in positions.iter().enumerate() {
                let d2 = (p.as_dvec3() - x.as_dvec3()).length_squared();
                if d2 < best.0 {
                    best = (d2, i);
                }
            }
            best.1 as f32
        };
        let untiled = values_at(&particles, &points, None);
        for tile in [8, 16] {
            let tiled = values_at(&particles, &points, Some(tile));
            assert_eq!(tiled, untiled, "tile {tile}");
        }
        let ids = &untiled[0];
        for (k, x) in points.iter().enumerate().take(5) {
            assert_eq!(ids.item(k)[0], nearest(*x), "point {x}");
        }
        // The coincident pair: the lower index.
        assert_eq!(ids.item(3)[0], (n - 2) as f32);
        // Inside: a weighted mean of several ids, not one of them.
        assert!(ids.item(5)[0].fract() != 0.0);
    }
}
