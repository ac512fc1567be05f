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
//! **What.** After decimation, the surface *as it will be output* (the control mesh
//! subdivided `levels` times, whether the pipeline subdivides or the `.mseq` decoder
//! does) is measured against every non-isolated centre near it. A centre less than
//! [`ContainmentOptions::min_depth`] under it (or outside it) pushes the control
//! triangle under its nearest surface point outwards along the surface normal there, by
//! what is missing (1.4 times that when one Loop step will average the push out over the
//! neighbours). Pushes are combined per control vertex by taking the largest, and halved
//! around any control triangle they would turn by more than about 75°, so they never fold
//! the surface. The surface is then moved by what Loop's (linear) masks make of the pushes
//! and the watched centres (those within r of being too shallow) near the moved part are
//! measured again, for at most [`ContainmentOptions::max_rounds`] rounds; a push of more
//! than r subdivides and measures everything again. Only control vertices move, the
//! topology does not change, so a closed 2-manifold stays one; the output is exactly the
//! subdivision of the moved control mesh (what a `.mseq` decoder makes of it).
//!
//! **Measure.** A centre's nearest surface vertices are looked up in a cell hash of the
//! surface's vertices (cells of `2r`, the 2 × 2 × 2 cells nearest the centre: every
//! vertex within r of it); a centre with none there is deep inside or isolated. A centre
//! deep under the tangent plane of its nearest vertex (normal from the control mesh),
//! deeper than the depth plus `0.15 r` plus `l²/2r` for a vertex `l` aside (what a
//! surface curved to a radius of r or more can lose against its tangent plane), is
//! taken at that depth. Otherwise its nearest point is measured exactly on the surface
//! triangles over the control triangles around the control triangle of its nearest vertex,
//! and its side is that of the angle-weighted pseudo-normal of the nearest feature (face,
//! edge or vertex; Bærentzen and Aanæs 2005).
//!
//! **Order.** Every centre is measured on its own and the pushes are combined per vertex
//! by taking the largest (ties: the lowest particle index), so the result depends neither
//! on the thread count nor on the order in which the particles are visited (tiles, spill
//! cells).
//!
//! **Cost** (frame 25, 42k particles: about 6 % of the pipeline; the 4M scene: see
//! `docs/performance-log.md`): one subdivision more when something moved, and on the
//! first round one look-up per particle, a few hundred nanoseconds for the quarter of
//! them near the surface.

