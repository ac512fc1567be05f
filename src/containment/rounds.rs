//! Containment's rounds (see the module docs of `containment`): measure the centres
//! near the surface, push the control vertices over the shallow ones out, and measure
//! again those the pushes may have brought too close, until none is shallow or the
//! rounds run out.

use super::centres::{bits, measure_centres, settle, Folds, Found, Need, Shallow, Watched};
use super::measure::{CellIndex, SurfaceIndex};
use super::slabs::Slabs;
use super::surface::{LoopSurface, Slots, Step};
use super::{Centres, ContainmentInput, ContainmentOptions, ContainmentStats};
use crate::cancel::CancelToken;
use crate::error::Result;
use crate::mesh::{TriMesh, VertexTriangles};
use glam::{DVec3, Vec3};
use hashbrown::{HashMap, HashSet};
use rayon::prelude::*;
use std::time::Instant;

/// [`super::contain`] over any [`Centres`] (see [`ContainmentInput`]): rounds of measuring every
/// centre near the surface and pushing the control vertices over the shallow ones out,
/// until none is shallow or the rounds run out.
pub(crate) fn contain_centres<C: Centres + ?Sized>(
    control: &mut TriMesh,
    input: &ContainmentInput<'_, C>,
    options: &ContainmentOptions,
    cancel: &CancelToken,
) -> Result<ContainmentStats> {
    let mut stats = ContainmentStats::default();
    if control.triangles.is_empty() {
        stats.rounds = 1;
        return Ok(stats);
    }
    // Lengths of the whole surface (cells, slabs, margins) from the largest particle; each
    // centre's own depth from its own radius ([`Need`]).
    let largest = crate::field::largest_ratio(input.sizes) as f64;
    let r = input.particle_radius as f64 * largest;
    let depth = options.min_depth.max(0.0) as f64 * r;
    let need = Need {
        depth: options.min_depth.max(0.0) as f64 * input.particle_radius as f64,
        r: input.particle_radius as f64,
        margin: r,
        ratios: input.sizes.map(|s| s.ratios),
        farthest_outside: input
            .farthest_outside
            .map_or(f64::INFINITY, |f| f as f64 + FOLD_TOLERANCE * r),
    };
    let mut folds = Folds::default();
    let mut rounds = Rounds::new(control, input, depth, &mut stats);
    loop {
        stats.rounds += 1;
        let Found {
            near,
            mut shallow,
            watched,
            folded: folded_here,
            ..
        } = rounds.measure(control, input, &need, cancel, &mut stats)?;
        folds.take(folded_here, &mut shallow, &need);
        if stats.rounds > 1 {
            stats.remeasured += if rounds.full_round {
                near
            } else {
                rounds.measured.len()
            };
        }
        // Those that a push could bring too close are watched after: after a full round
        // all of them, else the latest measure of each centre measured again replaces
        // the one before.
        if rounds.full_round {
            rounds.watch = watched;
        } else {
            let measured = std::mem::take(&mut rounds.measured);
            rounds
                .watch
                .retain(|w| measured.binary_search(&w.particle).is_err());
            rounds.watch.extend(watched);
        }
        if stats.rounds == 1 {
            stats.near_centres = near;
            stats.too_shallow = shallow.len();
            stats.outside = shallow.iter().filter(|s| s.outside()).count();
        }
        if shallow.is_empty() || stats.rounds > options.max_rounds {
            stats.folded = folds.count(&shallow);
            stats.remaining = shallow.len();
            break;
        }
        let (moved, largest) = rounds.push_out(control, &mut shallow);
        let pushed = rounds.pushed.iter().map(|&(v, _)| v);
        rounds.moved_since_slabs.extend(pushed);
        stats.moved_vertices += moved;
        // A push of more than r may reach centres nobody watched: measure again every
        // centre near the surface the pushes moved (every centre when that region is too
        // large to mark).
        rounds.full_round = false;
        rounds.near_pushes.clear();
        if largest > r {
            // The pushes lengthened the edges at the pushed vertices: the slabs' reach
            // (what a centre's measuring may read) is taken again, so that the surface
            // built around the centres measured next holds all they read.
            let clock = Instant::now();
            let moved = std::mem::take(&mut rounds.moved_since_slabs);
            rounds.slabs.update(control, &rounds.tris, &moved);
            stats.surface_seconds += clock.elapsed().as_secs_f64();
            match rounds.centres_near_pushes(control, input, cancel)? {
                Some(near) => rounds.near_pushes = near,
                None => rounds.full_round = true,
            }
            // The many centres measured again take the tangent-plane shortcut too.
            control.compute_normals();
        }
        rounds.fresh_normals = largest > r;
    }
    control.normals = Vec::new();
    Ok(stats)
}

