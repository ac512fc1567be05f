//! Containment: every non-isolated particle centre at least a given depth under the
//! surface, whatever decimation and Loop subdivision did to it.
//!
//! **Why.** The raw marching-cubes surface of the field (with its particle-coverage
//! balls) leaves no centre outside. Decimation and Loop both move the surface inwards
//! where it is strongly curved: decimation collapses thin sheets, filament tips and
//! coverage balls past their centres, and Loop pulls the coarse convex parts of the
//! decimated mesh further in (a vertex of valence 6 moves 3/8 of the way to the mean of
//! its neighbours). On a violent splash a few centres per hundred thousand end up outside
//! or just under the surface; on calm frames none do.
//!
//! **What.** After decimation and before subdivision, the surface *as one Loop step
//! will make it* (whether the pipeline subdivides or the `.mseq` decoder does) is
//! measured against every non-isolated centre near it. A centre less than
//! [`ContainmentOptions::min_depth`] under it (or outside it) pushes the control triangle
//! under its nearest surface point outwards along the surface normal there, by what is
//! missing (1.4 times that when Loop will average the push out over the neighbours).
//! Pushes are combined per control vertex by taking the largest, and halved around any
//! control triangle they would turn by more than about 75°, so they never fold the
//! surface. The one-step surface is recomputed where the pushes reach and the watched
//! centres (those within r of being too shallow) near them are measured again, for at
//! most [`ContainmentOptions::max_rounds`] rounds; a push of more than r measures every
//! centre again. Only control vertices move: the topology does not change, so a closed
//! 2-manifold stays one, and subdivision then runs on the moved control mesh as always.
//! With two or more steps the surface is measured after the first (the later ones move
//! it far less: the edges halve each step).
//!
//! **Measure.** The one-step surface is never built as a mesh: its points (Loop's vertex
//! point of every control vertex, the edge points of every control triangle's sides) are
//! computed from the control mesh, and its triangles are the four children of each
//! control triangle, so the stage holds about half of what the subdivided mesh would take
//! and stays under the subdivision's peak of memory. A centre's nearest points are looked
//! up in a cell hash of them (cells of `2r`, the 2 × 2 × 2 cells nearest the centre: every
//! point within r of it); a centre with none there is deep inside or isolated. A centre
//! deep under the tangent plane of its nearest point (normal from the control mesh),
//! deeper than the depth plus `0.15 r` plus `l²/2r` for a point `l` aside (what a surface
//! curved to a radius of r or more can lose against its tangent plane), is taken at that
//! depth. Otherwise its nearest point is measured exactly on the children of the control
//! triangles around the control triangle of its nearest point, and its side is that of
//! the angle-weighted pseudo-normal of the nearest feature (face, edge or vertex;
//! Bærentzen and Aanæs 2005).
//!
//! **Order.** Every centre is measured on its own and the pushes are combined per vertex
//! by taking the largest (ties: the lowest particle index), so the result depends neither
//! on the thread count nor on the order in which the particles are visited (tiles, spill
//! cells).
//!
//! **Cost**: on the first round one cell look-up per particle, and about a microsecond
//! for each of the quarter of them near the surface; figures in
//! `docs/performance-log.md`.

use crate::cancel::CancelToken;
use crate::error::Result;
use crate::mesh::{TriMesh, VertexTriangles};
use glam::{DVec3, Vec3};
use hashbrown::{HashMap, HashSet};
use rayon::prelude::*;
use std::time::Instant;

/// Options of [`contain`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ContainmentOptions {
    /// Least depth of a particle centre under the output surface, multiples of the particle
    /// radius r. Default 0.25.
    pub min_depth: f32,
    /// Rounds of measuring and pushing at most. Default 4.
    pub max_rounds: u32,
}

impl Default for ContainmentOptions {
    fn default() -> Self {
        ContainmentOptions {
            min_depth: 0.25,
            max_rounds: 4,
        }
    }
}

/// What [`contain`] did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct ContainmentStats {
    /// Centres with a surface vertex within r or so (see the module docs), measured in
    /// the first round.
    pub near_centres: usize,
    /// Centres less than the depth under the surface in the first round (outside included).
    pub too_shallow: usize,
    /// Of those, centres outside the surface.
    pub outside: usize,
    /// Control vertices moved, summed over the rounds.
    pub moved_vertices: usize,
    /// Rounds of measuring (1 when nothing had to move).
    pub rounds: u32,
    /// Centres still less than the depth under the surface after the last round.
    pub remaining: usize,
    /// Seconds spent computing the one-step surface it measures (points and cells).
    pub surface_seconds: f64,
}

