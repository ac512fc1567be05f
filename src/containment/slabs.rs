//! Slabs: the control mesh measured a part at a time, so that the one-step surface and
//! its cell hash never exist for the whole mesh at once.
//!
//! The centres are cut into slabs across the longest axis of the control mesh, each
//! with about [`super::ContainmentOptions::slab_triangles`] control triangles. A slab's
//! surface is built over every control triangle with a corner whose reach meets the slab
//! along the axis: whatever measuring a centre of the slab reads lies there (see
//! [`Slabs::new`]), so a centre is measured the same in any slab layout, and the output
//! does not depend on the chunk size. A later round, which measures a few centres
//! again, builds the surface only around them ([`Near`]).

use crate::mesh::{TriMesh, VertexTriangles};
use glam::{IVec3, Vec3};
use hashbrown::HashSet;
use rayon::prelude::*;

/// Bins of the histogram that places the slab boundaries.
const BINS: usize = 4096;

/// The slabs of one control mesh.
pub(super) struct Slabs {
    /// Axis across which the slabs lie.
    axis: usize,
    /// Boundaries between slabs along the axis (slab `k` from `bounds[k - 1]` to
    /// `bounds[k]`, the first and last open).
    bounds: Vec<f32>,
    /// Per control vertex: how far from it, per axis, a centre can be whose measuring
    /// reads a triangle with this corner, world units (see [`Slabs::new`]).
    reach: Vec<f32>,
    /// Control triangles of each slab's surface, ascending (`members[starts[k]..
    /// starts[k + 1]]`; empty with one slab: every triangle).
    starts: Vec<usize>,
    members: Vec<u32>,
    particle_radius: f32,
}

impl Slabs {
    /// Slabs of about `chunk_triangles` control triangles each.
    ///
    /// **Reach.** A centre's nearest surface point is looked up in the 2 × 2 × 2 cells of
    /// `2r` nearest it, all within `4r` per axis (`4r·√3` in all). A Loop vertex point lies
    /// in the hull of its vertex's one-ring, an edge point in the hull of its two
    /// triangles: within the longest edge `ρ_a` at a corner `a` of the triangle that owns
    /// it. The triangles then measured exactly are those around the corners of that
    /// triangle, neighbours `c` of `a`, within `ρ_a` more. So every control triangle a
    /// centre's measuring reads has a corner `c` within `4r·√3 + 2σ_c` of the centre,
    /// `σ_c` the longest edge at `c` or at a neighbour of `c`; the reach takes `8r + 2σ_c`.
    /// A slab's surface holds every control triangle with a corner whose reach meets
    /// the slab.
    pub(super) fn new(
        control: &TriMesh,
        tris: &VertexTriangles,
        chunk_triangles: usize,
        particle_radius: f64,
    ) -> Self {
        let r = particle_radius as f32;
        let reach = reaches(control, tris, r);
        let (lo, hi) = control
            .positions
            .par_iter()
            .fold(
                || (Vec3::INFINITY, Vec3::NEG_INFINITY),
                |(lo, hi), &p| (lo.min(p), hi.max(p)),
            )
            .reduce(
                || (Vec3::INFINITY, Vec3::NEG_INFINITY),
                |a, b| (a.0.min(b.0), a.1.max(b.1)),
            );
        let extent = hi - lo;
        let axis = if extent.x >= extent.y && extent.x >= extent.z {
            0
        } else if extent.y >= extent.z {
            1
        } else {
            2
        };
        let count = control
            .triangles
            .len()
            .div_ceil(chunk_triangles.max(1))
            .max(1);
        let bounds = if count > 1 && extent[axis] > 0.0 {
            boundaries(control, axis, lo[axis], extent[axis], count)
        } else {
            Vec::new()
        };
        let (starts, members) = members(control, axis, &bounds, &reach);
        Slabs {
            axis,
            bounds,
            reach,
            starts,
            members,
            particle_radius: r,
        }
    }

