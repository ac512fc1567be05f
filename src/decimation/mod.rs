//! Quadric-error-metric decimation (M. Garland and P. Heckbert, "Surface Simplification
//! Using Quadric Error Metrics", SIGGRAPH 1997), as Akinci et al. 2013 § 3.2 use it to
//! remove the bumps that irregular particle placement leaves in flat regions.
//!
//! **Input:** a triangle mesh. **Output:** the same surface with fewer triangles, unused
//! vertices removed, normals cleared.
//!
//! Steps: rescale to the unit box (conditioning) → per-vertex area-weighted plane quadrics
//! → passes until the triangle target or the error bound is reached: cost every live edge
//! (in parallel), find the cost of the (2·goal)-th cheapest, collapse every edge below it
//! in mesh order, each vertex at most once per pass (several passes approximate the
//! greedy order of a heap, without the heap's cache misses) → compact.
//!
//! **Reuse between passes.** An edge's cost and placement are a function of its two
//! ends' positions and quadrics, so a pass takes them from the previous pass's candidate
//! of the same triangle side when neither end moved (the tail passes of a decimation cost
//! few edges anew). A refused collapse is not tried again until a collapse has changed the
//! one-ring of one of its ends: every collapse stamps the closed one-ring of the merged
//! vertex, which is all it changes. Both are exact: the output is the same as costing and
//! trying everything every pass (a unit test compares them). On the 168k-particle splash's
//! raw surface (707k triangles, error-bounded) this halves the edges costed and the
//! refusals tried (143k → 62k), −9 % of the decimation's instructions.
//!
//! **Parallel walk** (meshes decimated whole, not region by region). The triangles are
//! cut into fixed chunks of `CHUNK_TRIANGLES` in mesh order (spatially coherent:
//! marching cubes emits them block by block). At the start of a pass every vertex is
//! owned by the chunk of its lowest-numbered triangle. The chunks
//! then walk their own candidates in parallel, each taking only collapses whose two closed
//! one-rings are owned by the chunk, so no two chunks ever read or write the same vertex or
//! triangle; each chunk may do its share of the pass's goal (in proportion to its
//! candidates below the limit). A sequential walk over all candidates in mesh order then
//! takes the collapses across chunk borders. Chunking does not depend on the thread count,
//! so neither does the output.
//!
//! **Regions (memory follows the region, not the mesh).** A mesh with more than twice
//! [`DecimateOptions::region_triangles`] triangles is first cut into regions: runs of
//! `region_triangles / 2` vertices in Morton order of position (compact pieces of
//! surface). Triangles with vertices in two regions are seam triangles; their vertices are
//! locked. Each region is decimated on its own, to the same fraction (or error bound), with
//! only its own state in memory (regions run in parallel, one per thread), and replaced by
//! its result in region order. A region's passes take their collapses in the sequential
//! walk alone: with the cores busy on other regions, the parallel walk's ownership tests
//! were pure cost (4M scene: decimation 4.0 → 3.5 s, 2026-11-24), and walking each region
//! in plain mesh order is closer to the greedy order (1M scene: flat bumpiness 0.0080 r
//! instead of 0.0083 r). Then the band around the seams (`decimate_band`: the seam
//! vertices and two rings around them) is decimated to the overall target, the rest of
//! the mesh left as the regions made it. Seam vertices keep their exact input positions until that
//! pass. (A final pass over the whole mesh instead took 0.90 s of 5.8 s on the 4M scene
//! for 2 % of the collapses, 2026-11-23.) On a 4M-particle scene (11.1 M raw
//! triangles, 41 regions) this keeps decimation under the field's memory peak (whole mesh
//! at once: +0.9 GB) and made it faster when introduced (regions one at a time: 4.8 s
//! instead of 7.6 s on that day's machine), since each region's state stays in cache;
//! the price, measured on the 1M-particle scene when regions came in, was a flat-region
//! bumpiness of 0.0076 r instead of 0.0075 r (regions of 2^17 triangles: faster still, but
//! 0.0078 r). The regions depend only on the mesh and the option, never on the
//! thread count. A tile's piece of a tiled run is cut the same way, its border locked
//! (`decimate_keeping`): the vertices locked by the caller stay locked in the band.
//!
//! **Order:** edges are ranked by the collapse's RMS distance to the original planes,
//! `Q(p) / area` (the quadric cost normalised by the area it stands for), not by the raw
//! area-weighted cost `Q(p)`: the raw cost grows with the area merged into a vertex, so it
//! protects large flat regions, which are exactly where the paper wants the particle bumps
//! gone. On `dambreak_small` frame 25 at the same 80 % this takes the flat-region
//! bumpiness (`shared/eval/meshq.py`) from 0.0099 r to 0.0079 r and the largest collapse
//! error from 0.0020 to 0.0007 world units.
//!
//! **Placement:** the quadric optimum when `A` is well conditioned and the optimum lies
//! within one edge length of the edge's midpoint; otherwise the quadric minimum on the
//! segment (the paper's choice).
//!
//! **A collapse is refused** when it would
//! * touch a boundary or non-manifold edge's vertex (boundaries neither open nor move);
//! * break the link condition (the endpoints share a neighbour other than the two
//!   opposite vertices), or leave an opposite vertex with valence below 3 (no folds, no
//!   collapsed tetrahedra);
//! * turn any surviving triangle by more than 60° (normal dot < 0.5), from its current
//!   normal or from its normal in the input (so small turns cannot add up to a flip), or
//!   make it degenerate (quality `4√3·A / Σl²` below 0.02).
//!
//! A closed 2-manifold therefore stays one. Costs are computed in parallel but each is a
//! pure function of the state, and collapses run in sorted order on one thread, so the
//! output is deterministic and does not depend on the thread count.