/// How much farther outside than [`super::ContainmentInput::farthest_outside`] a centre
/// may be measured before it counts as folded, multiples of r: the marching-cubes chords
/// and the moves along the surface. Measured on a violent splash (dam break frame 25
/// thrown apart ×8, steady surface, bound 0.35 r): the 40 centres really outside (by ray
/// parity) lay within 0.5 r, the 262 measured 1–2 r outside were all inside, none between.
const FOLD_TOLERANCE: f64 = 0.4;

/// What the surface measured is made of: one Loop step when the pipeline subdivides,
/// else the control mesh itself with its triangles cut at their edge midpoints where a
/// side is longer than `√3 (r − depth)` ([`Step::Flat`]). A centre is measured when a
/// point of the surface lies within `r` of it (its 2 × 2 × 2 cells of `2r`); any point of
/// a triangle with sides of at most `L` lies within `L/√3` of a corner, so every centre
/// less than `depth` under the surface is still measured with the corners of the
/// triangles not cut as their only points.
fn surface_step(levels: u32, r: f64, depth: f64) -> Step {
    if levels > 0 {
        Step::Loop
    } else {
        Step::Flat {
            split: (3f64.sqrt() * (r - depth)).max(0.0) as f32,
        }
    }
}

/// The state of containment's rounds.
struct Rounds {
    /// Least depth, world units (of the largest particle).
    depth: f64,
    /// Particle radius, world units (the largest particle's).
    r: f64,
    /// How much more than the surface must move a control vertex is pushed: Loop averages
    /// a push of a control triangle over its neighbours, so the surface over the triangle
    /// moves by 3/4 to 7/8 of it for one step; push more so that one round usually
    /// suffices.
    gain: f64,
    /// The positions of the isolated centres, skipped.
    isolated: HashSet<[u32; 3]>,
    /// The control mesh's vertex → triangle lists.
    tris: VertexTriangles,
    /// The control mesh cut into slabs.
    slabs: Slabs,
    /// No edge of the control mesh is longer, world units: taken with the slabs, raised
    /// by the edges at every pushed vertex (only those change).
    longest_edge: f64,
    /// Scratch of the one-step surface, reused from slab to slab.
    slots: Slots,
    /// What the surface measured is made of ([`surface_step`]).
    step: Step,
    /// Centres within r of being too shallow in the last full round.
    watch: Vec<Watched>,
    /// Control vertices whose one-ring holds a moved vertex (Loop's masks reach that far).
    reached: Vec<bool>,
    /// Whether the next round measures every centre, or only the watched ones (and
    /// those of `near_pushes`).
    full_round: bool,
    /// Centres near the surface the last pushes moved by more than r, measured again in
    /// the next round with the watched ones ([`Rounds::centres_near_pushes`]).
    near_pushes: Vec<Watched>,
    /// The pushes of the last round: control vertex and how far it moved.
    pushed: Vec<(u32, DVec3)>,
    /// The control vertices pushed since the slabs' reaches were last taken.
    moved_since_slabs: Vec<u32>,
    /// Particles measured in the last round that was not full, ascending.
    measured: Vec<u32>,
    /// Whether the control mesh's normals are those of its current positions (the
    /// tangent-plane shortcut reads them).
    fresh_normals: bool,
}