/// What [`Centres::visit`] calls on each chunk: positions and their particle indices.
pub(crate) type VisitChunk<'a> = dyn FnMut(&[Vec3], &[u32]) -> Result<()> + 'a;

/// Where the centres come from: visited in chunks of positions with their particle
/// indices (any order, any chunking).
pub(crate) trait Centres {
    /// Calls `visit` on every chunk of centres.
    fn visit(&self, visit: &mut VisitChunk<'_>) -> Result<()>;
}

impl Centres for [Vec3] {
    fn visit(&self, visit: &mut VisitChunk<'_>) -> Result<()> {
        let indices: Vec<u32> = (0..self.len() as u32).collect();
        visit(self, &indices)
    }
}

impl<S: crate::io::particles::ParticleSource> Centres for crate::tiles::ParticleStore<S> {
    fn visit(&self, visit: &mut VisitChunk<'_>) -> Result<()> {
        self.for_each_stored(&mut |positions, indices, _| visit(positions, indices))
    }
}

/// Moves the vertices of `control` (a closed surface, world units) so that every centre
/// of `centres` that lies near it ends at least `options.min_depth · particle_radius`
/// under the surface `control` becomes after `levels` Loop subdivision steps (measured
/// after one step; see the module docs); returns what was done.
pub fn contain(
    control: &mut TriMesh,
    levels: u32,
    centres: &[Vec3],
    particle_radius: f32,
    options: &ContainmentOptions,
) -> ContainmentStats {
    contain_centres(
        control,
        levels,
        centres,
        &[],
        particle_radius,
        options,
        &CancelToken::new(),
    )
    .expect("centres in memory cannot fail")
}

/// [`contain`] over any [`Centres`], skipping the centres at the positions of
/// `isolated` (the particles that have spheres of their own).
pub(crate) fn contain_centres(
    control: &mut TriMesh,
    levels: u32,
    centres: &(impl Centres + ?Sized),
    isolated: &[Vec3],
    particle_radius: f32,
    options: &ContainmentOptions,
    cancel: &CancelToken,
) -> Result<ContainmentStats> {
    let mut stats = ContainmentStats::default();
    let r = particle_radius as f64;
    let depth = options.min_depth.max(0.0) as f64 * r;
    // Pushes aim a little deeper than required, so that rounding cannot leave a centre
    // a hair short of the depth for another round.
    let aim = depth + AIM_BEYOND * r;
    let isolated: HashSet<[u32; 3]> = isolated.iter().map(|p| bits(*p)).collect();
    // Loop averages a push of a control triangle over its neighbours: the surface over
    // the triangle moves by 3/4 to 7/8 of it for one step; push more so that one round
    // usually suffices.
    let gain = if levels == 0 { 1.0 } else { 1.4 };
    stats.rounds = 1;
    if control.triangles.is_empty() {
        return Ok(stats);
    }
    let clock = Instant::now();
    let tris = VertexTriangles::new(control);
    let mut loop_surface = LoopSurface::new(control, &tris, levels > 0);
    // The tangent-plane shortcut reads the control mesh's normals.
    control.compute_normals();
    let mut cells = CellIndex::new(&loop_surface.points, 2.0 * r);
    stats.surface_seconds += clock.elapsed().as_secs_f64();
    stats.rounds = 0;
    // Centres within r of being too shallow in the last full round.
    let mut watch: Vec<Watched> = Vec::new();
    // Control vertices whose one-ring holds a moved vertex (Loop's masks reach that far).
    let mut reached = vec![false; control.positions.len()];
    let mut full_round = true;
    loop {
        stats.rounds += 1;
        let index = SurfaceIndex {
            cells: &cells,
            surface: &loop_surface,
            control,
            control_tris: &tris,
            // The tangent-plane shortcut needs normals, which are the control mesh's
            // only as it was when last measured whole.
            fast_depth: if full_round {
                depth + FAST_MARGIN * r
            } else {
                f64::INFINITY
            },
        };
        let probe_all = |ps: &[Vec3], is: &[u32]| -> (usize, Vec<Shallow>, Vec<Watched>) {
            let mut near = 0;
            let (mut shallow, mut watch) = (Vec::new(), Vec::new());
            for (&p, &i) in ps.iter().zip(is) {
                let Some(probe) = index.probe(p.as_dvec3()) else {
                    continue;
                };
                if !isolated.is_empty() && isolated.contains(&bits(p)) {
                    continue;
                }
                near += 1;
                if probe.signed_distance > -(depth + r) {
                    watch.push(Watched {
                        particle: i,
                        position: p,
                        parent: probe.control_triangle,
                    });
                }
                if probe.signed_distance > -depth + TOLERANCE * r {
                    shallow.push(Shallow {
                        particle: i,
                        push: probe.normal * (probe.signed_distance + aim),
                        outside: probe.signed_distance > 0.0,
                        control_triangle: probe.control_triangle,
                    });
                }
            }
            (near, shallow, watch)
        };
        let mut near = 0usize;
        let mut shallow: Vec<Shallow> = Vec::new();
        let mut gather = |ps: &[Vec3], is: &[u32], watched: &mut Vec<Watched>| {
            let found: Vec<_> = ps
                .par_chunks(PROBE_CHUNK)
                .zip(is.par_chunks(PROBE_CHUNK))
                .map(|(ps, is)| probe_all(ps, is))
                .collect();
            for (n, s, w) in found {
                near += n;
                shallow.extend(s);
                watched.extend(w);
            }
        };
        if full_round {
            // Every centre; those that a push could bring too close are watched after.
            watch.clear();
            centres.visit(&mut |positions, indices| {
                cancel.check()?;
                gather(positions, indices, &mut watch);
                Ok(())
            })?;
        } else {
            // Pushes of less than r: only the watched centres whose nearest surface lay
            // over a control triangle the pushes reached can be too close now.
            cancel.check()?;
            let (is, ps): (Vec<u32>, Vec<Vec3>) = watch
                .iter()
                .filter(|w| {
                    control.triangles[w.parent as usize]
                        .iter()
                        .any(|&v| reached[v as usize])
                })
                .map(|w| (w.particle, w.position))
                .unzip();
            gather(&ps, &is, &mut Vec::new());
        }
        if stats.rounds == 1 {
            stats.near_centres = near;
            stats.too_shallow = shallow.len();
            stats.outside = shallow.iter().filter(|s| s.outside).count();
        }
        if shallow.is_empty() || stats.rounds > options.max_rounds {
            stats.remaining = shallow.len();
            break;
        }
        // The largest push per control vertex (ties: the lowest particle index).
        shallow.sort_unstable_by_key(|s| s.particle);
        let mut push: HashMap<u32, (f64, u32, DVec3)> = HashMap::new();
        let mut largest = 0.0f64;
        for s in &shallow {
            let d = s.push * gain;
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
        stats.moved_vertices += push.len();
        let mut moved = vec![false; control.positions.len()];
        for &(v, _) in &push {
            moved[v as usize] = true;
        }
        apply_pushes(control, &tris, &mut push);
        reached.fill(false);
        for t in &control.triangles {
            if t.iter().any(|&v| moved[v as usize]) {
                for &v in t {
                    reached[v as usize] = true;
                }
            }
        }
        // The one-step surface where the pushes reach; a push of more than r may reach
        // centres nobody watched: measure every centre again.
        full_round = largest > r;
        let clock = Instant::now();
        loop_surface.update(control, &tris, &reached);
        if full_round {
            control.compute_normals();
            cells = CellIndex::new(&loop_surface.points, 2.0 * r);
        }
        stats.surface_seconds += clock.elapsed().as_secs_f64();
    }
    control.normals = Vec::new();
    Ok(stats)
}

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
const FAST_MARGIN: f64 = 0.15;

/// How much deeper than required a push aims, multiples of r.
const AIM_BEYOND: f64 = 0.02;
/// How much shallower than required a centre may be before it is pushed, multiples of r
/// (float rounding of the pushed positions).
const TOLERANCE: f64 = 1e-3;

/// Nearest vertices whose parent triangles' neighbourhoods a measure covers.
const PROBE_VERTICES: usize = 3;

/// Centres per parallel task.
const PROBE_CHUNK: usize = 4096;

/// Cells per block edge of the cell index.
const BLOCK: i32 = 1 << 3;
const BLOCK_CELLS: usize = (BLOCK * BLOCK * BLOCK) as usize;

/// The exact bits of a position (isolated centres are matched by position).
fn bits(p: Vec3) -> [u32; 3] {
    p.to_array().map(f32::to_bits)
}

/// A centre found too close to the surface.
struct Shallow {
    particle: u32,
    /// How its nearest surface point has to move, world units.
    push: DVec3,
    outside: bool,
    /// Control triangle under its nearest surface point.
    control_triangle: u32,
}

/// A centre that a push could bring too close to the surface.
#[derive(Clone, Copy)]
struct Watched {
    particle: u32,
    position: Vec3,
    /// Control triangle over which its nearest surface point lay.
    parent: u32,
}

/// A centre's nearest surface point.
struct Probe {
    /// Distance to the surface, positive outside, world units.
    signed_distance: f64,
    /// Outward unit normal there.
    normal: DVec3,
    /// Control triangle under it.
    control_triangle: u32,
}

/// The nearest feature of a triangle to a point.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Feature {
    Face,
    /// Corners `k` and `k + 1`.
    Edge(usize),
    Vertex(usize),
}

/// Points hashed by cell: blocks of [`BLOCK`]³ cells, each with the start of every
/// cell's run in `order`.
struct CellIndex {
    cell: f64,
    blocks: HashMap<[i32; 3], u32>,
    starts: Vec<[u32; BLOCK_CELLS + 1]>,
    /// Point indices by (block slot, cell in block), in index order within a cell.
    order: Vec<u32>,
}

impl CellIndex {
    fn new(positions: &[Vec3], cell: f64) -> Self {
        // Each point's block slot (slots in order of first point: points in mesh order
        // come block by block) and cell in the block.
        let mut blocks: HashMap<[i32; 3], u32> = HashMap::new();
        let mut last: Option<([i32; 3], u32)> = None;
        let mut locals = Vec::with_capacity(positions.len());
        let slots: Vec<u32> = positions
            .iter()
            .map(|&p| {
                let (block, local) = split_cell(floor(p.as_dvec3() / cell));
                locals.push(local);
                match last {
                    Some((b, slot)) if b == block => slot,
                    _ => {
                        let next = blocks.len() as u32;
                        let slot = *blocks.entry(block).or_insert(next);
                        last = Some((block, slot));
                        slot
                    }
                }
            })
            .collect();
        // Counting sort by (slot, cell).
        let mut starts = vec![[0u32; BLOCK_CELLS + 1]; blocks.len()];
        for (&slot, &local) in slots.iter().zip(&locals) {
            starts[slot as usize][local as usize + 1] += 1;
        }
        let mut first = 0;
        for s in &mut starts {
            s[0] = first;
            for k in 0..BLOCK_CELLS {
                s[k + 1] += s[k];
            }
            first = s[BLOCK_CELLS];
        }
        let mut fill = starts.clone();
        let mut order = vec![0u32; positions.len()];
        for (v, (&slot, &local)) in slots.iter().zip(&locals).enumerate() {
            let f = &mut fill[slot as usize][local as usize];
            order[*f as usize] = v as u32;
            *f += 1;
        }
        CellIndex {
            cell,
            blocks,
            starts,
            order,
        }
    }