mod candidate;
mod collapse;
mod pieces;
mod placement;
mod quadric;
mod state;
mod tri_list;

use crate::mesh::TriMesh;
use candidate::{Candidate, Mark};
use collapse::{Attempt, Outcome, View, WalkTally};
use glam::{DVec3, Vec3};
pub(crate) use pieces::place_survivors;
pub(crate) use pieces::{decimate_band, Remap};
use rayon::prelude::*;
use state::State;

/// Options of [`decimate`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub struct DecimateOptions {
    /// Fraction of the triangles to remove, in `[0, 1)`, or `None` to stop on the error
    /// bound only. Default `Some(0.8)` (the paper's).
    pub target_reduction: Option<f32>,
    /// Largest error of a collapse, world units: the root of the quadric cost divided by
    /// the quadric's area weight (an RMS distance to the original planes). `None`: no
    /// bound. Default `None`.
    pub max_error: Option<f32>,
    /// Region size, triangles: a mesh with more than twice this many is decimated region
    /// by region first (see the module docs), so that the decimation state follows the
    /// region, not the mesh. `0` never splits. Default `1 << 18` (262 144).
    #[serde(default = "default_region_triangles")]
    pub region_triangles: usize,
}

fn default_region_triangles() -> usize {
    1 << 18
}