impl Rounds {
    fn new<C: Centres + ?Sized>(
        control: &mut TriMesh,
        input: &ContainmentInput<'_, C>,
        depth: f64,
        stats: &mut ContainmentStats,
    ) -> Self {
        let r = input.particle_radius as f64;
        let clock = Instant::now();
        let tris = VertexTriangles::new(control);
        // The tangent-plane shortcut reads the control mesh's normals.
        control.compute_normals();
        let slabs = Slabs::new(control, &tris, input.slab_triangles, r);
        stats.slabs = slabs.count() as u32;
        stats.surface_seconds += clock.elapsed().as_secs_f64();
        Rounds {
            step: surface_step(input.levels, r, depth),
            depth,
            r,
            gain: if input.levels == 0 { 1.0 } else { 1.4 },
            isolated: input.isolated.iter().map(|p| bits(*p)).collect(),
            slots: Slots::new(control),
            longest_edge: slabs.edge_bound() as f64,
            tris,
            slabs,
            watch: Vec::new(),
            reached: vec![false; control.positions.len()],
            full_round: true,
            near_pushes: Vec::new(),
            pushed: Vec::new(),
            moved_since_slabs: Vec::new(),
            measured: Vec::new(),
            fresh_normals: true,
        }
    }

    /// One round of measuring, slab by slab: every centre in a full round, else only the
    /// watched centres whose nearest surface lay over a control triangle the last pushes
    /// reached (pushes of less than r cannot bring any other one too close).
    fn measure<C: Centres + ?Sized>(
        &mut self,
        control: &TriMesh,
        input: &ContainmentInput<'_, C>,
        need: &Need<'_>,
        cancel: &CancelToken,
        stats: &mut ContainmentStats,
    ) -> Result<Found> {
        let again: Vec<Watched> = if self.full_round {
            Vec::new()
        } else {
            let mut again: Vec<Watched> = self
                .watch
                .iter()
                .filter(|w| {
                    control.triangles[w.parent as usize]
                        .iter()
                        .any(|&v| self.reached[v as usize])
                })
                .chain(&self.near_pushes)
                .copied()
                .collect();
            again.sort_unstable_by_key(|w| w.particle);
            again.dedup_by_key(|w| w.particle);
            self.measured = again.iter().map(|w| w.particle).collect();
            again
        };
        let near_again = (!self.full_round).then(|| {
            let ps: Vec<Vec3> = again.iter().map(|w| w.position).collect();
            let near = self.slabs.near(&ps);
            self.slabs.holding(control, &near)
        });
        let mut found = Found::default();
        for slab in 0..self.slabs.count() {
            let again: Vec<&Watched> = again
                .iter()
                .filter(|w| self.slabs.of(w.position) == slab)
                .collect();
            if !self.full_round && again.is_empty() {
                continue;
            }
            cancel.check()?;
            // The one-step surface over the slab (where the centres measured again are).
            let clock = Instant::now();
            let ids = self.slabs.triangles(control, slab, near_again.as_deref());
            let slots_here = std::mem::take(&mut self.slots);
            let surface = LoopSurface::new(control, &self.tris, ids, self.step, slots_here);
            let cells = CellIndex::new(&surface.points, 2.0 * self.r);
            stats.surface_seconds += clock.elapsed().as_secs_f64();
            let index = SurfaceIndex {
                cells: &cells,
                surface: &surface,
                control,
                control_tris: &self.tris,
                // The tangent-plane shortcut needs the control mesh's normals, which are
                // computed after the first round only when the pushes were large.
                fast_depth: if self.fresh_normals {
                    self.depth + FAST_MARGIN * self.r
                } else {
                    f64::INFINITY
                },
                spread: self.step.spread(self.longest_edge),
            };
            let isolated = &self.isolated;
            let mut gather = |ps: &[Vec3], is: &[u32]| {
                found.extend(measure_centres(&index, isolated, need, ps, is));
            };
            if self.full_round {
                self.visit_slab(slab, input.centres, cancel, &mut gather)?;
            } else {
                let (is, ps): (Vec<u32>, Vec<Vec3>) =
                    again.iter().map(|w| (w.particle, w.position)).unzip();
                gather(&ps, &is);
            }
            settle(&index, &mut found, need);
            self.slots = surface.into_slots();
        }
        Ok(found)
    }

    /// Hands `gather` every centre of slab `slab`, chunk by chunk.
    fn visit_slab<C: Centres + ?Sized>(
        &self,
        slab: usize,
        centres: &C,
        cancel: &CancelToken,
        gather: &mut dyn FnMut(&[Vec3], &[u32]),
    ) -> Result<()> {
        let whole = self.slabs.count() == 1;
        let (axis, lo, hi) = self.slabs.range(slab);
        centres.visit_between(axis, lo, hi, &mut |positions, indices| {
            cancel.check()?;
            if whole {
                gather(positions, indices);
            } else {
                let (ps, is): (Vec<Vec3>, Vec<u32>) = positions
                    .iter()
                    .zip(indices)
                    .filter(|(p, _)| (lo..hi).contains(&p[axis]))
                    .map(|(p, i)| (*p, *i))
                    .unzip();
                gather(&ps, &is);
            }
            Ok(())
        })
    }