    /// The slabs after the control vertices `moved` moved (any order, repeats allowed):
    /// the reaches of the vertices within two rings of them (the only ones a move
    /// changes) taken again, bit for bit what [`Self::new`] would give, and the members
    /// with them. The bounds stay: a centre is measured the same in any slab layout.
    pub(super) fn update(&mut self, control: &TriMesh, tris: &VertexTriangles, moved: &[u32]) {
        let mut moved = moved.to_vec();
        moved.sort_unstable();
        moved.dedup();
        let changed = ring(control, tris, &ring(control, tris, &moved));
        let r = self.particle_radius;
        let fresh: Vec<f32> = changed
            .par_iter()
            .map(|&v| {
                8.0 * r + 2.0 * fan_max(control, tris, v, &|w| longest_edge(control, tris, w))
            })
            .collect();
        for (&v, reach) in changed.iter().zip(fresh) {
            self.reach[v as usize] = reach;
        }
        if !self.bounds.is_empty() {
            (self.starts, self.members) = members(control, self.axis, &self.bounds, &self.reach);
        }
    }

    /// The longest edge of the control mesh as the reaches were last taken, world units:
    /// at least that of every edge then (see [`Self::new`]).
    pub(super) fn edge_bound(&self) -> f32 {
        let reach = self.reach.par_iter().copied().reduce(|| 0.0, f32::max);
        (reach - 8.0 * self.particle_radius).max(0.0) / 2.0
    }

    /// The axis and the extent along it of slab `k` (from `lo`, to under `hi`).
    pub(super) fn range(&self, k: usize) -> (usize, f32, f32) {
        let lo = if k == 0 {
            f32::NEG_INFINITY
        } else {
            self.bounds[k - 1]
        };
        let hi = self.bounds.get(k).copied().unwrap_or(f32::INFINITY);
        (self.axis, lo, hi)
    }

    /// Number of slabs.
    pub(super) fn count(&self) -> usize {
        self.bounds.len() + 1
    }

    /// The slab of a centre (the one whose [`Self::range`] holds it).
    pub(super) fn of(&self, p: Vec3) -> usize {
        self.bounds.partition_point(|&b| b <= p[self.axis])
    }

    /// Per control vertex: whether its reach meets a cell of `near` (the centres of
    /// `near` can read the triangles at it). Taken once per round, for every slab.
    pub(super) fn holding(&self, control: &TriMesh, near: &Near) -> Vec<bool> {
        control
            .positions
            .par_iter()
            .zip(&self.reach)
            .map(|(&p, &m)| near.holds(p, m))
            .collect()
    }

    /// The control triangles of slab `k`'s surface, ascending; only those with a corner
    /// of `holds` ([`Self::holding`]) when given.
    pub(super) fn triangles(
        &self,
        control: &TriMesh,
        k: usize,
        holds: Option<&[bool]>,
    ) -> Vec<u32> {
        let all: Vec<u32>;
        let members = if self.bounds.is_empty() {
            all = (0..control.triangles.len() as u32).collect();
            &all[..]
        } else {
            &self.members[self.starts[k]..self.starts[k + 1]]
        };
        let Some(holds) = holds else {
            return members.to_vec();
        };
        members
            .par_iter()
            .copied()
            .filter(|&t| {
                control.triangles[t as usize]
                    .iter()
                    .any(|&v| holds[v as usize])
            })
            .collect()
    }

    /// Where some centres are, to build a surface only where they can read it.
    pub(super) fn near(&self, centres: &[Vec3]) -> Near {
        let cell = NEAR_CELL * self.particle_radius;
        let home: HashSet<IVec3> = centres.iter().map(|&p| cell_of(p, cell)).collect();
        let reach = self.reach.par_iter().copied().reduce(|| 0.0, f32::max);
        // Dilations by 1, 2, 4, … cells up to the largest reach.
        let mut dilated = Vec::new();
        let mut k = 1;
        loop {
            let side = (2 * k + 1) as usize;
            let cells =
                (home.len().saturating_mul(side * side * side) <= NEAR_MAX_CELLS).then(|| {
                    let mut cells = HashSet::new();
                    for c in &home {
                        for dz in -k..=k {
                            for dy in -k..=k {
                                for dx in -k..=k {
                                    cells.insert(*c + IVec3::new(dx, dy, dz));
                                }
                            }
                        }
                    }
                    cells
                });
            let last = cells.is_none() || k as f32 * cell >= reach;
            dilated.push(cells);
            if last {
                break;
            }
            k *= 2;
        }
        Near { cell, dilated }
    }
}