impl DecimateOptions {
    /// Checks the target: a fraction in `[0, 1)` and an error bound `> 0` (world units),
    /// at least one of them.
    pub fn validate(&self) -> crate::Result<()> {
        let bad = |option: &'static str, message: String| {
            Err(crate::Error::InvalidOption { option, message })
        };
        match (self.target_reduction, self.max_error) {
            (Some(f), _) if !(0.0..1.0).contains(&f) => bad(
                "decimate.target_reduction",
                format!("takes a fraction in [0, 1), got {f}"),
            ),
            (_, Some(e)) if !(e.is_finite() && e > 0.0) => bad(
                "decimate.max_error",
                format!("must be > 0 (world units), got {e}"),
            ),
            (None, None) => bad(
                "decimate",
                "needs a fraction to remove or an error bound, or no decimation".into(),
            ),
            _ => Ok(()),
        }
    }

    /// Removing the fraction `target_reduction` of the triangles, without an error bound.
    pub fn fraction(target_reduction: f32) -> Self {
        DecimateOptions {
            target_reduction: Some(target_reduction),
            max_error: None,
            region_triangles: default_region_triangles(),
        }
    }

    /// Collapsing while no collapse moves the surface by more than `max_error` (world
    /// units), whatever the number of triangles.
    pub fn error_bound(max_error: f32) -> Self {
        DecimateOptions {
            target_reduction: None,
            max_error: Some(max_error),
            region_triangles: default_region_triangles(),
        }
    }

    /// The same options with the error bound `max_error` (world units, `None`: none).
    pub fn with_max_error(self, max_error: Option<f32>) -> Self {
        DecimateOptions { max_error, ..self }
    }

    /// The same options with regions of `region_triangles` (0: never split).
    pub fn with_region_triangles(self, region_triangles: usize) -> Self {
        DecimateOptions {
            region_triangles,
            ..self
        }
    }

    /// Whether a mesh of `triangles` is decimated region by region.
    fn splits(&self, triangles: usize) -> bool {
        self.region_triangles > 0 && triangles > 2 * self.region_triangles
    }

    /// Triangles to keep out of `triangles`: the fraction's share, rounded up, or 0 when
    /// only the error bound stops the decimation.
    pub fn target_triangles(&self, triangles: usize) -> usize {
        self.target_reduction
            .map(|f| ((1.0 - f.clamp(0.0, 1.0) as f64) * triangles as f64).ceil() as usize)
            .unwrap_or(0)
    }
}

impl Default for DecimateOptions {
    fn default() -> Self {
        DecimateOptions {
            target_reduction: Some(0.8),
            max_error: None,
            region_triangles: default_region_triangles(),
        }
    }
}

/// What [`decimate`] did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct DecimateStats {
    /// Triangles before.
    pub triangles_before: usize,
    /// Triangles after.
    pub triangles_after: usize,
    /// Edge collapses performed.
    pub collapses: usize,
    /// Vertices locked because they lie on a boundary or non-manifold edge (not counting
    /// the seams between pieces; summed over the pieces, so a vertex near a seam may
    /// count twice).
    pub refused_boundary: usize,
    /// Collapses refused by the link condition or valence rule.
    pub refused_topology: usize,
    /// Collapses refused because a triangle would flip or degenerate.
    pub refused_geometry: usize,
    /// Largest error of a performed collapse, world units.
    pub max_error: f32,
    /// Sorted passes over the edges (summed over the regions and the seam band).
    pub passes: u32,
    /// Regions decimated before the band around their seams (0: not split).
    pub regions: usize,
}

impl DecimateStats {
    /// Adds the work of another run (collapses, refusals, passes; the larger error) to
    /// this one, for decimations done piece by piece.
    pub(crate) fn add_work(&mut self, other: &DecimateStats) {
        self.collapses += other.collapses;
        self.refused_topology += other.refused_topology;
        self.refused_geometry += other.refused_geometry;
        self.max_error = self.max_error.max(other.max_error);
        self.passes += other.passes;
        self.refused_boundary += other.refused_boundary;
    }
}

/// Memory of a region being decimated, bytes per triangle of
/// [`DecimateOptions::region_triangles`]: its piece, quadrics, candidates and walk state.
/// Measured as what each further thread added to the peak of the 4M splash under
/// `--memory-budget 1GiB` in 128-block tiles (16 regions a tile) before the regions in
/// flight were capped: 42–44 MiB from 2 to 8 and to 16 threads.
pub(crate) const REGION_BYTES_PER_TRIANGLE: u64 = 170;

/// Triangles per chunk of the parallel walk. Fixed, so the output does not depend on the
/// number of threads.
pub(crate) const CHUNK_TRIANGLES: usize = 16 * 1024;

/// Decimates `mesh` in place.
pub fn decimate(mesh: &mut TriMesh, options: &DecimateOptions) -> DecimateStats {
    let target = options.target_triangles(mesh.triangle_count());
    if options.splits(mesh.triangle_count()) {
        pieces::decimate_by_regions(mesh, options, target, &[], Remap::Drop, usize::MAX).0
    } else {
        decimate_locked(mesh, target, options.max_error, &[]).0
    }
}