    /// Pushes the control vertices over the `shallow` centres out (the largest push per
    /// vertex; ties: the lowest particle index) and marks the vertices their pushes
    /// reach; returns how many vertices moved and the largest push, world units.
    fn push_out(&mut self, control: &mut TriMesh, shallow: &mut [Shallow]) -> (usize, f64) {
        shallow.sort_unstable_by_key(|s| s.particle);
        let mut push: HashMap<u32, (f64, u32, DVec3)> = HashMap::new();
        let mut largest = 0.0f64;
        for s in shallow.iter() {
            let d = s.push * self.gain;
            let amount = d.length();
            largest = largest.max(amount);
            for v in control.triangles[s.control_triangle as usize] {
                let e = push
                    .entry(v)
                    .or_insert((f64::NEG_INFINITY, u32::MAX, DVec3::ZERO));
                if amount > e.0 {
                    *e = (amount, s.particle, d);
                }
            }
        }
        let mut push: Vec<(u32, DVec3)> = push.into_iter().map(|(v, (_, _, d))| (v, d)).collect();
        push.sort_unstable_by_key(|&(v, _)| v);
        apply_pushes(control, &self.tris, &mut push);
        for &(v, _) in &push {
            let longest = super::slabs::longest_edge(control, &self.tris, v) as f64;
            self.longest_edge = self.longest_edge.max(longest);
        }
        self.reached.fill(false);
        for &(v, _) in &push {
            for &t in self.tris.of(v) {
                for w in control.triangles[t as usize] {
                    self.reached[w as usize] = true;
                }
            }
        }
        self.pushed = push;
        (self.pushed.len(), largest)
    }

    /// Every centre that the last pushes may have brought within r of being too shallow,
    /// or `None` when the region they moved spans more than [`NEAR_PUSH_MAX_CELLS`]
    /// cells. The one-step surface over a control triangle lies in the hull of its
    /// corners' one-rings, so the pushes moved it only within the one-rings of the
    /// corners of the triangles with a `reached` vertex, between where their vertices
    /// were and where they are: a centre farther than `depth + r` from all of those
    /// (boxes of them, in cells of 2r) was not shallow or watched before the pushes and
    /// is not now.
    fn centres_near_pushes<C: Centres + ?Sized>(
        &self,
        control: &TriMesh,
        input: &ContainmentInput<'_, C>,
        cancel: &CancelToken,
    ) -> Result<Option<Vec<Watched>>> {
        let cell = (2.0 * self.r) as f32;
        let margin = Vec3::splat((self.depth + self.r) as f32);
        let cell_of = |p: Vec3| super::slabs::cell_of(p, cell);
        let pushed: HashMap<u32, Vec3> =
            self.pushed.iter().map(|&(v, d)| (v, d.as_vec3())).collect();
        // The corners of the triangles with a reached vertex (the reached vertices are
        // the corners of the triangles around the pushed ones).
        let pushed_vertices: Vec<u32> = self.pushed.iter().map(|&(v, _)| v).collect();
        let reached = super::slabs::ring(control, &self.tris, &pushed_vertices);
        let corners = super::slabs::ring(control, &self.tris, &reached);
        let mut cells: HashSet<glam::IVec3> = HashSet::new();
        for &u in &corners {
            let (mut lo, mut hi) = (Vec3::MAX, Vec3::MIN);
            for &t in self.tris.of(u) {
                for w in control.triangles[t as usize] {
                    let p = control.positions[w as usize];
                    let before = pushed.get(&w).map_or(p, |&d| p - d);
                    lo = lo.min(p).min(before);
                    hi = hi.max(p).max(before);
                }
            }
            let (a, b) = (cell_of(lo - margin), cell_of(hi + margin));
            let span = (b - a + 1).as_i64vec3();
            if cells.len() as i64 + span.x * span.y * span.z > NEAR_PUSH_MAX_CELLS as i64 {
                return Ok(None);
            }
            for z in a.z..=b.z {
                for y in a.y..=b.y {
                    for x in a.x..=b.x {
                        cells.insert(glam::IVec3::new(x, y, z));
                    }
                }
            }
        }
        let mut near = Vec::new();
        for slab in 0..self.slabs.count() {
            self.visit_slab(slab, input.centres, cancel, &mut |ps, is| {
                let found: Vec<Watched> = ps
                    .par_iter()
                    .zip(is)
                    .filter(|(p, _)| cells.contains(&cell_of(**p)))
                    .map(|(&position, &particle)| Watched {
                        particle,
                        position,
                        parent: NO_PARENT,
                    })
                    .collect();
                near.extend(found);
            })?;
        }
        Ok(Some(near))
    }
}

