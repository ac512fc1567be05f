//! Measuring a centre against the one-step Loop surface: a cell hash of the surface's
//! points, the tangent-plane shortcut, the exact nearest point on the children of the
//! control triangles around it, and the side by pseudo-normal (see the module docs of
//! [`super`]).

use super::surface::{LoopSurface, Owner};
#[cfg(test)]
use super::surface::{Slots, Step};
use crate::mesh::{TriMesh, VertexTriangles};
use glam::{DVec3, Vec3};
use hashbrown::{HashMap, HashSet};
use rayon::prelude::*;

/// Cells per coarse cell edge in [`SurfaceIndex::confirm`], rejecting triangles by their
/// boxes.
const COARSE: f64 = 8.0;

/// Cells per coarse cell edge in [`SurfaceIndex::confirm`], rejecting triangles by their
/// first corners.
const CORNER_COARSE: f64 = 2.0;

/// Nearest vertices whose parent triangles' neighbourhoods a measure covers.
const PROBE_VERTICES: usize = 3;

/// Points whose cells [`CellIndex::new`] finds in parallel at once.
const SPLIT_CHUNK: usize = 1 << 16;

/// Cells per block edge of the cell index.
const BLOCK: i32 = 1 << 3;
const BLOCK_CELLS: usize = (BLOCK * BLOCK * BLOCK) as usize;

/// A centre's nearest surface point.
#[derive(Clone, Copy)]
pub(super) struct Probe {
    /// Distance to the surface, positive outside, world units.
    pub(super) signed_distance: f64,
    /// Outward unit normal there.
    pub(super) normal: DVec3,
    /// Control triangle under it.
    pub(super) control_triangle: u32,
}

/// Which control triangles [`SurfaceIndex::confirm`] reads ([`SurfaceIndex::rejection`]).
enum Rejection {
    /// Those whose first corner is near (per vertex of the part, by its index there).
    Corners { near: Vec<bool> },
    /// Those whose box of one-step points is not inside one coarse cell (of edge
    /// `coarse`) outside `cells`.
    Boxes {
        coarse: f64,
        cells: HashSet<[i32; 3]>,
    },
}

impl Rejection {
    /// The box of control triangle `t`'s one-step points, unless it is rejected.
    fn box_unless_far(&self, index: &SurfaceIndex<'_>, t: u32) -> Option<(DVec3, DVec3)> {
        match self {
            Rejection::Corners { near } => {
                let first = index.control.triangles[t as usize][0];
                near[index.surface.vertex(first) as usize].then(|| index.child_box(t))
            }
            Rejection::Boxes { coarse, cells } => {
                let (lo, hi) = index.child_box(t);
                let (a, b) = (floor(lo / *coarse), floor(hi / *coarse));
                (a != b || cells.contains(&a.to_array())).then_some((lo, hi))
            }
        }
    }
}

/// The nearest feature of a triangle to a point.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum Feature {
    Face,
    /// Corners `k` and `k + 1`.
    Edge(usize),
    Vertex(usize),
}

/// Points hashed by cell: blocks of [`BLOCK`]³ cells, each with the start of every
/// cell's run in `order`.
pub(super) struct CellIndex {
    cell: f64,
    blocks: HashMap<[i32; 3], u32>,
    starts: Vec<[u32; BLOCK_CELLS + 1]>,
    /// Point indices by (block slot, cell in block), in index order within a cell.
    order: Vec<u32>,
}