/// [`decimate`] with the `locked` vertices (indexed like the mesh's) never moving nor
/// removed, region by region when the mesh is large; returns the stats and the new index
/// of every input vertex (`u32::MAX` when it was removed). A tile's piece goes through
/// it ([`crate::tiles`]), its border locked. At most `in_flight` regions are decimated at
/// once, whatever the thread count: each holds about [`REGION_BYTES_PER_TRIANGLE`] per
/// triangle of [`DecimateOptions::region_triangles`] (the output does not depend on it).
pub(crate) fn decimate_keeping(
    mesh: &mut TriMesh,
    options: &DecimateOptions,
    locked: &[bool],
    in_flight: usize,
) -> (DecimateStats, Vec<u32>) {
    let target = options.target_triangles(mesh.triangle_count());
    if options.splits(mesh.triangle_count()) {
        pieces::decimate_by_regions(mesh, options, target, locked, Remap::Keep, in_flight)
    } else {
        decimate_locked(mesh, target, options.max_error, locked)
    }
}

fn bounds(positions: &[Vec3]) -> (DVec3, DVec3) {
    positions
        .iter()
        .fold((DVec3::MAX, DVec3::MIN), |(l, h), p| {
            (l.min(p.as_dvec3()), h.max(p.as_dvec3()))
        })
}

/// Decimates to `target` triangles or the error bound, with the `extra_locked` vertices
/// (indexed like the mesh's; may be empty) never moving; returns the stats and the new
/// index of every input vertex (`u32::MAX` when it was removed).
pub(crate) fn decimate_locked(
    mesh: &mut TriMesh,
    target: usize,
    max_error: Option<f32>,
    extra_locked: &[bool],
) -> (DecimateStats, Vec<u32>) {
    decimate_locked_walk(mesh, target, max_error, extra_locked, Walk::Chunked)
}

/// How the passes of [`decimate_locked_walk`] take their collapses.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) enum Walk {
    /// The parallel walk inside chunks, then the sequential walk over what is left.
    Chunked,
    /// The sequential walk alone, over all candidates in mesh order: for meshes that are
    /// themselves decimated in parallel with others (the regions), where the chunked walk's
    /// ownership tests are pure cost.
    Sequential,
}

/// [`decimate_locked`] with the choice of walk.
pub(crate) fn decimate_locked_walk(
    mesh: &mut TriMesh,
    target: usize,
    max_error: Option<f32>,
    extra_locked: &[bool],
    walk: Walk,
) -> (DecimateStats, Vec<u32>) {
    decimate_with(mesh, target, max_error, extra_locked, walk, Reuse::Yes)
}

/// Whether a pass reuses what the previous one learnt: the costs of edges whose ends did
/// not move, and the refusals of collapses whose one-rings did not change. Either way the
/// output is the same (a unit test compares them); `No` is the reference.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Reuse {
    Yes,
    #[cfg(test)]
    No,
}