/// Most cells of 2r that [`Rounds::centres_near_pushes`] marks before it measures every
/// centre again instead (64 MiB of cells).
const NEAR_PUSH_MAX_CELLS: usize = 1 << 22;

/// The parent of a centre measured again for being near a push, not for being watched.
const NO_PARENT: u32 = u32::MAX;

/// Moves the control vertices by `push` (sorted by vertex), halving the pushes around
/// any triangle they would turn by more than [`MAX_TURN_COS`] (up to three times, then
/// leaving those vertices where they were), so that pushes never fold the surface; the
/// pushes that were made are left in `push`.
fn apply_pushes(control: &mut TriMesh, tris: &VertexTriangles, push: &mut [(u32, DVec3)]) {
    let before: Vec<Vec3> = push
        .iter()
        .map(|&(v, _)| control.positions[v as usize])
        .collect();
    let normal = |positions: &[Vec3], t: u32| {
        let [a, b, c] = control.triangles[t as usize].map(|v| positions[v as usize].as_dvec3());
        (b - a).cross(c - a).normalize_or_zero()
    };
    // Every triangle around a pushed vertex, once, with its normal before.
    let mut around: Vec<u32> = push
        .iter()
        .flat_map(|&(v, _)| tris.of(v).iter().copied())
        .collect();
    around.sort_unstable();
    around.dedup();
    let old: Vec<DVec3> = around
        .iter()
        .map(|&t| normal(&control.positions, t))
        .collect();
    for attempt in 0..=3 {
        for (k, &(v, d)) in push.iter().enumerate() {
            control.positions[v as usize] = (before[k].as_dvec3() + d).as_vec3();
        }
        let folded: Vec<u32> = around
            .iter()
            .zip(&old)
            .filter(|&(&t, n)| normal(&control.positions, t).dot(*n) < MAX_TURN_COS)
            .map(|(&t, _)| t)
            .collect();
        if folded.is_empty() {
            return;
        }
        for t in folded {
            for v in control.triangles[t as usize] {
                if let Ok(k) = push.binary_search_by_key(&v, |&(w, _)| w) {
                    push[k].1 = if attempt == 3 {
                        DVec3::ZERO
                    } else {
                        push[k].1 * 0.5
                    };
                }
            }
        }
    }
    for (k, &(v, d)) in push.iter().enumerate() {
        control.positions[v as usize] = (before[k].as_dvec3() + d).as_vec3();
    }
}

/// Least cosine between a control triangle's normal before and after a round's pushes.
const MAX_TURN_COS: f64 = 0.25;

/// Depth, beyond the required one and in multiples of r, under the tangent plane of the
/// nearest vertex that counts as deep enough without measuring the triangles.
pub(super) const FAST_MARGIN: f64 = 0.15;

#[cfg(test)]
mod tests {
    use super::super::contain;
    use super::super::measure::with_index;
    use super::*;
    use crate::isolated::icosphere;