    /// The `K` nearest points (distance², index; by distance, then index) in the
    /// 2 × 2 × 2 cells nearest `p`, which hold every point within half a cell of `p`.
    fn nearest<const K: usize>(&self, positions: &[Vec3], p: DVec3) -> [(f32, u32); K] {
        let f = p / self.cell;
        let c = floor(f);
        let o = (f - c.as_dvec3())
            .to_array()
            .map(|x| if x < 0.5 { -1 } else { 0 });
        let pf = p.as_vec3();
        let mut best = [(f32::INFINITY, u32::MAX); K];
        let mut last: Option<([i32; 3], Option<u32>)> = None;
        for dz in o[2]..=o[2] + 1 {
            for dy in o[1]..=o[1] + 1 {
                for dx in o[0]..=o[0] + 1 {
                    let (block, local) = split_cell(c + glam::IVec3::new(dx, dy, dz));
                    let slot = match last {
                        Some((b, slot)) if b == block => slot,
                        _ => {
                            let slot = self.blocks.get(&block).copied();
                            last = Some((block, slot));
                            slot
                        }
                    };
                    let Some(slot) = slot else {
                        continue;
                    };
                    let starts = &self.starts[slot as usize];
                    let (s, e) = (starts[local as usize], starts[local as usize + 1]);
                    for &v in &self.order[s as usize..e as usize] {
                        let cand = ((positions[v as usize] - pf).length_squared(), v);
                        if cand < best[K - 1] {
                            let mut k = K - 1;
                            best[k] = cand;
                            while k > 0 && best[k] < best[k - 1] {
                                best.swap(k, k - 1);
                                k -= 1;
                            }
                        }
                    }
                }
            }
        }
        best
    }
}

/// The surface one Loop step makes of a control mesh, without its triangles: every
/// control vertex's vertex point and every control triangle's three edge points (an edge
/// point is computed for both triangles of its edge, the same way, so the two copies are
/// equal bit for bit). Surface triangle `s` is child `s % 4` of control triangle `s / 4`.
struct LoopSurface {
    /// Vertex points (one per control vertex), then edge points (three per control
    /// triangle, side `k` from corner `k` to `k + 1`).
    points: Vec<Vec3>,
    vertex_count: usize,
    /// With Loop's masks, or the control mesh itself (vertex points in place, edge points
    /// at the midpoints) when the surface is not subdivided.
    smooth: bool,
}

impl LoopSurface {
    fn new(control: &TriMesh, tris: &VertexTriangles, smooth: bool) -> Self {
        let nv = control.positions.len();
        let mut surface = LoopSurface {
            points: vec![Vec3::ZERO; nv + 3 * control.triangles.len()],
            vertex_count: nv,
            smooth,
        };
        surface.update(control, tris, &vec![true; nv]);
        surface
    }

