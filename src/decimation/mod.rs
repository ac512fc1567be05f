//! Quadric-error-metric decimation (M. Garland and P. Heckbert, "Surface Simplification
//! Using Quadric Error Metrics", SIGGRAPH 1997), as Akinci et al. 2013 § 3.2 use it to
//! remove the bumps that irregular particle placement leaves in flat regions.
//!
//! **Input:** a triangle mesh. **Output:** the same surface with fewer triangles, unused
//! vertices removed, normals cleared.
//!
//! Steps: rescale to the unit box (conditioning) → per-vertex area-weighted plane quadrics
//! → one candidate collapse per edge with its cost → a min-heap of collapses (lazy
//! invalidation by vertex version stamps, ties broken by vertex indices) → collapse until
//! the triangle target or the error bound is reached → compact.
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
//! * turn any surviving triangle by more than 78° (normal dot < 0.2), from its current
//!   normal or from its normal in the input (so small turns cannot add up to a flip), or
//!   make it degenerate (quality `4√3·A / Σl²` below 0.02).
//!
//! A closed 2-manifold therefore stays one. Single-threaded heap, so the output is
//! deterministic and does not depend on the thread count.

mod quadric;

use crate::mesh::TriMesh;
use glam::DVec3;
use quadric::Quadric;
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// Options of [`decimate`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DecimateOptions {
    /// Fraction of the triangles to remove, in `[0, 1)`, or `None` to stop on the error
    /// bound only. Default `Some(0.8)` (the paper's).
    pub target_reduction: Option<f32>,
    /// Largest error of a collapse, world units: the root of the quadric cost divided by
    /// the quadric's area weight (an RMS distance to the original planes). `None`: no
    /// bound. Default `None`.
    pub max_error: Option<f32>,
}