    /// A centre outside a coarse closed surface ends inside at the depth, after pushes that
    /// move only the triangles over it; centres already deep enough move nothing.
    #[test]
    fn pushes_shallow_centres_under_the_surface() {
        for levels in [0, 1] {
            let mut control = icosphere(1, 1.0);
            let before = control.clone();
            let centres = [
                DVec3::new(0.0, 1.05, 0.0).as_vec3(), // outside
                DVec3::new(0.7, 0.0, 0.0).as_vec3(),  // shallow
                DVec3::new(0.0, 0.0, 0.0).as_vec3(),  // deep
            ];
            let options = ContainmentOptions {
                min_depth: 1.0,
                max_rounds: 6,
                ..Default::default()
            };
            let stats = contain(&mut control, levels, &centres, 0.3, &options);
            let mut surface = control.clone();
            crate::subdivision::subdivide(
                &mut surface,
                &crate::subdivision::SubdivideOptions { levels },
            );
            assert_eq!(stats.remaining, 0, "levels {levels}: {stats:?}");
            assert!(stats.outside >= 1 && stats.too_shallow >= 2, "{stats:?}");
            with_index(&surface, 0.3, false, |index| {
                for p in &centres[..2] {
                    let probe = index.probe(p.as_dvec3()).unwrap();
                    assert!(
                        probe.signed_distance <= -0.3 + 1e-6,
                        "{}",
                        probe.signed_distance
                    );
                }
            });
            let moved = before
                .positions
                .iter()
                .zip(&control.positions)
                .filter(|(a, b)| a != b)
                .count();
            assert!(moved > 0 && moved < before.positions.len() / 2, "{moved}");
            assert!(crate::mesh::validate(&surface).is_closed_manifold());
        }
    }

    /// A centre measured outside farther than the surface can have moved from one that
    /// enclosed it is not pushed (its side was read through a fold) and counts as folded,
    /// not remaining; a centre a little outside is pushed under as always. Without the
    /// bound both are pushed.
    #[test]
    fn centres_farther_outside_than_the_surface_moved_are_not_pushed() {
        let r = 0.2f32;
        let centres = [
            Vec3::new(0.0, 1.0 + 0.1 * r, 0.0), // a little outside: pushed
            Vec3::new(1.0 + 1.5 * r, 0.0, 0.0), // 1.5 r outside: folded
        ];
        let run = |farthest_outside: Option<f32>| {
            let mut control = icosphere(3, 1.0);
            let input = ContainmentInput {
                sizes: None,
                farthest_outside,
                levels: 0,
                centres: &centres[..],
                isolated: &[],
                particle_radius: r,
                slab_triangles: usize::MAX,
            };
            let options = ContainmentOptions::default();
            let stats = contain_centres(&mut control, &input, &options, &CancelToken::new())
                .expect("in memory");
            let reach = |axis: usize| {
                control
                    .positions
                    .iter()
                    .map(|p| p[axis])
                    .fold(f32::MIN, f32::max)
            };
            (stats, reach(0), reach(1))
        };
        let (bounded, x, y) = run(Some(0.05 * r));
        assert_eq!((bounded.folded, bounded.remaining), (1, 0), "{bounded:?}");
        assert!(
            x < 1.0 + 1e-6,
            "the folded centre pushed the surface to x = {x}"
        );
        assert!(
            y > 1.0 + 0.3 * r,
            "the centre a little outside was not pushed: y = {y}"
        );
        let (free, x, _) = run(None);
        assert_eq!((free.folded, free.remaining), (0, 0), "{free:?}");
        assert!(
            x > 1.0 + 1.5 * r,
            "without the bound the far centre is pushed: x = {x}"
        );
    }

    /// Centres a little outside a sphere, and a grid of centres inside it at spacing
    /// about r: the particles of [`pushes_of_more_than_r_measure_again_only_near_them`]
    /// and of [`centres_near_pushes_hold_every_centre_near_the_moved_surface`].
    fn ball_with_outsiders(r: f32) -> Vec<Vec3> {
        let mut centres = Vec::new();
        let steps = 20;
        for z in -steps..=steps {
            for y in -steps..=steps {
                for x in -steps..=steps {
                    let p = Vec3::new(x as f32, y as f32, z as f32) * (0.95 / steps as f32);
                    if p.length() < 0.96 {
                        centres.push(p);
                    }
                }
            }
        }
        // Three centres 0.8 r outside, in different directions (pushes of about 1.5 r).
        for d in [
            Vec3::X,
            Vec3::new(0.0, -0.6, 0.8),
            Vec3::new(-0.5, 0.5, 0.7),
        ] {
            centres.push(d.normalize() * (1.0 + 0.8 * r));
        }
        centres
    }