    /// Recomputes the points that depend on the vertices marked in `changed` or on their
    /// neighbours (every vertex point of a marked vertex, every edge point of a triangle
    /// with a marked corner: the marks must cover the one-rings of the moved vertices).
    fn update(&mut self, control: &TriMesh, tris: &VertexTriangles, changed: &[bool]) {
        let nv = self.vertex_count;
        let (vertex_points, edge_points) = self.points.split_at_mut(nv);
        let smooth = self.smooth;
        let betas = crate::subdivision::loop_betas(&[64]);
        vertex_points
            .par_iter_mut()
            .enumerate()
            .filter(|(v, _)| changed[*v])
            .for_each(|(v, out)| {
                *out = vertex_point(control, tris, v as u32, smooth, &betas);
            });
        edge_points
            .par_chunks_mut(3)
            .enumerate()
            .filter(|(t, _)| control.triangles[*t].iter().any(|&v| changed[v as usize]))
            .for_each(|(t, out)| {
                for (k, e) in out.iter_mut().enumerate() {
                    *e = edge_point(control, tris, t as u32, k, smooth);
                }
            });
    }

    /// Point index of control triangle `t`'s edge point on side `k`.
    fn edge(&self, t: u32, k: usize) -> u32 {
        (self.vertex_count + 3 * t as usize + k) as u32
    }