/// [`decimate_locked_walk`], reusing or not.
fn decimate_with(
    mesh: &mut TriMesh,
    target: usize,
    max_error: Option<f32>,
    extra_locked: &[bool],
    walk: Walk,
    reuse: Reuse,
) -> (DecimateStats, Vec<u32>) {
    let before = mesh.triangle_count();
    let mut stats = DecimateStats {
        triangles_before: before,
        triangles_after: before,
        ..Default::default()
    };
    if before == 0 {
        return (stats, (0..mesh.vertex_count() as u32).collect());
    }
    let (mut s, frame) = State::from_mesh(mesh, extra_locked, &mut stats);
    s.reuse = reuse;
    let mut progress = Progress {
        stats,
        alive_tris: before,
        target,
        max_cost_error: max_error.map(|e| e as f64 / frame.scale),
        scale: frame.scale,
    };
    let mut pass = 0u32;
    let mut stalled = false;
    // Multiple of the pass goal that sets the cost limit; grows when passes stall.
    let mut limit_factor = 2usize;
    // The candidates of the previous pass, whose costs the next pass reuses where neither
    // end moved.
    let mut previous = Vec::new();
    while progress.alive_tris > target {
        pass += 1;
        let mut chunks = s.candidates(std::mem::take(&mut previous), pass);
        // Collapse every edge cheaper than the cost of the (2·goal)-th cheapest candidate,
        // walking the edges in mesh order (spatially coherent, so the walk stays in cache),
        // each vertex at most once per pass; several passes approximate the greedy order
        // of a heap. A pass that collapses nothing lifts the limit once.
        let goal = (progress.alive_tris - target).div_ceil(2).max(1);
        let cost_limit = if stalled {
            f64::INFINITY
        } else {
            cost_limit(&chunks, limit_factor * goal)
        };
        let mut done = 0;
        if walk == Walk::Chunked && chunks.len() > 1 && progress.alive_tris > target + 2 {
            done += parallel_walk(&mut s, &mut chunks, cost_limit, goal, pass, &mut progress);
        }
        done += sequential_walk(
            &mut s,
            &mut chunks,
            cost_limit,
            goal - done.min(goal),
            pass,
            &mut progress,
        );
        if done == 0 {
            // Nothing changed: a pass with no limit would try the same collapses again
            // unless some were over this pass's limit and under the error bound.
            let bound = progress.max_cost_error;
            let tried_all = chunks
                .iter()
                .flatten()
                .all(|c| c.cost <= cost_limit || bound.is_some_and(|m| c.cost.sqrt() > m));
            if stalled || tried_all {
                break;
            }
            previous = chunks;
            stalled = true;
        } else {
            previous = chunks;
            stalled = false;
        }
        // A pass that reached under a quarter of its goal spent a full costing for little:
        // widen the limit so the tail of the decimation takes few passes.
        if done * 4 < goal {
            limit_factor = limit_factor.saturating_mul(4);
        }
    }
    drop(previous);
    let mut stats = progress.stats;
    stats.passes = pass;
    let remap = s.compact_into(mesh, frame);
    stats.triangles_after = mesh.triangle_count();
    (stats, remap)
}

/// The unit-box frame of the decimation state: `unit = (world − centre) / scale`.
#[derive(Clone, Copy)]
struct Frame {
    centre: DVec3,
    scale: f64,
}

/// The running figures of [`decimate_locked_walk`].
struct Progress {
    stats: DecimateStats,
    alive_tris: usize,
    target: usize,
    /// The error bound in unit-box units.
    max_cost_error: Option<f64>,
    scale: f64,
}

impl Progress {
    /// Counts a walk's collapses and refusals.
    fn record(&mut self, tally: &WalkTally) {
        self.alive_tris -= tally.removed_triangles;
        self.stats.collapses += tally.collapses;
        self.stats.refused_topology += tally.refused_topology;
        self.stats.refused_geometry += tally.refused_geometry;
        self.stats.max_error = self
            .stats
            .max_error
            .max((tally.max_error * self.scale) as f32);
    }
}

/// The cost of the `k`-th cheapest candidate (the last when there are fewer), rounded up
/// to the next `f32`; infinite when there is no candidate.
fn cost_limit(chunks: &[Vec<Candidate>], k: usize) -> f64 {
    let mut costs: Vec<f32> = chunks
        .iter()
        .flat_map(|c| c.iter().map(|c| c.cost as f32))
        .collect();
    if costs.is_empty() {
        return f64::INFINITY;
    }
    // Twice the goal: with each vertex moved at most once per pass, about half of the
    // edges below the limit can collapse. Measured on frame 25 and the box: as good as
    // half the goal (greedier) in 9 passes instead of 18; four times the goal takes 3
    // passes but raises the box's flat normal error by 25 %.
    let k = k.min(costs.len() - 1);
    // The limit in f32 (half the memory), rounded up to keep every f64 cost equal to it
    // below it.
    costs.select_nth_unstable_by(k, f32::total_cmp).1.next_up() as f64
}