/// The largest `f` over the corners of `v`'s fan (`v` and its neighbours).
fn fan_max(
    control: &TriMesh,
    tris: &VertexTriangles,
    v: u32,
    f: &(dyn Fn(u32) -> f32 + Sync),
) -> f32 {
    tris.of(v)
        .iter()
        .flat_map(|&t| control.triangles[t as usize])
        .map(f)
        .fold(0.0, f32::max)
}

/// The longest edge at control vertex `v` (0 without triangles).
pub(super) fn longest_edge(control: &TriMesh, tris: &VertexTriangles, v: u32) -> f32 {
    let x = |w: u32| control.positions[w as usize];
    fan_max(control, tris, v, &|w| (x(w) - x(v)).length())
}

/// The reach of every control vertex: `8r` plus twice the longest edge at it or at a
/// neighbour (see [`Slabs::new`]).
fn reaches(control: &TriMesh, tris: &VertexTriangles, r: f32) -> Vec<f32> {
    let n = control.positions.len() as u32;
    let longest: Vec<f32> = (0..n)
        .into_par_iter()
        .map(|v| longest_edge(control, tris, v))
        .collect();
    (0..n)
        .into_par_iter()
        .map(|v| 8.0 * r + 2.0 * fan_max(control, tris, v, &|w| longest[w as usize]))
        .collect()
}

/// The corners of the triangles around `vertices` (their closed one-rings), ascending.
pub(super) fn ring(control: &TriMesh, tris: &VertexTriangles, vertices: &[u32]) -> Vec<u32> {
    let mut out: Vec<u32> = vertices
        .iter()
        .flat_map(|&v| tris.of(v))
        .flat_map(|&t| control.triangles[t as usize])
        .collect();
    out.sort_unstable();
    out.dedup();
    out
}

/// Boundaries along `axis` that cut the control triangles (by first corner) into `count`
/// slabs of about equal numbers: a histogram of [`BINS`] bins from `lo` over `extent`,
/// a boundary where the running count passes each multiple of the share.
fn boundaries(control: &TriMesh, axis: usize, lo: f32, extent: f32, count: usize) -> Vec<f32> {
    let width = extent / BINS as f32;
    let bin = |x: f32| (((x - lo) / width) as usize).min(BINS - 1);
    let histogram = control
        .triangles
        .par_iter()
        .fold(
            || vec![0usize; BINS],
            |mut h, t| {
                h[bin(control.positions[t[0] as usize][axis])] += 1;
                h
            },
        )
        .reduce(
            || vec![0usize; BINS],
            |mut a, b| {
                a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
                a
            },
        );
    let share = control.triangles.len().div_ceil(count);
    let (mut bounds, mut running) = (Vec::new(), 0);
    for (k, n) in histogram.iter().enumerate() {
        running += n;
        if running >= share * (bounds.len() + 1) && bounds.len() + 1 < count {
            bounds.push(lo + width * (k + 1) as f32);
        }
    }
    bounds
}