    /// Corner point indices of surface triangle `s`.
    fn triangle(&self, control: &TriMesh, s: u32) -> [u32; 3] {
        let t = s >> 2;
        let tri = control.triangles[t as usize];
        let m = [0, 1, 2].map(|k| self.edge(t, k));
        crate::subdivision::children(tri, m)[(s & 3) as usize]
    }
}

/// Loop's vertex point of control vertex `v` (interior mask; the vertex itself when not
/// `smooth`, or when its fan is not a closed ring).
fn vertex_point(
    control: &TriMesh,
    tris: &VertexTriangles,
    v: u32,
    smooth: bool,
    betas: &[f64],
) -> Vec3 {
    let x = control.positions[v as usize];
    let fan = tris.of(v);
    if !smooth || fan.len() < 3 {
        return x;
    }
    // In a closed fan every neighbour follows v in exactly one triangle.
    let mut sum = DVec3::ZERO;
    for &t in fan {
        let tri = control.triangles[t as usize];
        let k = tri.iter().position(|&w| w == v).expect("v is a corner");
        sum += control.positions[tri[(k + 1) % 3] as usize].as_dvec3();
    }
    let n = fan.len();
    let beta = if n < betas.len() {
        betas[n]
    } else {
        crate::subdivision::loop_betas(&[n as u32])[n]
    };
    ((1.0 - n as f64 * beta) * x.as_dvec3() + beta * sum).as_vec3()
}

/// Loop's edge point on side `k` of control triangle `t`: `3/8 (a + b) + 1/8 (c + d)`
/// with `d` the far corner of the triangle across the side (the midpoint when not
/// `smooth` or when the side has not exactly one triangle across). Summed in vertex-index
/// order, so both triangles of the edge compute the same bits.
fn edge_point(control: &TriMesh, tris: &VertexTriangles, t: u32, k: usize, smooth: bool) -> Vec3 {
    let tri = control.triangles[t as usize];
    let (a, b, c) = (tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]);
    let x = |v: u32| control.positions[v as usize].as_dvec3();
    let pair = |u: u32, w: u32| if u < w { x(u) + x(w) } else { x(w) + x(u) };
    let mut across = tris
        .of(a)
        .iter()
        .filter(|&&u| u != t && control.triangles[u as usize].contains(&b));
    let d = match (smooth, across.next(), across.next()) {
        (true, Some(&u), None) => control.triangles[u as usize]
            .into_iter()
            .find(|&w| w != a && w != b),
        _ => None,
    };
    match d {
        Some(d) => (0.375 * pair(a, b) + 0.125 * pair(c, d)).as_vec3(),
        None => (0.5 * pair(a, b)).as_vec3(),
    }
}