impl CellIndex {
    pub(super) fn new(positions: &[Vec3], cell: f64) -> Self {
        // Each point's block slot (slots in order of first point: points in mesh order
        // come block by block) and cell in the block. The cells are found in parallel, a
        // chunk of points at a time; the slots then in order.
        let mut blocks: HashMap<[i32; 3], u32> = HashMap::new();
        let mut last: Option<([i32; 3], u32)> = None;
        let mut locals = Vec::with_capacity(positions.len());
        let mut slots: Vec<u32> = Vec::with_capacity(positions.len());
        let mut split = Vec::with_capacity(SPLIT_CHUNK.min(positions.len()));
        for chunk in positions.chunks(SPLIT_CHUNK) {
            split.clear();
            split.par_extend(
                chunk
                    .par_iter()
                    .map(|&p| split_cell(floor(p.as_dvec3() / cell))),
            );
            for &(block, local) in &split {
                locals.push(local);
                slots.push(match last {
                    Some((b, slot)) if b == block => slot,
                    _ => {
                        let next = blocks.len() as u32;
                        let slot = *blocks.entry(block).or_insert(next);
                        last = Some((block, slot));
                        slot
                    }
                });
            }
        }
        drop(split);
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

/// What a centre is measured against: the one-step Loop surface, found through its
/// points; its triangles through the control mesh they subdivide.
pub(super) struct SurfaceIndex<'a> {
    pub(super) cells: &'a CellIndex,
    pub(super) surface: &'a LoopSurface,
    pub(super) control: &'a TriMesh,
    pub(super) control_tris: &'a VertexTriangles,
    /// Depth under the nearest point's tangent plane that is deep enough.
    pub(super) fast_depth: f64,
    /// How far from its first corner any point of a control triangle's surface lies at
    /// most ([`super::surface::Step::spread`]), world units.
    pub(super) spread: f64,
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
        match self.surface.owner(i) {
            Owner::Vertex(v) => self.control_tris.of(v)[0],
            Owner::Edge(t, _) => t,
        }
    }

    /// The unit normal of the surface at point `i`, from the control mesh: a control
    /// vertex's own, or the mean of the two ends of the side an edge point splits.
    fn point_normal(&self, i: u32) -> DVec3 {
        let normals = &self.control.normals;
        match self.surface.owner(i) {
            Owner::Vertex(v) => normals[v as usize].as_dvec3(),
            Owner::Edge(t, k) => {
                let tri = self.control.triangles[t as usize];
                (normals[tri[k] as usize] + normals[tri[(k + 1) % 3] as usize])
                    .as_dvec3()
                    .normalize_or_zero()
            }
        }
    }