/// The parallel walk: each chunk takes the collapses whose closed one-rings it owns, up to
/// its share of the pass's goal (in proportion to its candidates below the limit); the
/// candidates it decided are marked. Returns the collapses made.
fn parallel_walk(
    s: &mut State,
    chunks: &mut [Vec<Candidate>],
    cost_limit: f64,
    goal: usize,
    pass: u32,
    progress: &mut Progress,
) -> usize {
    s.assign_owners();
    let below: Vec<usize> = chunks
        .par_iter()
        .map(|c| c.iter().filter(|c| c.cost <= cost_limit).count())
        .collect();
    let below_total: usize = below.iter().sum::<usize>().max(1);
    // Each collapse removes at most two triangles, and the chunks' shares add up to at
    // most the goal, so the parallel walk cannot overshoot the target.
    let budget = goal.min((progress.alive_tris - progress.target) / 2);
    let max_cost_error = progress.max_cost_error;
    // Every collapse of the parallel walk stamps with the same clock, newer than every
    // refusal so far.
    let clock = s.clock + 1;
    let view = View::new(s);
    let tallies: Vec<WalkTally> = chunks
        .par_iter_mut()
        .zip(below)
        .enumerate()
        .map(|(chunk, (candidates, below))| {
            let share = (budget as u128 * below as u128 / below_total as u128) as usize;
            // SAFETY: the chunk takes only collapses whose closed one-rings it owns (see
            // `walk_chunk`), and ownership is fixed during the walk, so no two chunks
            // touch the same vertex, triangle or vertex list.
            unsafe {
                view.walk_chunk(
                    chunk as u32,
                    candidates,
                    cost_limit,
                    share,
                    Attempt {
                        pass,
                        max_cost_error,
                        clock,
                    },
                )
            }
        })
        .collect();
    s.clock = clock;
    tallies
        .iter()
        .map(|t| {
            progress.record(t);
            t.collapses
        })
        .sum()
}