    /// After pushes of more than r, the centres chosen to be measured again include every
    /// centre within `depth + r` of a point of the one-step surface that moved, where it
    /// was or where it is (the surface points checked one by one, against the choice made
    /// from boxes of control vertices).
    #[test]
    fn centres_near_pushes_hold_every_centre_near_the_moved_surface() {
        let r = 0.05f32;
        let centres = ball_with_outsiders(r);
        let mut control = icosphere(4, 1.0);
        let input = ContainmentInput {
            sizes: None,
            farthest_outside: None,
            levels: 1,
            centres: &centres[..],
            isolated: &[],
            particle_radius: r,
            slab_triangles: usize::MAX,
        };
        let depth = 0.25 * r as f64;
        let mut stats = ContainmentStats::default();
        let mut rounds = Rounds::new(&mut control, &input, depth, &mut stats);
        let need = Need {
            depth,
            r: r as f64,
            margin: r as f64,
            ratios: None,
            farthest_outside: f64::INFINITY,
        };
        let mut found = rounds
            .measure(&control, &input, &need, &CancelToken::new(), &mut stats)
            .unwrap();
        assert_eq!(found.shallow.len(), 3);
        let before = control.clone();
        let (_, largest) = rounds.push_out(&mut control, &mut found.shallow);
        assert!(largest > r as f64, "{largest}");
        let chosen: HashSet<u32> = rounds
            .centres_near_pushes(&control, &input, &CancelToken::new())
            .unwrap()
            .expect("a small region")
            .iter()
            .map(|w| w.particle)
            .collect();
        let one_step = |mesh: &TriMesh| {
            let mut m = mesh.clone();
            crate::subdivision::subdivide(
                &mut m,
                &crate::subdivision::SubdivideOptions { levels: 1 },
            );
            m.positions
        };
        let (old, new) = (one_step(&before), one_step(&control));
        let moved: Vec<Vec3> = old
            .iter()
            .zip(&new)
            .filter(|(a, b)| a != b)
            .flat_map(|(a, b)| [*a, *b])
            .collect();
        assert!(!moved.is_empty());
        let reach = (depth + r as f64) as f32;
        let mut near = 0;
        for (i, c) in centres.iter().enumerate() {
            if moved.iter().any(|q| q.distance(*c) < reach) {
                near += 1;
                assert!(chosen.contains(&(i as u32)), "centre {i} at {c} not chosen");
            }
        }
        // Some; the boxes of the moved control one-rings hold more (1359 against 41 when
        // written), but a small part of all centres.
        assert!(
            near > 20 && chosen.len() * 10 < centres.len(),
            "{near} near, {} chosen",
            chosen.len()
        );
    }

    /// Centres a little outside need pushes of more than r: the next round measures again the
    /// centres near the moved surface only, not all of them, and every centre still ends
    /// at the depth under the surface Loop makes.
    #[test]
    fn pushes_of_more_than_r_measure_again_only_near_them() {
        let r = 0.05f32;
        let centres = ball_with_outsiders(r);
        let inside = centres.len() - 3;
        let mut control = icosphere(4, 1.0);
        let options = ContainmentOptions {
            min_depth: 0.25,
            max_rounds: 8,
            ..Default::default()
        };
        let stats = contain(&mut control, 1, &centres, r, &options);
        assert_eq!(stats.remaining, 0, "{stats:?}");
        assert!(stats.outside >= 3 && stats.rounds >= 2, "{stats:?}");
        // Measured again: some, far fewer than the near centres of the first round.
        assert!(
            stats.remeasured > 0 && stats.remeasured * 3 < stats.near_centres,
            "{stats:?} ({inside} inside)"
        );
        let mut surface = control.clone();
        crate::subdivision::subdivide(
            &mut surface,
            &crate::subdivision::SubdivideOptions { levels: 1 },
        );
        assert!(crate::mesh::validate(&surface).is_closed_manifold());
        let depth = 0.25 * r as f64;
        with_index(&surface, r as f64, false, |index| {
            for p in &centres {
                match index.probe(p.as_dvec3()) {
                    Some(probe) => assert!(
                        probe.signed_distance <= -depth + 2e-3 * r as f64,
                        "{p}: {}",
                        probe.signed_distance
                    ),
                    // No surface within r: deep inside (the pushes only moved it out).
                    None => assert!(p.length() < 1.0 - r, "{p}"),
                }
            }
        });
    }
}