    /// The nearest surface point of `p`, when a surface point lies within half a cell of
    /// it; a centre deep under the tangent plane of its nearest point, close to that
    /// point's normal line, is taken at that depth without measuring triangles.
    pub(super) fn probe(&self, p: DVec3) -> Option<Probe> {
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

    /// Measures `probes` (centres and their probes) again over every control triangle
    /// of the part whose one-step surface may pass nearer than the probe found. A probe
    /// reads the triangles around the parent of the nearest surface *point*; where the
    /// surface's triangles are large (regions decimated far) one can pass nearer than
    /// any of its points, on another part of the surface (across a thin sheet, a fold),
    /// and the side found would be the wrong part's: a centre well inside was taken for
    /// 2–4 r outside on violent splashes, and the pushes that followed wrecked the
    /// surface around it. Every control triangle whose box of one-step points lies
    /// within a probe's distance of its centre is read (those all lie in the part: see
    /// [`super::slabs::Slabs::new`]).
    pub(super) fn confirm(&self, probes: &mut [(DVec3, Probe)]) {
        if probes.is_empty() {
            return;
        }
        let cell = self.cells.cell;
        let key = |q: DVec3| floor(q / cell);
        let reach = |probe: &Probe| probe.signed_distance.abs() * (1.0 + 1e-9) + 1e-12;
        // The centres by the cells their distance spheres' boxes meet.
        let mut grid: HashMap<[i32; 3], Vec<u32>> = HashMap::new();
        for (k, (p, probe)) in probes.iter().enumerate() {
            let rad = DVec3::splat(reach(probe));
            for c in cells_between(key(*p - rad), key(*p + rad)) {
                grid.entry(c).or_default().push(k as u32);
            }
        }
        let reject = self.rejection(probes, reach);
        // (centre, control triangle) wherever the triangle's box is within reach.
        let mut pairs: Vec<(u32, u32)> = self
            .surface
            .triangle_ids
            .par_chunks(4096)
            .flat_map_iter(|chunk| {
                let mut out = Vec::new();
                for &t in chunk {
                    let Some((lo, hi)) = reject.box_unless_far(self, t) else {
                        continue;
                    };
                    for c in cells_between(key(lo), key(hi)) {
                        for &k in grid.get(&c).map_or(&[][..], Vec::as_slice) {
                            let (p, probe) = &probes[k as usize];
                            let gap = (lo - *p).max(*p - hi).max(DVec3::ZERO);
                            if gap.length() <= reach(probe) {
                                out.push((k, t));
                            }
                        }
                    }
                }
                out
            })
            .collect();
        pairs.par_sort_unstable();
        pairs.dedup();
        let mut groups: Vec<&[(u32, u32)]> = vec![&[]; probes.len()];
        for group in pairs.chunk_by(|a, b| a.0 == b.0) {
            groups[group[0].0 as usize] = group;
        }
        probes
            .par_iter_mut()
            .zip(groups)
            .for_each(|((p, probe), group)| {
                let controls: Vec<u32> = group.iter().map(|&(_, t)| t).collect();
                if let Some(exact) = self.nearest_among(*p, &controls) {
                    *probe = exact;
                }
            });
    }

    /// How [`Self::confirm`] rejects the control triangles far from every probe (`reach`:
    /// how far from its centre a probe reads). Where the surface's triangles are small
    /// (spread at most a coarse cell of [`CORNER_COARSE`] cells), by their first corner:
    /// a triangle whose box lies within a centre's reach has every point, its first
    /// corner too, within the spread of that corner, so the corner lies within reach +
    /// spread of the centre (per axis); the corners in none of the coarse cells around
    /// the centres so widened reject all their triangles, one look-up per corner (on the
    /// steady surface of dam break frame 25, 3 ms instead of 17). Else (a decimated
    /// surface's long edges would widen them too far) by their boxes' coarse cells.
    fn rejection(&self, probes: &[(DVec3, Probe)], reach: impl Fn(&Probe) -> f64) -> Rejection {
        let cell = self.cells.cell;
        let by_corner = self.spread <= CORNER_COARSE * cell;
        let coarse = if by_corner { CORNER_COARSE } else { COARSE } * cell;
        let coarse_key = |q: DVec3| floor(q / coarse);
        let widen = if by_corner { self.spread } else { 0.0 };
        let mut cells: HashSet<[i32; 3]> = HashSet::new();
        for (p, probe) in probes {
            let far = DVec3::splat(reach(probe) + widen);
            cells.extend(cells_between(coarse_key(*p - far), coarse_key(*p + far)));
        }
        if !by_corner {
            return Rejection::Boxes { coarse, cells };
        }
        let near = self
            .surface
            .vertex_ids
            .par_iter()
            .map(|&v| {
                let x = self.control.positions[v as usize].as_dvec3();
                cells.contains(&coarse_key(x).to_array())
            })
            .collect();
        Rejection::Corners { near }
    }

    /// The box of the one-step points of control triangle `t` (its children's corners).
    fn child_box(&self, t: u32) -> (DVec3, DVec3) {
        let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        for i in self.surface.points_of(self.control, t) {
            let q = self.surface.points[i as usize].as_dvec3();
            lo = lo.min(q);
            hi = hi.max(q);
        }
        (lo, hi)
    }

    /// The control triangles around the corners of control triangle `t`, ascending.
    fn fan(&self, t: u32) -> Vec<u32> {
        let mut around: Vec<u32> = self.control.triangles[t as usize]
            .iter()
            .flat_map(|&c| self.control_tris.of(c).iter().copied())
            .collect();
        around.sort_unstable();
        around.dedup();
        around
    }

    /// The nearest surface point of `p` among the surface triangles over the control
    /// triangles around the corners of control triangle `parent`.
    fn measure(&self, p: DVec3, parent: u32) -> Option<Probe> {
        self.nearest_among(p, &self.fan(parent))
    }

    /// The nearest surface point of `p` among the surface triangles over the control
    /// triangles `controls` (ties: the lowest surface triangle), with the side of the
    /// pseudo-normal of its feature.
    fn nearest_among(&self, p: DVec3, controls: &[u32]) -> Option<Probe> {
        let mut nearest = (f64::INFINITY, u32::MAX, DVec3::ZERO, Feature::Face);
        for &c in controls {
            let children = self.surface.children(c);
            // Skip a control triangle whose surface lies in a box farther than the best.
            let (lo, hi) = self.child_box(c);
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
        // The pseudo-normal of the nearest feature, from every surface triangle that
        // shares it (by position: an edge point has one index per triangle of its edge).
        // Those lie over the control triangles around the corners of the nearest one's
        // parent: a vertex point's triangles over the control triangles around its
        // vertex, an edge point's over the two that share its side.
        let corners = self.corners(s);
        let has = |u: u32, xs: &[DVec3]| {
            let uc = self.corners(u);
            xs.iter().all(|x| uc.contains(x))
        };
        let around = self.fan(s >> 2);
        let measured = || around.iter().flat_map(|&c| self.surface.children(c));
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

/// The cells from `lo` to `hi`, both included, x fastest.
fn cells_between(lo: glam::IVec3, hi: glam::IVec3) -> impl Iterator<Item = [i32; 3]> {
    (lo.z..=hi.z)
        .flat_map(move |z| (lo.y..=hi.y).flat_map(move |y| (lo.x..=hi.x).map(move |x| [x, y, z])))
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
/// Measures points against `mesh` taken as its own control mesh, unsubdivided (cells
/// of `2r`).
pub(super) fn with_index<T>(
    mesh: &TriMesh,
    r: f64,
    fast: bool,
    f: impl FnOnce(&SurfaceIndex) -> T,
) -> T {
    with_index_of(mesh, r, fast, Step::Flat { split: 0.0 }, f)
}

#[cfg(test)]
/// The longest edge of `mesh`.
pub(super) fn longest_edge(mesh: &TriMesh) -> f32 {
    mesh.triangles
        .iter()
        .flat_map(|t| (0..3).map(move |k| (t[k], t[(k + 1) % 3])))
        .map(|(a, b)| mesh.positions[a as usize].distance(mesh.positions[b as usize]))
        .fold(0.0, f32::max)
}

#[cfg(test)]
/// [`with_index`] with the surface made as `step` says.
pub(super) fn with_index_of<T>(
    mesh: &TriMesh,
    r: f64,
    fast: bool,
    step: Step,
    f: impl FnOnce(&SurfaceIndex) -> T,
) -> T {
    let mut control = mesh.clone();
    control.compute_normals();
    let tris = VertexTriangles::new(mesh);
    let all = (0..mesh.triangles.len() as u32).collect();
    let surface = LoopSurface::new(mesh, &tris, all, step, Slots::new(mesh));
    let cells = CellIndex::new(&surface.points, 2.0 * r);
    let index = SurfaceIndex {
        cells: &cells,
        surface: &surface,
        control: &control,
        control_tris: &tris,
        fast_depth: if fast {
            0.25 * r + super::rounds::FAST_MARGIN * r
        } else {
            f64::INFINITY
        },
        spread: step.spread(longest_edge(mesh) as f64),
    };
    f(&index)
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

    /// A centre just under a large face, with no corner of it within reach but a small
    /// sphere just over the face: the probe reads the sphere (the nearest points) and
    /// takes the centre for outside it; confirming finds the face and the right side.
    #[test]
    fn confirming_finds_a_nearer_large_triangle_and_its_side() {
        // Away from the face's corners and edge midpoints (points of the surface).
        let (x, y) = (5.0, -8.0);
        let mut mesh = icosphere(2, 1.0);
        for p in &mut mesh.positions {
            *p += Vec3::new(x, y, 1.5);
        }
        let base = mesh.positions.len() as u32;
        for k in 0..8 {
            let bit = |b: u32, lo: f32, hi: f32| if k >> b & 1 == 1 { hi } else { lo };
            let corner = Vec3::new(bit(0, -20.0, 20.0), bit(1, -20.0, 20.0), bit(2, -40.0, 0.0));
            mesh.positions.push(corner);
        }
        for t in [
            [0, 2, 3],
            [0, 3, 1],
            [4, 5, 7],
            [4, 7, 6],
            [0, 1, 5],
            [0, 5, 4],
            [2, 6, 7],
            [2, 7, 3],
            [0, 4, 6],
            [0, 6, 2],
            [1, 3, 7],
            [1, 7, 5],
        ] {
            mesh.triangles.push(t.map(|v| base + v));
        }
        assert!(crate::mesh::validate(&mesh).is_closed_manifold());
        // r = 1: the box's triangles are long against the cells (rejected by their
        // boxes); r = 25: short (rejected by their first corners, 20 or more away).
        for r in [1.0, 25.0] {
            with_index(&mesh, r, false, |index| {
                let p = DVec3::new(x as f64 + 0.1, y as f64 - 0.2, -0.3);
                let probe = index.probe(p).expect("the sphere is within reach");
                assert!(probe.signed_distance > 0.5, "{}", probe.signed_distance);
                let mut probes = vec![(p, probe)];
                index.confirm(&mut probes);
                let probe = &probes[0].1;
                assert!(
                    (probe.signed_distance + 0.3).abs() < 1e-6,
                    "r {r}: {}",
                    probe.signed_distance
                );
                assert!((probe.normal - DVec3::Z).length() < 1e-9);
            });
        }
    }

    /// The control mesh measured whole where its edges are short (its corners the only
    /// points) gives the centres the same nearest points, sides and distances as the
    /// same mesh cut into four at every edge midpoint: the same surface, a seventh of the
    /// points.
    #[test]
    fn whole_triangles_measure_as_the_cut_ones() {
        let sphere = icosphere(4, 1.0);
        let longest = sphere
            .triangles
            .iter()
            .flat_map(|t| {
                let [a, b, c] = t.map(|v| sphere.positions[v as usize]);
                [a.distance(b), b.distance(c), c.distance(a)]
            })
            .fold(0.0f32, f32::max);
        let probes = |step: Step| {
            with_index_of(&sphere, 0.2, false, step, |index| {
                let mut out = Vec::new();
                for i in 0..400 {
                    let u = (i as f64 * 0.618034).fract() * 2.0 - 1.0;
                    let phi = i as f64 * 2.399963;
                    let s = (1.0 - u * u).sqrt();
                    let dir = DVec3::new(s * phi.cos(), u, s * phi.sin());
                    let p = dir * (0.9 + 0.2 * (i as f64 * 0.37).fract());
                    out.push(index.probe(p).map(|probe| {
                        let mut probes = vec![(p, probe)];
                        index.confirm(&mut probes);
                        (probes[0].1.signed_distance, probes[0].1.control_triangle)
                    }));
                }
                (out, index.surface.points.len())
            })
        };
        let (cut, cut_points) = probes(Step::Flat { split: 0.0 });
        let (whole, whole_points) = probes(Step::Flat { split: longest });
        let (half, _) = probes(Step::Flat {
            split: 0.99 * longest,
        });
        assert!(3 * whole_points < cut_points, "{whole_points} {cut_points}");
        let measured = cut.iter().filter(|p| p.is_some()).count();
        assert!(measured > 300, "{measured} of 400 near the surface");
        for (k, ((a, b), c)) in cut.iter().zip(&whole).zip(&half).enumerate() {
            let (a, b, c) = (a.expect("near"), b.expect("near"), c.expect("near"));
            for x in [b, c] {
                assert!(
                    (a.0 - x.0).abs() < 1e-6,
                    "centre {k}: {} against {}",
                    a.0,
                    x.0
                );
            }
        }
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
}