/// What a centre is measured against: the one-step Loop surface, found through its
/// points; its triangles through the control mesh they subdivide.
struct SurfaceIndex<'a> {
    cells: &'a CellIndex,
    surface: &'a LoopSurface,
    control: &'a TriMesh,
    control_tris: &'a VertexTriangles,
    /// Depth under the nearest point's tangent plane that is deep enough.
    fast_depth: f64,
}

impl SurfaceIndex<'_> {
    fn corners(&self, s: u32) -> [DVec3; 3] {
        self.surface
            .triangle(self.control, s)
            .map(|i| self.surface.points[i as usize].as_dvec3())
    }

    fn face_normal(&self, s: u32) -> DVec3 {
        let [a, b, c] = self.corners(s);
        (b - a).cross(c - a).normalize_or_zero()
    }

    /// A control triangle at surface point `i`.
    fn parent(&self, i: u32) -> u32 {
        let nv = self.surface.vertex_count as u32;
        if i < nv {
            self.control_tris.of(i)[0]
        } else {
            (i - nv) / 3
        }
    }

    /// The unit normal of the surface at point `i`, from the control mesh: a control
    /// vertex's own, or the mean of the two ends of the side an edge point splits.
    fn point_normal(&self, i: u32) -> DVec3 {
        let normals = &self.control.normals;
        let nv = self.surface.vertex_count as u32;
        if i < nv {
            return normals[i as usize].as_dvec3();
        }
        let (t, k) = ((i - nv) / 3, ((i - nv) % 3) as usize);
        let tri = self.control.triangles[t as usize];
        (normals[tri[k] as usize] + normals[tri[(k + 1) % 3] as usize])
            .as_dvec3()
            .normalize_or_zero()
    }

    /// The nearest surface point of `p`, when a surface point lies within half a cell of
    /// it; a centre deep under the tangent plane of its nearest point, close to that
    /// point's normal line, is taken at that depth without measuring triangles.
    fn probe(&self, p: DVec3) -> Option<Probe> {
        let best = self
            .cells
            .nearest::<PROBE_VERTICES>(&self.surface.points, p);
        let (d2, i0) = best[0];
        if i0 == u32::MAX {
            return None;
        }
        if self.fast_depth < f64::INFINITY {
            let n0 = self.point_normal(i0);
            let along = (p - self.surface.points[i0 as usize].as_dvec3()).dot(n0);
            let lateral2 = d2 as f64 - along * along;
            let r = self.cells.cell / 2.0;
            // Under a surface curved to a radius of r or more, the tangent plane of a
            // point `l` aside overstates the depth by at most l²/2r.
            if along + lateral2.max(0.0) / (2.0 * r) < -self.fast_depth {
                return Some(Probe {
                    signed_distance: along,
                    normal: n0,
                    control_triangle: self.parent(i0),
                });
            }
        }
        self.measure(p, self.parent(i0))
    }

    /// The nearest surface point of `p` among the surface triangles over the control
    /// triangles around the corners of control triangle `parent`.
    fn measure(&self, p: DVec3, parent: u32) -> Option<Probe> {
        let mut controls = [u32::MAX; 64];
        let mut count = 0;
        for &c in self.control.triangles[parent as usize].iter() {
            for &t in self.control_tris.of(c) {
                if count < controls.len() && !controls[..count].contains(&t) {
                    controls[count] = t;
                    count += 1;
                }
            }
        }
        let mut nearest = (f64::INFINITY, u32::MAX, DVec3::ZERO, Feature::Face);
        for &c in &controls[..count] {
            let children = 4 * c..4 * c + 4;
            // Skip a control triangle whose surface lies in a box farther than the best.
            let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
            for i in self.control.triangles[c as usize]
                .into_iter()
                .chain([0, 1, 2].map(|k| self.surface.edge(c, k)))
            {
                let q = self.surface.points[i as usize].as_dvec3();
                lo = lo.min(q);
                hi = hi.max(q);
            }
            let gap = (lo - p).max(p - hi).max(DVec3::ZERO);
            if gap.length_squared() > nearest.0 {
                continue;
            }
            for s in children {
                let (q, feature) = closest_on_triangle(p, self.corners(s));
                let d2 = (q - p).length_squared();
                if (d2, s) < (nearest.0, nearest.1) {
                    nearest = (d2, s, q, feature);
                }
            }
        }
        let (d2, s, q, feature) = nearest;
        if s == u32::MAX {
            return None;
        }
        // The pseudo-normal of the nearest feature, from the measured triangles that
        // share it (by position: an edge point has one index per triangle of its edge).
        let corners = self.corners(s);
        let has = |u: u32, xs: &[DVec3]| {
            let uc = self.corners(u);
            xs.iter().all(|x| uc.contains(x))
        };
        let measured = || controls[..count].iter().flat_map(|&c| 4 * c..4 * c + 4);
        let normal = match feature {
            Feature::Face => self.face_normal(s),
            Feature::Edge(k) => {
                let edge = [corners[k], corners[(k + 1) % 3]];
                measured()
                    .filter(|&u| has(u, &edge))
                    .map(|u| self.face_normal(u))
                    .sum::<DVec3>()
            }
            Feature::Vertex(k) => {
                let x = corners[k];
                let mut n = DVec3::ZERO;
                for u in measured().filter(|&u| has(u, &[x])) {
                    let uc = self.corners(u);
                    let j = uc.iter().position(|&w| w == x).expect("shares x");
                    let angle = (uc[(j + 1) % 3] - x).angle_between(uc[(j + 2) % 3] - x);
                    if angle.is_finite() {
                        n += angle * self.face_normal(u);
                    }
                }
                n
            }
        }
        .normalize_or_zero();
        let normal = if normal == DVec3::ZERO {
            self.face_normal(s)
        } else {
            normal
        };
        let distance = d2.sqrt();
        Some(Probe {
            signed_distance: if (p - q).dot(normal) > 0.0 {
                distance
            } else {
                -distance
            },
            normal,
            control_triangle: s >> 2,
        })
    }
}