use crate::cancel::CancelToken;
use crate::error::Result;
use crate::mesh::TriMesh;
use crate::subdivision::{subdivide, SubdivideOptions};
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
    /// Seconds of Loop subdivision inside the stage (the surface it measures).
    pub subdivision_seconds: f64,
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
/// under the surface `control` becomes after `levels` Loop subdivision steps; returns
/// that subdivided surface (with its vertex normals) and what was done.
pub fn contain(
    control: &mut TriMesh,
    levels: u32,
    centres: &[Vec3],
    particle_radius: f32,
    options: &ContainmentOptions,
) -> (TriMesh, ContainmentStats) {
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
) -> Result<(TriMesh, ContainmentStats)> {
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
    let clock = Instant::now();
    let mut surface = subdivided(control, levels);
    stats.subdivision_seconds += clock.elapsed().as_secs_f64();
    if control.triangles.is_empty() {
        stats.rounds = 1;
        return Ok((surface, stats));
    }
    // The tangent-plane shortcut reads the control mesh's normals.
    control.compute_normals();
    let control_tris = VertexTriangles::new(control);
    let valence: Vec<u32> = (0..control.positions.len() as u32)
        .map(|v| control_tris.of(v).len() as u32)
        .collect();
    let betas = crate::subdivision::loop_betas(&valence);
    // One triangle of the subdivided surface at each of its vertices (the topology is
    // the same every round).
    let mut corner_tri = vec![0u32; surface.positions.len()];
    for (t, tri) in surface.triangles.iter().enumerate() {
        for &v in tri {
            corner_tri[v as usize] = t as u32;
        }
    }
    let mut cells = CellIndex::new(&surface.positions, 2.0 * r);
    // Centres within r of being too shallow in the last full round.
    let mut watch: Vec<Watched> = Vec::new();
    // Control vertices whose one-ring holds a moved vertex (Loop's masks reach that far).
    let mut reached = vec![false; control.positions.len()];
    let mut full_round = true;
    loop {
        stats.rounds += 1;
        let index = SurfaceIndex {
            cells: &cells,
            surface: &surface,
            control,
            control_tris: &control_tris,
            corner_tri: &corner_tri,
            levels,
            // The tangent-plane shortcut needs normals, which are those of the control
            // mesh only as it was when last subdivided whole; with two or more steps a
            // surface vertex is no longer tied to one control vertex or edge.
            fast_depth: if full_round && levels <= 1 {
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
                        parent: probe.triangle >> (2 * levels),
                    });
                }
                if probe.signed_distance > -depth + TOLERANCE * r {
                    let outside = probe.signed_distance > 0.0;
                    shallow.push(Shallow {
                        particle: i,
                        push: probe.normal * (probe.signed_distance + aim),
                        outside,
                        triangle: probe.triangle,
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
            let parent = control.triangles[(s.triangle >> (2 * levels)) as usize];
            let d = s.push * gain;
            let amount = d.length();
            largest = largest.max(amount);
            for v in parent {
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
        apply_pushes(control, &control_tris, &mut push);
        reached.fill(false);
        for t in &control.triangles {
            if t.iter().any(|&v| moved[v as usize]) {
                for &v in t {
                    reached[v as usize] = true;
                }
            }
        }
        // A push of more than r may reach centres nobody watched: subdivide whole and
        // measure every centre again. Else move the surface by what Loop's masks make of
        // the pushes (one step) and measure the watched centres.
        full_round = largest > r || levels > 1;
        let clock = Instant::now();
        if full_round {
            drop(std::mem::take(&mut surface));
            surface = subdivided(control, levels);
            control.compute_normals();
            cells = CellIndex::new(&surface.positions, 2.0 * r);
        } else if levels == 0 {
            surface.positions.clone_from(&control.positions);
        } else {
            for &(v, d) in &push {
                loop_push(&mut surface, control, &control_tris, &betas, &valence, v, d);
            }
        }
        stats.subdivision_seconds += clock.elapsed().as_secs_f64();
    }
    if !full_round && levels > 0 {
        // The output is exactly the subdivision of the moved control mesh, as a `.mseq`
        // decoder makes it (the measuring structures freed first: this is the stage's
        // peak of memory).
        drop((
            cells,
            corner_tri,
            control_tris,
            valence,
            betas,
            watch,
            reached,
        ));
        let clock = Instant::now();
        drop(std::mem::take(&mut surface));
        surface = subdivided(control, levels);
        stats.subdivision_seconds += clock.elapsed().as_secs_f64();
    }
    control.normals = Vec::new();
    Ok((surface, stats))
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

/// `control` subdivided `levels` times (positions and triangles only).
fn subdivided(control: &TriMesh, levels: u32) -> TriMesh {
    let mut surface = TriMesh {
        positions: control.positions.clone(),
        triangles: control.triangles.clone(),
        ..TriMesh::default()
    };
    subdivide(&mut surface, &SubdivideOptions { levels });
    surface
}

/// Moves the one-step Loop subdivision `surface` of `control` as moving control vertex
/// `v` by `d` moves it (Loop's masks are linear; interior masks, as on a closed mesh):
/// the vertex point by `(1 − nβ) d`, its neighbours' vertex points by `β d`, the edge
/// points of its edges by `3/8 d` and of the edges opposite it by `1/8 d`.
fn loop_push(
    surface: &mut TriMesh,
    control: &TriMesh,
    tris: &VertexTriangles,
    betas: &[f64],
    valence: &[u32],
    v: u32,
    d: DVec3,
) {
    let mut add = |w: u32, x: DVec3| {
        let p = &mut surface.positions[w as usize];
        *p = (p.as_dvec3() + x).as_vec3();
    };
    let beta = |w: u32| betas[valence[w as usize] as usize];
    let n = valence[v as usize] as f64;
    add(v, (1.0 - n * beta(v)) * d);
    for &t in tris.of(v) {
        let tri = control.triangles[t as usize];
        let k = tri.iter().position(|&w| w == v).expect("v is a corner");
        let (a, b) = (tri[(k + 1) % 3], tri[(k + 2) % 3]);
        // Each neighbour and each edge at v lies on two of v's triangles.
        add(a, 0.5 * beta(a) * d);
        add(b, 0.5 * beta(b) * d);
        let m = surface.triangles[4 * t as usize + 3];
        add(m[k], 0.1875 * d);
        add(m[(k + 2) % 3], 0.1875 * d);
        add(m[(k + 1) % 3], 0.125 * d);
    }
}

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
    /// Surface triangle of its nearest point.
    triangle: u32,
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
    /// Surface triangle of the nearest point.
    triangle: u32,
}

/// The nearest feature of a triangle to a point.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Feature {
    Face,
    /// Corners `k` and `k + 1`.
    Edge(usize),
    Vertex(usize),
}

/// Each vertex's triangles (a compressed list).
struct VertexTriangles {
    start: Vec<u32>,
    triangles: Vec<u32>,
}

impl VertexTriangles {
    fn new(mesh: &TriMesh) -> Self {
        let nv = mesh.positions.len();
        let mut start = vec![0u32; nv + 1];
        for t in &mesh.triangles {
            for &v in t {
                start[v as usize + 1] += 1;
            }
        }
        for i in 0..nv {
            start[i + 1] += start[i];
        }
        let mut fill = start.clone();
        let mut triangles = vec![0u32; start[nv] as usize];
        for (t, tri) in mesh.triangles.iter().enumerate() {
            for &v in tri {
                triangles[fill[v as usize] as usize] = t as u32;
                fill[v as usize] += 1;
            }
        }
        VertexTriangles { start, triangles }
    }

    fn of(&self, v: u32) -> &[u32] {
        &self.triangles[self.start[v as usize] as usize..self.start[v as usize + 1] as usize]
    }
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

/// What a centre is measured against: the subdivided surface, found through its
/// vertices; its triangles found through the control mesh they subdivide.
struct SurfaceIndex<'a> {
    cells: &'a CellIndex,
    surface: &'a TriMesh,
    control: &'a TriMesh,
    control_tris: &'a VertexTriangles,
    /// One triangle of the surface at every surface vertex.
    corner_tri: &'a [u32],
    levels: u32,
    /// Depth under the nearest vertex's tangent plane that is deep enough.
    fast_depth: f64,
}

impl SurfaceIndex<'_> {
    fn corners(&self, t: u32) -> [DVec3; 3] {
        self.surface.triangles[t as usize].map(|v| self.surface.positions[v as usize].as_dvec3())
    }

    fn face_normal(&self, t: u32) -> DVec3 {
        let [a, b, c] = self.corners(t);
        (b - a).cross(c - a).normalize_or_zero()
    }

    /// The nearest surface point of `p`, when a surface vertex lies within half a cell
    /// of it; a centre deep under the tangent plane of its nearest vertex, close to
    /// that vertex's normal line, is taken at that depth without measuring triangles.
    fn probe(&self, p: DVec3) -> Option<Probe> {
        let best = self
            .cells
            .nearest::<PROBE_VERTICES>(&self.surface.positions, p);
        let (d2, v0) = best[0];
        if v0 == u32::MAX {
            return None;
        }
        if self.fast_depth == f64::INFINITY {
            return self.measure(p, &best);
        }
        let n0 = self.vertex_normal(v0);
        let along = (p - self.surface.positions[v0 as usize].as_dvec3()).dot(n0);
        let lateral2 = d2 as f64 - along * along;
        let r = self.cells.cell / 2.0;
        // Under a surface curved to a radius of r/2 or more, the tangent plane of a
        // vertex `l` aside overstates the depth by at most l²/r.
        if along + lateral2.max(0.0) / (2.0 * r) < -self.fast_depth {
            return Some(Probe {
                signed_distance: along,
                normal: n0,
                triangle: self.corner_tri[v0 as usize],
            });
        }
        self.measure(p, &best)
    }

    /// The unit normal of the subdivided surface at its vertex `v`, from the control mesh
    /// (one subdivision step or none): a control vertex's own, or the mean of the two
    /// ends of the control edge that `v` splits.
    fn vertex_normal(&self, v: u32) -> DVec3 {
        let normals = &self.control.normals;
        if (v as usize) < self.control.positions.len() {
            return normals[v as usize].as_dvec3();
        }
        let parent = (self.corner_tri[v as usize] >> 2) as usize;
        let tri = self.control.triangles[parent];
        let m = self.surface.triangles[4 * parent + 3];
        let k = m
            .iter()
            .position(|&w| w == v)
            .expect("an edge point of its parent");
        (normals[tri[k] as usize] + normals[tri[(k + 1) % 3] as usize])
            .as_dvec3()
            .normalize_or_zero()
    }

    /// The nearest surface point of `p` among the surface triangles over the control
    /// triangles around the parent of `p`'s nearest vertex (`best`).
    fn measure(&self, p: DVec3, best: &[(f32, u32)]) -> Option<Probe> {
        // The control triangles over which the nearest vertices lie, and their
        // neighbours: the surface triangles they become.
        let mut controls = [u32::MAX; 64];
        let mut count = 0;
        for &(_, v) in best.iter().take(1) {
            let parent = self.corner_tri[v as usize] >> (2 * self.levels);
            for &c in self.control.triangles[parent as usize].iter() {
                for &t in self.control_tris.of(c) {
                    if count < controls.len() && !controls[..count].contains(&t) {
                        controls[count] = t;
                        count += 1;
                    }
                }
            }
        }
        let per = 1u32 << (2 * self.levels);
        let mut nearest = (f64::INFINITY, u32::MAX, DVec3::ZERO, Feature::Face);
        for &c in &controls[..count] {
            let triangles = c * per..(c + 1) * per;
            // Skip a control triangle whose surface lies in a box farther than the best.
            let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
            for t in triangles.clone() {
                for q in self.corners(t) {
                    lo = lo.min(q);
                    hi = hi.max(q);
                }
            }
            let gap = (lo - p).max(p - hi).max(DVec3::ZERO);
            if gap.length_squared() > nearest.0 {
                continue;
            }
            for t in triangles {
                let (q, feature) = closest_on_triangle(p, self.corners(t));
                let d2 = (q - p).length_squared();
                if (d2, t) < (nearest.0, nearest.1) {
                    nearest = (d2, t, q, feature);
                }
            }
        }
        let (d2, t, q, feature) = nearest;
        // The pseudo-normal of the nearest feature, from the measured triangles that
        // share it (every one, when the feature lies inside the measured patch).
        let tri = self.surface.triangles[t as usize];
        let shares = |u: u32, verts: &[u32]| {
            let ut = self.surface.triangles[u as usize];
            verts.iter().all(|v| ut.contains(v))
        };
        let normal = match feature {
            Feature::Face => self.face_normal(t),
            Feature::Edge(k) => {
                let edge = [tri[k], tri[(k + 1) % 3]];
                let mut n = DVec3::ZERO;
                for &c in &controls[..count] {
                    for u in (c * per..(c + 1) * per).filter(|&u| shares(u, &edge)) {
                        n += self.face_normal(u);
                    }
                }
                n
            }
            Feature::Vertex(k) => {
                let v = tri[k];
                let mut n = DVec3::ZERO;
                for &c in &controls[..count] {
                    for u in (c * per..(c + 1) * per).filter(|&u| shares(u, &[v])) {
                        let ut = self.surface.triangles[u as usize];
                        let j = ut.iter().position(|&w| w == v).expect("shares v");
                        let pc = self.corners(u);
                        let angle =
                            (pc[(j + 1) % 3] - pc[j]).angle_between(pc[(j + 2) % 3] - pc[j]);
                        if angle.is_finite() {
                            n += angle * self.face_normal(u);
                        }
                    }
                }
                n
            }
        }
        .normalize_or_zero();
        let normal = if normal == DVec3::ZERO {
            self.face_normal(t)
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
            triangle: t,
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

    /// Measures points against `mesh` taken as its own control mesh (cells of `2r`).
    fn with_index<T>(mesh: &TriMesh, r: f64, f: impl FnOnce(&SurfaceIndex) -> T) -> T {
        let surface = mesh.clone();
        let mut control = mesh.clone();
        control.compute_normals();
        let tris = VertexTriangles::new(mesh);
        let corner_tri: Vec<u32> = {
            let mut c = vec![0; mesh.positions.len()];
            for (t, tri) in mesh.triangles.iter().enumerate() {
                for &v in tri {
                    c[v as usize] = t as u32;
                }
            }
            c
        };
        let cells = CellIndex::new(&surface.positions, 2.0 * r);
        let index = SurfaceIndex {
            cells: &cells,
            surface: &surface,
            control: &control,
            control_tris: &tris,
            corner_tri: &corner_tri,
            levels: 0,
            fast_depth: 0.25 * r + FAST_MARGIN * r,
        };
        f(&index)
    }

    /// Signed distances to a fine sphere match the analytic ones, inside and outside,
    /// on the fast path and the measured one.
    #[test]
    fn probe_signs_and_distances_on_a_sphere() {
        let sphere = icosphere(4, 1.0);
        with_index(&sphere, 0.2, |index| {
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
            let (surface, stats) = contain(&mut control, levels, &centres, 0.3, &options);
            assert_eq!(stats.remaining, 0, "levels {levels}: {stats:?}");
            assert!(stats.outside >= 1 && stats.too_shallow >= 2, "{stats:?}");
            with_index(&surface, 0.3, |index| {
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