/// The sequential walk over all candidates in mesh order, skipping those the parallel walk
/// decided and those refused before whose ends no collapse has stamped since (they would
/// be refused again), until `goal` more collapses are made or the target is reached.
/// Returns the collapses made.
fn sequential_walk(
    s: &mut State,
    chunks: &mut [Vec<Candidate>],
    cost_limit: f64,
    goal: usize,
    pass: u32,
    progress: &mut Progress,
) -> usize {
    let mut clock = s.clock;
    let reuse = s.reuse;
    let view = View::new(s);
    let mut done = 0;
    for c in chunks.iter_mut().flatten() {
        if done >= goal || progress.alive_tris <= progress.target {
            break;
        }
        // SAFETY (here and below): one thread; `view` is the only access to the state.
        if c.mark == Mark::DECIDED || c.cost > cost_limit || unsafe { view.refused_since(c) } {
            continue;
        }
        let mut tally = WalkTally::default();
        let attempt = Attempt {
            pass,
            max_cost_error: progress.max_cost_error,
            clock: clock + 1,
        };
        let outcome = unsafe { view.try_collapse(c, attempt, &mut tally) };
        match outcome {
            Outcome::Collapsed => {
                clock += 1;
                done += 1;
            }
            Outcome::Refused if reuse == Reuse::Yes => c.mark = clock,
            Outcome::Refused | Outcome::Passed => {}
        }
        progress.record(&tally);
    }
    s.clock = clock;
    done
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_rng::TestRng;

    /// An icosphere of 20·4^level triangles, every vertex pushed in or out by up to
    /// `noise` (the bumps decimation removes).
    fn noisy_sphere(level: u32, noise: f32) -> TriMesh {
        let mut mesh = crate::isolated::icosphere(level, 1.0);
        let mut rng = TestRng::new(3);
        for p in &mut mesh.positions {
            *p *= 1.0 + noise * (rng.unit_f64() as f32 * 2.0 - 1.0);
        }
        mesh
    }

    #[test]
    fn keeping_locked_vertices_region_by_region_reports_where_every_vertex_went() {
        let input = noisy_sphere(6, 0.01);
        // A cap and a ring of vertices locked (a tile's border), across several regions.
        let locked: Vec<bool> = input
            .positions
            .iter()
            .map(|p| p.z > 0.8 || p.x.abs() < 0.02)
            .collect();
        let options = DecimateOptions::default().with_region_triangles(4096);
        let mut mesh = input.clone();
        let (stats, remap) = decimate_keeping(&mut mesh, &options, &locked, usize::MAX);
        assert!(stats.regions >= 8, "{stats:?}");
        assert!(
            mesh.triangle_count() <= input.triangle_count() / 4,
            "{stats:?}"
        );
        assert!(crate::mesh::validate(&mesh).is_closed_manifold());
        // Every output vertex is the image of exactly one input vertex.
        let mut seen = vec![false; mesh.vertex_count()];
        for &new in remap.iter().filter(|&&n| n != u32::MAX) {
            assert!(
                !std::mem::replace(&mut seen[new as usize], true),
                "{new} twice"
            );
        }
        assert!(seen.iter().all(|&s| s), "an output vertex nobody maps to");
        // The locked ones survive at their exact input positions.
        for (v, _) in locked.iter().enumerate().filter(|(_, &l)| l) {
            let new = remap[v];
            assert_ne!(new, u32::MAX, "locked vertex {v} removed");
            assert_eq!(
                mesh.positions[new as usize], input.positions[v],
                "vertex {v}"
            );
        }
        // Unlocked vertices did move or go: the decimation did its work around them.
        let unlocked_kept = (0..input.vertex_count())
            .filter(|&v| !locked[v] && remap[v] != u32::MAX)
            .count();
        assert!(unlocked_kept < (input.vertex_count() - locked.iter().filter(|&&l| l).count()) / 3);
        // The same with one thread.
        let mut one = input.clone();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let (_, remap_one) =
            pool.install(|| decimate_keeping(&mut one, &options, &locked, usize::MAX));
        assert!(
            one == mesh && remap_one == remap,
            "thread count changed the output"
        );
        // And with one region at a time, or three (what a memory budget may allow).
        for in_flight in [1, 3] {
            let mut capped = input.clone();
            let (_, remap_capped) = decimate_keeping(&mut capped, &options, &locked, in_flight);
            assert!(
                capped == mesh && remap_capped == remap,
                "{in_flight} regions at once changed the output"
            );
        }
    }

    #[test]
    fn reusing_costs_and_refusals_gives_the_same_decimation() {
        // Five chunks (the parallel walk runs), with and without an error bound.
        let mesh = noisy_sphere(6, 0.01);
        let n = mesh.triangle_count();
        assert!(n > 4 * CHUNK_TRIANGLES);
        for (walk, target, max_error) in [
            (Walk::Chunked, n / 5, None),
            (Walk::Sequential, n / 5, None),
            (Walk::Chunked, n / 10, Some(0.004)),
            (Walk::Sequential, 0, Some(0.004)),
        ] {
            let mut reused = mesh.clone();
            let (stats, remap) =
                decimate_with(&mut reused, target, max_error, &[], walk, Reuse::Yes);
            let mut fresh = mesh.clone();
            let (reference, reference_remap) =
                decimate_with(&mut fresh, target, max_error, &[], walk, Reuse::No);
            assert!(reused == fresh, "{target} {max_error:?}: the meshes differ");
            assert_eq!(remap, reference_remap);
            assert_eq!(stats.collapses, reference.collapses);
            assert_eq!(stats.passes, reference.passes);
            assert!(stats.collapses > n / 4, "{stats:?}");
            // Refusals are tried again only where a collapse changed the one-rings: the
            // tail of a bounded decimation, pass after pass over the same refused edges,
            // tries fewer (the parallel walk's refusals are tried again next pass).
            let refused = |s: &DecimateStats| s.refused_geometry + s.refused_topology;
            assert!(refused(&stats) <= refused(&reference));
            if walk == Walk::Sequential && max_error.is_some() {
                assert!(
                    refused(&stats) < refused(&reference),
                    "{stats:?} against {reference:?}"
                );
            }
        }
    }
}
