//! Measuring a centre against the one-step Loop surface: a cell hash of the surface's
//! points, the tangent-plane shortcut, the exact nearest point on the children of the
//! control triangles around it, and the side by pseudo-normal (see the module docs of
//! [`super`]).

#[cfg(test)]
use super::surface::Slots;
use super::surface::{LoopSurface, Owner};
use crate::mesh::{TriMesh, VertexTriangles};
use glam::{DVec3, Vec3};
use hashbrown::HashMap;

/// Nearest vertices whose parent triangles' neighbourhoods a measure covers.
const PROBE_VERTICES: usize = 3;

/// Cells per block edge of the cell index.
const BLOCK: i32 = 1 << 3;
const BLOCK_CELLS: usize = (BLOCK * BLOCK * BLOCK) as usize;

/// A centre's nearest surface point.
pub(super) struct Probe {
    /// Distance to the surface, positive outside, world units.
    pub(super) signed_distance: f64,
    /// Outward unit normal there.
    pub(super) normal: DVec3,
    /// Control triangle under it.
    pub(super) control_triangle: u32,
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

/// What a centre is measured against: the one-step Loop surface, found through its
/// points; its triangles through the control mesh they subdivide.
pub(super) struct SurfaceIndex<'a> {
    pub(super) cells: &'a CellIndex,
    pub(super) surface: &'a LoopSurface,
    pub(super) control: &'a TriMesh,
    pub(super) control_tris: &'a VertexTriangles,
    /// Depth under the nearest point's tangent plane that is deep enough.
    pub(super) fast_depth: f64,
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
                .map(|v| self.surface.vertex(v))
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
/// Measures points against `mesh` taken as its own control mesh, unsubdivided (cells
/// of `2r`).
pub(super) fn with_index<T>(
    mesh: &TriMesh,
    r: f64,
    fast: bool,
    f: impl FnOnce(&SurfaceIndex) -> T,
) -> T {
    let mut control = mesh.clone();
    control.compute_normals();
    let tris = VertexTriangles::new(mesh);
    let all = (0..mesh.triangles.len() as u32).collect();
    let surface = LoopSurface::new(mesh, &tris, all, false, Slots::new(mesh));
    let cells = CellIndex::new(&surface.points, 2.0 * r);
    let index = SurfaceIndex {
        cells: &cells,
        surface: &surface,
        control: &control,
        control_tris: &tris,
        fast_depth: if fast {
            0.25 * r + super::FAST_MARGIN * r
        } else {
            f64::INFINITY
        },
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