impl Default for DecimateOptions {
    fn default() -> Self {
        DecimateOptions {
            target_reduction: Some(0.8),
            max_error: None,
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
    /// Collapses refused at a boundary or non-manifold vertex.
    pub refused_boundary: usize,
    /// Collapses refused by the link condition or valence rule.
    pub refused_topology: usize,
    /// Collapses refused because a triangle would flip or degenerate.
    pub refused_geometry: usize,
    /// Largest error of a performed collapse, world units.
    pub max_error: f32,
}

#[derive(Clone, Copy)]
struct Candidate {
    cost: f64,
    u: u32,
    v: u32,
    stamp_u: u32,
    stamp_v: u32,
    target: DVec3,
}

impl PartialEq for Candidate {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o) == Ordering::Equal
    }
}
impl Eq for Candidate {}
impl PartialOrd for Candidate {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Candidate {
    /// Reversed, so that `BinaryHeap` pops the cheapest collapse first.
    fn cmp(&self, o: &Self) -> Ordering {
        o.cost
            .total_cmp(&self.cost)
            .then_with(|| (o.u, o.v).cmp(&(self.u, self.v)))
    }
}

struct State {
    pos: Vec<DVec3>,
    quadric: Vec<Quadric>,
    tris: Vec<[u32; 3]>,
    /// Unit normal of every triangle in the input (zero for a degenerate one): a
    /// triangle may never turn far from it, however many collapses touch it.
    reference_normal: Vec<DVec3>,
    tri_alive: Vec<bool>,
    vert_tris: Vec<Vec<u32>>,
    locked: Vec<bool>,
    stamp: Vec<u32>,
    alive: Vec<bool>,
}

const MIN_NORMAL_DOT: f64 = 0.2;
const MIN_QUALITY: f64 = 0.02;

/// Decimates `mesh` in place.
pub fn decimate(mesh: &mut TriMesh, options: &DecimateOptions) -> DecimateStats {
    let before = mesh.triangle_count();
    let mut stats = DecimateStats {
        triangles_before: before,
        triangles_after: before,
        ..Default::default()
    };
    if before == 0 {
        return stats;
    }
    let (lo, hi) = mesh
        .positions
        .iter()
        .fold((DVec3::MAX, DVec3::MIN), |(l, h), p| {
            (l.min(p.as_dvec3()), h.max(p.as_dvec3()))
        });
    let centre = (lo + hi) * 0.5;
    let scale = ((hi - lo).max_element() * 0.5).max(f64::MIN_POSITIVE);
    let nv = mesh.positions.len();
    let mut s = State {
        pos: mesh
            .positions
            .iter()
            .map(|p| (p.as_dvec3() - centre) / scale)
            .collect(),
        quadric: vec![Quadric::default(); nv],
        tris: mesh.triangles.clone(),
        reference_normal: Vec::new(),
        tri_alive: vec![true; before],
        vert_tris: vec![Vec::new(); nv],
        locked: vec![false; nv],
        stamp: vec![0; nv],
        alive: vec![true; nv],
    };
    s.reference_normal = s
        .tris
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| s.pos[v as usize]);
            (b - a).cross(c - a).normalize_or_zero()
        })
        .collect();
    for (t, tri) in s.tris.iter().enumerate() {
        let q = Quadric::from_triangle(
            s.pos[tri[0] as usize],
            s.pos[tri[1] as usize],
            s.pos[tri[2] as usize],
        );
        for &v in tri {
            s.quadric[v as usize] += q;
            s.vert_tris[v as usize].push(t as u32);
        }
    }
    // Edges with one or more than two triangles lock their endpoints.
    let mut edges: Vec<(u32, u32)> = s
        .tris
        .iter()
        .flat_map(|t| (0..3).map(move |k| (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]))))
        .collect();
    edges.sort_unstable();
    let mut i = 0;
    let mut unique = Vec::with_capacity(edges.len() / 2);
    while i < edges.len() {
        let mut j = i + 1;
        while j < edges.len() && edges[j] == edges[i] {
            j += 1;
        }
        if j - i != 2 {
            s.locked[edges[i].0 as usize] = true;
            s.locked[edges[i].1 as usize] = true;
        }
        unique.push(edges[i]);
        i = j;
    }
    drop(edges);

    let target = options
        .target_reduction
        .map(|f| ((1.0 - f.clamp(0.0, 1.0) as f64) * before as f64).ceil() as usize)
        .unwrap_or(0);
    let max_cost_error = options.max_error.map(|e| e as f64 / scale);
    let mut heap: BinaryHeap<Candidate> = unique
        .iter()
        .filter_map(|&(u, v)| s.candidate(u, v))
        .collect();
    let mut alive_tris = before;
    while alive_tris > target {
        let Some(c) = heap.pop() else { break };
        let (u, v) = (c.u as usize, c.v as usize);
        if !s.alive[u] || !s.alive[v] || s.stamp[u] != c.stamp_u || s.stamp[v] != c.stamp_v {
            continue;
        }
        let error = s.error(&c);
        if max_cost_error.is_some_and(|m| error > m) {
            break;
        }
        if s.locked[u] || s.locked[v] {
            stats.refused_boundary += 1;
            continue;
        }
        if !s.link_ok(c.u, c.v) {
            stats.refused_topology += 1;
            continue;
        }
        if !s.geometry_ok(c.u, c.v, c.target) {
            stats.refused_geometry += 1;
            continue;
        }
        alive_tris -= s.collapse(c.u, c.v, c.target);
        stats.collapses += 1;
        stats.max_error = stats.max_error.max((error * scale) as f32);
        let mut neighbours: Vec<u32> = s.vert_tris[u]
            .iter()
            .flat_map(|&t| s.tris[t as usize])
            .filter(|&w| w != c.u)
            .collect();
        neighbours.sort_unstable();
        neighbours.dedup();
        for w in neighbours {
            if let Some(n) = s.candidate(c.u.min(w), c.u.max(w)) {
                heap.push(n);
            }
        }
    }

    // Compact: surviving triangles in order, vertices in order of first use.
    let mut remap = vec![u32::MAX; nv];
    let mut positions = Vec::new();
    let mut triangles = Vec::with_capacity(alive_tris);
    for (t, tri) in s.tris.iter().enumerate() {
        if !s.tri_alive[t] {
            continue;
        }
        triangles.push(tri.map(|v| {
            if remap[v as usize] == u32::MAX {
                remap[v as usize] = positions.len() as u32;
                positions.push((s.pos[v as usize] * scale + centre).as_vec3());
            }
            remap[v as usize]
        }));
    }
    *mesh = TriMesh {
        positions,
        triangles,
        normals: Vec::new(),
    };
    stats.triangles_after = mesh.triangle_count();
    stats
}

impl State {
    fn candidate(&self, u: u32, v: u32) -> Option<Candidate> {
        let (pu, pv) = (self.pos[u as usize], self.pos[v as usize]);
        let q = self.quadric[u as usize] + self.quadric[v as usize];
        let mid = (pu + pv) * 0.5;
        let target = match q.optimum() {
            Some(p) if (p - mid).length() <= (pv - pu).length() => p,
            _ => q.segment_minimum(pu, pv),
        };
        Some(Candidate {
            cost: q.evaluate(target),
            u,
            v,
            stamp_u: self.stamp[u as usize],
            stamp_v: self.stamp[v as usize],
            target,
        })
    }