/// The control triangles of every slab, ascending, as (starts, members): each triangle
/// in the slabs its corners' reaches meet. Empty with one slab.
fn members(
    control: &TriMesh,
    axis: usize,
    bounds: &[f32],
    reach: &[f32],
) -> (Vec<usize>, Vec<u32>) {
    let mut starts = vec![0usize; bounds.len() + 2];
    if bounds.is_empty() {
        return (starts, Vec::new());
    }
    let spans: Vec<(u32, u32)> = control
        .triangles
        .par_iter()
        .map(|t| {
            let (mut a, mut b) = (f32::INFINITY, f32::NEG_INFINITY);
            for &v in t {
                let (x, m) = (control.positions[v as usize][axis], reach[v as usize]);
                a = a.min(x - m);
                b = b.max(x + m);
            }
            (
                bounds.partition_point(|&x| x <= a) as u32,
                bounds.partition_point(|&x| x < b) as u32,
            )
        })
        .collect();
    for &(a, b) in &spans {
        for k in a..=b {
            starts[k as usize + 1] += 1;
        }
    }
    for k in 0..=bounds.len() {
        starts[k + 1] += starts[k];
    }
    let mut fill = starts.clone();
    let mut members = vec![0u32; starts[bounds.len() + 1]];
    for (t, &(a, b)) in spans.iter().enumerate() {
        for k in a..=b {
            members[fill[k as usize]] = t as u32;
            fill[k as usize] += 1;
        }
    }
    (starts, members)
}

/// Edge of [`Near`]'s cells, multiples of r: a point whose reach is at most this less
/// the reach's `8r` (a neighbourhood of edges up to 4r) is checked in the 27 cells around.
const NEAR_CELL: f32 = 8.0;
/// Most cells a [`Near`] marks for one dilation; a larger one lets every point through.
const NEAR_MAX_CELLS: usize = 1 << 22;

pub(super) fn cell_of(p: Vec3, cell: f32) -> IVec3 {
    (p / cell).floor().as_ivec3()
}

/// The cells of some centres dilated by 1, 2, 4, … cells: a point whose reach spans `k`
/// cells is near when its cell lies in the centres' cells dilated by `k` or more (some
/// farther points pass too).
pub(super) struct Near {
    cell: f32,
    /// Dilation by `2^j` cells → its cells (`None`: too many, every point passes).
    dilated: Vec<Option<HashSet<IVec3>>>,
}

impl Near {
    /// Whether a point with reach `m` may be within its reach of a centre, per axis.
    fn holds(&self, p: Vec3, m: f32) -> bool {
        let span = (m / self.cell).ceil().max(1.0) as u32;
        let j = span.next_power_of_two().trailing_zeros() as usize;
        match self.dilated.get(j) {
            Some(Some(cells)) => cells.contains(&cell_of(p, self.cell)),
            _ => true,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// After some vertices move (some by more than the edges), `update` gives the reaches
    /// `new` would, bit for bit, and the members of those reaches with its bounds.
    #[test]
    fn updated_slabs_hold_the_reaches_taken_afresh() {
        let mut control = crate::isolated::icosphere(4, 1.0);
        let r = 0.02;
        let tris = VertexTriangles::new(&control);
        let mut slabs = Slabs::new(&control, &tris, 700, r);
        assert!(slabs.count() > 3, "{} slabs", slabs.count());
        let mut rng = crate::test_rng::TestRng::new(3);
        let mut moved = Vec::new();
        for k in 0..40u32 {
            let v = (k * 61) % control.positions.len() as u32;
            let d = Vec3::new(rng.unit_f32(), rng.unit_f32(), rng.unit_f32()) - 0.5;
            control.positions[v as usize] += d * if k % 4 == 0 { 0.5 } else { 0.02 };
            moved.push(v);
        }
        moved.push(moved[0]);
        let before = slabs.reach.clone();
        slabs.update(&control, &tris, &moved);
        let fresh = reaches(&control, &tris, r as f32);
        assert!(fresh != before, "the moves change some reaches");
        assert!(
            fresh
                .iter()
                .zip(&slabs.reach)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "reaches as taken afresh"
        );
        let (starts, members) = members(&control, slabs.axis, &slabs.bounds, &fresh);
        assert_eq!(
            (starts, members),
            (slabs.starts.clone(), slabs.members.clone())
        );
    }
}