/// `v.floor()` as integers, without a libm call per component (cells lie well inside
/// the `i32` range).
fn floor(v: DVec3) -> glam::IVec3 {
    let t = v.as_ivec3(); // towards zero
    t - glam::IVec3::from(v.cmplt(t.as_dvec3())).abs()
}

/// A cell's block and its index inside the block (blocks of 8³ cells: shifts and masks,
/// which floor negative coordinates too).
fn split_cell(c: glam::IVec3) -> ([i32; 3], u16) {
    let l = c & glam::IVec3::splat(BLOCK - 1);
    (
        [c.x >> 3, c.y >> 3, c.z >> 3],
        (l.x + BLOCK * (l.y + BLOCK * l.z)) as u16,
    )
}

/// The point of triangle `[a, b, c]` nearest to `p`, and the feature it lies on (Ericson,
/// *Real-Time Collision Detection*, § 5.1.5).
fn closest_on_triangle(p: DVec3, [a, b, c]: [DVec3; 3]) -> (DVec3, Feature) {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, Feature::Vertex(0));
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return (b, Feature::Vertex(1));
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (a + v * ab, Feature::Edge(0));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return (c, Feature::Vertex(2));
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + w * ac, Feature::Edge(2));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + w * (c - b), Feature::Edge(1));
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    if !(v.is_finite() && w.is_finite()) {
        // Degenerate triangle: its first corner.
        return (a, Feature::Vertex(0));
    }
    (a + ab * v + ac * w, Feature::Face)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::isolated::icosphere;

    #[test]
    fn closest_point_features() {
        let t = [DVec3::ZERO, DVec3::X, DVec3::Y];
        let (q, f) = closest_on_triangle(DVec3::new(0.2, 0.2, 1.0), t);
        assert!(f == Feature::Face && (q - DVec3::new(0.2, 0.2, 0.0)).length() < 1e-12);
        let (q, f) = closest_on_triangle(DVec3::new(0.5, -1.0, 0.3), t);
        assert!(f == Feature::Edge(0) && (q - DVec3::new(0.5, 0.0, 0.0)).length() < 1e-12);
        let (q, f) = closest_on_triangle(DVec3::new(1.0, 1.0, 0.0), t);
        assert!(f == Feature::Edge(1) && (q - DVec3::new(0.5, 0.5, 0.0)).length() < 1e-12);
        let (_, f) = closest_on_triangle(DVec3::new(-1.0, 0.5, 0.0), t);
        assert!(f == Feature::Edge(2));
        let (q, f) = closest_on_triangle(DVec3::new(-1.0, -1.0, 2.0), t);
        assert!(f == Feature::Vertex(0) && q == DVec3::ZERO);
        let (_, f) = closest_on_triangle(DVec3::new(3.0, -0.5, 0.0), t);
        assert!(f == Feature::Vertex(1));
        let (_, f) = closest_on_triangle(DVec3::new(-0.5, 3.0, 0.0), t);
        assert!(f == Feature::Vertex(2));
    }

    /// Measures points against `mesh` taken as its own control mesh, unsubdivided (cells
    /// of `2r`).
    fn with_index<T>(mesh: &TriMesh, r: f64, fast: bool, f: impl FnOnce(&SurfaceIndex) -> T) -> T {
        let mut control = mesh.clone();
        control.compute_normals();
        let tris = VertexTriangles::new(mesh);
        let surface = LoopSurface::new(mesh, &tris, false);
        let cells = CellIndex::new(&surface.points, 2.0 * r);
        let index = SurfaceIndex {
            cells: &cells,
            surface: &surface,
            control: &control,
            control_tris: &tris,
            fast_depth: if fast {
                0.25 * r + FAST_MARGIN * r
            } else {
                f64::INFINITY
            },
        };
        f(&index)
    }

    /// The one-step surface measured is Loop's subdivision: every triangle's corners as
    /// `subdivide` makes them (to f32 rounding), after moving a few vertices too.
    #[test]
    fn loop_surface_is_the_subdivision() {
        let mut control = icosphere(2, 1.0);
        for (i, p) in control.positions.iter_mut().enumerate() {
            *p *= 1.0 + 0.1 * ((i * 7 % 5) as f32 / 5.0);
        }
        let tris = VertexTriangles::new(&control);
        let mut surface = LoopSurface::new(&control, &tris, true);
        let check = |control: &TriMesh, surface: &LoopSurface| {
            let mut expected = control.clone();
            crate::subdivision::subdivide(
                &mut expected,
                &crate::subdivision::SubdivideOptions { levels: 1 },
            );
            for s in 0..expected.triangles.len() as u32 {
                let want = expected.triangles[s as usize].map(|v| expected.positions[v as usize]);
                let got = surface
                    .triangle(control, s)
                    .map(|i| surface.points[i as usize]);
                for (w, g) in want.iter().zip(&got) {
                    assert!((*w - *g).length() < 1e-6, "triangle {s}: {w} against {g}");
                }
            }
        };
        check(&control, &surface);
        let mut changed = vec![false; control.positions.len()];
        control.positions[3] += Vec3::splat(0.05);
        for t in &control.triangles {
            if t.contains(&3) {
                for &v in t {
                    changed[v as usize] = true;
                }
            }
        }
        surface.update(&control, &tris, &changed);
        check(&control, &surface);
    }

    /// Signed distances to a fine sphere match the analytic ones, inside and outside,
    /// on the fast path and the measured one.
    #[test]
    fn probe_signs_and_distances_on_a_sphere() {
        let sphere = icosphere(4, 1.0);
        with_index(&sphere, 0.2, true, |index| {
            for (k, &radius) in [0.9, 0.95, 0.98, 1.02, 1.05, 1.1].iter().enumerate() {
                for i in 0..50 {
                    let u = (i as f64 * 0.618034 + k as f64 * 0.1).fract() * 2.0 - 1.0;
                    let phi = i as f64 * 2.399963;
                    let s = (1.0 - u * u).sqrt();
                    let dir = DVec3::new(s * phi.cos(), u, s * phi.sin());
                    let probe = index.probe(dir * radius).expect("near the surface");
                    // The icosphere's faces lie within 0.002 of the unit sphere at level 4.
                    assert!(
                        (probe.signed_distance - (radius - 1.0)).abs() < 0.004,
                        "{radius}: {}",
                        probe.signed_distance
                    );
                    assert!(probe.normal.dot(dir) > 0.95);
                }
            }
            assert!(index.probe(DVec3::ZERO).is_none(), "far from every vertex");
        });
    }

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
}