    /// RMS distance (unit-box units) of a candidate: √(cost / area weight).
    fn error(&self, c: &Candidate) -> f64 {
        let w = self.quadric[c.u as usize].weight + self.quadric[c.v as usize].weight;
        if w > 0.0 {
            (c.cost / w).sqrt()
        } else {
            0.0
        }
    }

    fn neighbours(&self, v: u32) -> Vec<u32> {
        let mut n: Vec<u32> = self.vert_tris[v as usize]
            .iter()
            .flat_map(|&t| self.tris[t as usize])
            .filter(|&w| w != v)
            .collect();
        n.sort_unstable();
        n.dedup();
        n
    }

    /// The link condition: the common neighbours of `u` and `v` are exactly the opposite
    /// vertices of the two triangles on the edge, each of valence above 3.
    fn link_ok(&self, u: u32, v: u32) -> bool {
        let shared: Vec<u32> = self.vert_tris[u as usize]
            .iter()
            .copied()
            .filter(|&t| self.tris[t as usize].contains(&v))
            .collect();
        if shared.len() != 2 {
            return false;
        }
        let mut opposite: Vec<u32> = shared
            .iter()
            .map(|&t| {
                *self.tris[t as usize]
                    .iter()
                    .find(|&&w| w != u && w != v)
                    .expect("a third vertex")
            })
            .collect();
        opposite.sort_unstable();
        if opposite[0] == opposite[1] {
            return false;
        }
        let (nu, nv) = (self.neighbours(u), self.neighbours(v));
        let common: Vec<u32> = nu
            .iter()
            .copied()
            .filter(|w| nv.binary_search(w).is_ok())
            .collect();
        if common != opposite {
            return false;
        }
        opposite
            .iter()
            .all(|&w| self.vert_tris[w as usize].len() > 3)
    }

    /// No surviving triangle around `u` or `v` flips or degenerates when both move to `p`.
    fn geometry_ok(&self, u: u32, v: u32, p: DVec3) -> bool {
        for &x in &[u, v] {
            for &t in &self.vert_tris[x as usize] {
                let tri = self.tris[t as usize];
                if tri.contains(&u) && tri.contains(&v) {
                    continue;
                }
                let old = tri.map(|w| self.pos[w as usize]);
                let new = tri.map(|w| {
                    if w == u || w == v {
                        p
                    } else {
                        self.pos[w as usize]
                    }
                });
                let n0 = (old[1] - old[0]).cross(old[2] - old[0]);
                let n1 = (new[1] - new[0]).cross(new[2] - new[0]);
                let (l0, l1) = (n0.length(), n1.length());
                if l1 == 0.0 {
                    return false;
                }
                if l0 > 0.0 && n0.dot(n1) < MIN_NORMAL_DOT * l0 * l1 {
                    return false;
                }
                if n1.dot(self.reference_normal[t as usize]) < MIN_NORMAL_DOT * l1 {
                    return false;
                }
                let edges2 = (new[1] - new[0]).length_squared()
                    + (new[2] - new[1]).length_squared()
                    + (new[0] - new[2]).length_squared();
                let quality = 2.0 * 3f64.sqrt() * l1 / edges2;
                if quality < MIN_QUALITY {
                    return false;
                }
            }
        }
        true
    }

    /// Collapses `v` into `u` at `p`; returns the number of triangles removed.
    fn collapse(&mut self, u: u32, v: u32, p: DVec3) -> usize {
        let (ui, vi) = (u as usize, v as usize);
        let mut removed = 0;
        let v_tris = std::mem::take(&mut self.vert_tris[vi]);
        for &t in &v_tris {
            let tri = &mut self.tris[t as usize];
            if tri.contains(&u) {
                self.tri_alive[t as usize] = false;
                removed += 1;
                for &w in tri.iter() {
                    if w != v {
                        self.vert_tris[w as usize].retain(|&x| x != t);
                    }
                }
            } else {
                for w in tri.iter_mut() {
                    if *w == v {
                        *w = u;
                    }
                }
                self.vert_tris[ui].push(t);
            }
        }
        self.pos[ui] = p;
        let q = self.quadric[vi];
        self.quadric[ui] += q;
        self.alive[vi] = false;
        self.stamp[ui] += 1;
        self.stamp[vi] += 1;
        removed
    }
}
