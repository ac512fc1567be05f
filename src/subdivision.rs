//! Loop subdivision (C. Loop, "Smooth Subdivision Surfaces Based on Triangles", 1987),
//! smoothing what decimation sharpened (Akinci et al. 2013, § 3.3).
//!
//! **Input:** a triangle mesh (closed or with boundaries). **Output:** the mesh refined
//! `levels` times: every triangle split into four, positions smoothed by Loop's masks.
//! * edge point, interior edge `ab` with opposite vertices `c, d`: `3/8 (a + b) + 1/8 (c + d)`;
//!   boundary edge: `1/2 (a + b)`;
//! * vertex point, interior vertex of valence `n`: `(1 − nβ) v + β Σ neighbours` with Loop's
//!   `β = (5/8 − (3/8 + 1/4 cos(2π/n))²) / n`; boundary vertex: `3/4 v + 1/8 (b₁ + b₂)` with
//!   its two boundary neighbours (a boundary stays a curve of the boundary alone);
//! * a vertex on more than two boundary edges or an edge of more than two triangles (not a
//!   manifold) keeps its position, as does an edge point of a non-manifold edge
//!   (midpoint).
//!
//! Vertex order: the old vertices keep their indices, edge points follow in sorted
//! (min, max) edge order; triangle `t` becomes triangles `4t .. 4t + 3`. The output keeps
//! the orientation and does not depend on the thread count. Normals are the caller's job.
//!
//! Per-vertex attributes (one item per vertex) are subdivided with the same masks as the
//! positions, so a constant attribute stays constant and a linear function of the
//! positions stays the same linear function of the new positions (every mask is affine:
//! its weights sum to 1). An attribute without one item per vertex is dropped.

use crate::mesh::{Attribute, TriMesh};
use glam::DVec3;
use rayon::prelude::*;

/// Peak working set of one Loop step, bytes per input triangle (the input's triangles,
/// side → edge indices, the output mesh; measured 104 on 32M particles, 134 on 4M where
/// heap left over from the tiles counts more). 110 put the 32M scene's whole-run estimate
/// (1906 MiB) within 1 % of its measured peaks (1863–1922 MiB over three sessions) and
/// under a 2 GiB budget; 120 refused that run. Since the step frees the input positions
/// before writing the triangles (2026-11-24) that run peaks at 1762 MiB: the estimate is
/// now 8 % high, kept as margin.
pub(crate) const BYTES_PER_INPUT_TRIANGLE: f64 = 110.0;

/// Options of [`subdivide`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub struct SubdivideOptions {
    /// Subdivision steps. Default 1.
    pub levels: u32,
}

impl SubdivideOptions {
    /// `levels` subdivision steps.
    pub fn levels(levels: u32) -> Self {
        SubdivideOptions { levels }
    }
}

impl Default for SubdivideOptions {
    fn default() -> Self {
        SubdivideOptions { levels: 1 }
    }
}

/// What [`subdivide`] did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct SubdivideStats {
    /// Triangles before.
    pub triangles_before: usize,
    /// Triangles after (`4^levels` times more).
    pub triangles_after: usize,
}

/// Subdivides `mesh` in place `options.levels` times; clears its normals.
pub fn subdivide(mesh: &mut TriMesh, options: &SubdivideOptions) -> SubdivideStats {
    let before = mesh.triangle_count();
    for _ in 0..options.levels {
        *mesh = subdivide_once(std::mem::take(mesh));
    }
    SubdivideStats {
        triangles_before: before,
        triangles_after: mesh.triangle_count(),
    }
}

/// One step. Takes the mesh by value so that its positions are freed as soon as the new
/// ones exist: the last step, writing four triangles per triangle, is the peak of memory
/// of a large run (the 32M scene under a 2 GiB budget), and holds only the input's
/// triangles, the side → edge map and the output.
fn subdivide_once(mesh: TriMesh) -> TriMesh {
    let TriMesh {
        positions: old_positions,
        triangles: old_triangles,
        attributes: old_attributes,
        ..
    } = mesh;
    let nv = old_positions.len();
    let tris = &old_triangles;
    let (mut sides, bucket_start) = sides_by_smaller_vertex(tris, nv);
    let (edges, rings) = number_edges(tris, &old_positions, &mut sides, bucket_start);
    let EdgeTable {
        edge_start,
        side_edge,
    } = edges;
    let ne = edge_start.len() - 1;
    let beta = loop_betas(&rings.valence);
    // Vertex points, then edge points, written straight into the output's positions.
    let mut positions: Vec<glam::Vec3> = Vec::with_capacity(nv + ne);
    positions.par_extend(
        (0..nv)
            .into_par_iter()
            .map(|v| rings.vertex_point(v, old_positions[v].as_dvec3(), &beta)),
    );
    let stencil = Stencil {
        tris,
        sides: &sides,
        edge_start: &edge_start,
        valence: &rings.valence,
        boundary_count: &rings.boundary_count,
        non_manifold: &rings.non_manifold,
        beta: &beta,
    };
    let attributes: Vec<Attribute> = old_attributes
        .iter()
        .filter(|a| a.components > 0 && a.values.len() == a.components * nv)
        .map(|a| stencil.apply(a))
        .collect();
    drop(old_attributes);
    drop(rings);
    let pos = |i: u32| old_positions[i as usize].as_dvec3();
    positions.par_extend((0..ne).into_par_iter().map(|e| {
        let group = &sides[edge_start[e] as usize..edge_start[e + 1] as usize];
        let (a, b) = side_ends(tris, group[0]);
        let (a, b) = (pos(a), pos(b));
        let p = if group.len() == 2 {
            let opposite = |s: u32| pos(tris[s as usize / 3][(s as usize % 3 + 2) % 3]);
            0.375 * (a + b) + 0.125 * (opposite(group[0]) + opposite(group[1]))
        } else {
            0.5 * (a + b)
        };
        p.as_vec3()
    }));
    drop(old_positions);
    drop(sides);
    drop(edge_start);
    let mut triangles: Vec<[u32; 3]> = vec![[0; 3]; tris.len() * 4];
    triangles
        .par_chunks_mut(4)
        .zip(tris.par_iter())
        .enumerate()
        .for_each(|(t, (out, tri))| {
            let m = [0, 1, 2].map(|k| nv as u32 + side_edge[t * 3 + k]);
            out.copy_from_slice(&children(*tri, m));
        });
    TriMesh {
        positions,
        triangles,
        normals: Vec::new(),
        attributes,
    }
}

/// The undirected edge (smaller vertex, larger vertex) of triangle side `s`: side `s % 3`
/// of triangle `s / 3`, from corner `s % 3` to the next.
#[inline]
fn side_ends(tris: &[[u32; 3]], s: u32) -> (u32, u32) {
    let t = &tris[s as usize / 3];
    let k = s as usize % 3;
    let (a, b) = (t[k], t[(k + 1) % 3]);
    (a.min(b), a.max(b))
}

/// Every side once, bucketed by the smaller vertex of its edge (4 bytes per side, no
/// sort of wide records), in side order within a bucket; and the buckets' starts.
fn sides_by_smaller_vertex(tris: &[[u32; 3]], nv: usize) -> (Vec<u32>, Vec<u32>) {
    let mut bucket_start = vec![0u32; nv + 1];
    for s in 0..tris.len() as u32 * 3 {
        bucket_start[side_ends(tris, s).0 as usize + 1] += 1;
    }
    for v in 0..nv {
        bucket_start[v + 1] += bucket_start[v];
    }
    let mut sides = vec![0u32; tris.len() * 3];
    let mut fill = bucket_start.clone();
    for s in 0..tris.len() as u32 * 3 {
        let a = side_ends(tris, s).0 as usize;
        sides[fill[a] as usize] = s;
        fill[a] += 1;
    }
    (sides, bucket_start)
}

/// The edges of one step: every side's edge, edges numbered in (min, max) order.
struct EdgeTable {
    /// Edge `e` is `sides[edge_start[e]..edge_start[e + 1]]` (one more entry at the end).
    edge_start: Vec<u32>,
    /// The edge of every side.
    side_edge: Vec<u32>,
}

/// The vertices' neighbourhoods, gathered edge by edge.
struct Rings {
    valence: Vec<u32>,
    /// Sum of the neighbours' positions.
    sum: Vec<DVec3>,
    /// Neighbours across boundary edges: count and sum.
    boundary_count: Vec<u32>,
    boundary_sum: Vec<DVec3>,
    /// On an edge of more than two triangles.
    non_manifold: Vec<bool>,
}

impl Rings {
    /// Loop's vertex point of vertex `v` at `p` (boundary rule on a regular boundary,
    /// fixed on a corner, a non-manifold edge or alone).
    fn vertex_point(&self, v: usize, p: DVec3, beta: &[f64]) -> glam::Vec3 {
        let n = self.valence[v];
        let moved = if self.non_manifold[v] || self.boundary_count[v] > 2 || n == 0 {
            p
        } else if self.boundary_count[v] == 2 {
            0.75 * p + 0.125 * self.boundary_sum[v]
        } else if self.boundary_count[v] == 0 {
            let (nf, beta) = (n as f64, beta[n as usize]);
            (1.0 - nf * beta) * p + beta * self.sum[v]
        } else {
            p
        };
        moved.as_vec3()
    }
}

/// One pass over the buckets in vertex order: sorts each by the larger vertex (sides of
/// one edge stay in side order), numbers the edges in (min, max) order, gives every side
/// its edge, and gathers the vertex neighbourhoods (valence, neighbour sum, boundary
/// neighbours) edge by edge. `sides` ends sorted by (edge, side).
fn number_edges(
    tris: &[[u32; 3]],
    positions: &[glam::Vec3],
    sides: &mut [u32],
    bucket_start: Vec<u32>,
) -> (EdgeTable, Rings) {
    let nv = positions.len();
    let pos = |i: u32| positions[i as usize].as_dvec3();
    let mut edge_start: Vec<u32> = Vec::with_capacity(sides.len() / 2 + 1);
    let mut side_edge = vec![0u32; tris.len() * 3];
    let mut rings = Rings {
        valence: vec![0u32; nv],
        sum: vec![DVec3::ZERO; nv],
        boundary_count: vec![0u32; nv],
        boundary_sum: vec![DVec3::ZERO; nv],
        non_manifold: vec![false; nv],
    };
    let mut bucket: Vec<(u32, u32)> = Vec::new();
    for a in 0..nv {
        let range = bucket_start[a] as usize..bucket_start[a + 1] as usize;
        bucket.clear();
        bucket.extend(
            sides[range.clone()]
                .iter()
                .map(|&s| (side_ends(tris, s).1, s)),
        );
        // Sides were filled in ascending order: (larger vertex, side) is the stable order.
        bucket.sort_unstable();
        for (slot, &(_, s)) in sides[range.clone()].iter_mut().zip(&bucket) {
            *slot = s;
        }
        let mut i = 0;
        while i < bucket.len() {
            let b = bucket[i].0;
            let mut j = i + 1;
            while j < bucket.len() && bucket[j].0 == b {
                j += 1;
            }
            let e = edge_start.len() as u32;
            edge_start.push((range.start + i) as u32);
            for &(_, s) in &bucket[i..j] {
                side_edge[s as usize] = e;
            }
            let (a32, b) = (a as u32, b as usize);
            let r = &mut rings;
            r.valence[a] += 1;
            r.valence[b] += 1;
            r.sum[a] += pos(b as u32);
            r.sum[b] += pos(a32);
            match j - i {
                1 => {
                    r.boundary_count[a] += 1;
                    r.boundary_count[b] += 1;
                    r.boundary_sum[a] += pos(b as u32);
                    r.boundary_sum[b] += pos(a32);
                }
                2 => {}
                _ => {
                    r.non_manifold[a] = true;
                    r.non_manifold[b] = true;
                }
            }
            i = j;
        }
    }
    edge_start.push(sides.len() as u32);
    (
        EdgeTable {
            edge_start,
            side_edge,
        },
        rings,
    )
}

/// The masks of one step as [`subdivide_once`] found them, for per-vertex values.
struct Stencil<'a> {
    tris: &'a [[u32; 3]],
    /// Every side, grouped by edge (edge `e` is `sides[edge_start[e]..edge_start[e + 1]]`).
    sides: &'a [u32],
    edge_start: &'a [u32],
    valence: &'a [u32],
    boundary_count: &'a [u32],
    non_manifold: &'a [bool],
    beta: &'a [f64],
}

impl Stencil<'_> {
    /// `attribute` (one item per old vertex) through the masks of the positions: vertex
    /// items, then edge items, in the order of the new vertices.
    fn apply(&self, attribute: &Attribute) -> Attribute {
        let k = attribute.components;
        let nv = self.valence.len();
        let ne = self.edge_start.len() - 1;
        let value = |v: u32, c: usize| attribute.values[v as usize * k + c] as f64;
        let ends = |s: u32| {
            let t = &self.tris[s as usize / 3];
            let j = s as usize % 3;
            let (a, b) = (t[j], t[(j + 1) % 3]);
            (a.min(b), a.max(b))
        };
        let opposite = |s: u32| self.tris[s as usize / 3][(s as usize % 3 + 2) % 3];
        let group =
            |e: usize| &self.sides[self.edge_start[e] as usize..self.edge_start[e + 1] as usize];
        // Neighbour sums (all neighbours, and boundary neighbours), edge by edge as the
        // positions gather them.
        let mut sum = vec![0f64; nv * k];
        let mut boundary_sum = vec![0f64; nv * k];
        for e in 0..ne {
            let g = group(e);
            let (a, b) = ends(g[0]);
            for c in 0..k {
                let (va, vb) = (value(a, c), value(b, c));
                sum[a as usize * k + c] += vb;
                sum[b as usize * k + c] += va;
                if g.len() == 1 {
                    boundary_sum[a as usize * k + c] += vb;
                    boundary_sum[b as usize * k + c] += va;
                }
            }
        }
        let mut values: Vec<f32> = Vec::with_capacity((nv + ne) * k);
        values.par_extend((0..nv * k).into_par_iter().map(|i| {
            let (v, c) = (i / k, i % k);
            let p = value(v as u32, c);
            let n = self.valence[v];
            let moved = if self.non_manifold[v] || self.boundary_count[v] > 2 || n == 0 {
                p
            } else if self.boundary_count[v] == 2 {
                0.75 * p + 0.125 * boundary_sum[i]
            } else if self.boundary_count[v] == 0 {
                let (nf, beta) = (n as f64, self.beta[n as usize]);
                (1.0 - nf * beta) * p + beta * sum[i]
            } else {
                p
            };
            moved as f32
        }));
        values.par_extend((0..ne * k).into_par_iter().map(|i| {
            let (e, c) = (i / k, i % k);
            let g = group(e);
            let (a, b) = ends(g[0]);
            let (a, b) = (value(a, c), value(b, c));
            let p = if g.len() == 2 {
                0.375 * (a + b) + 0.125 * (value(opposite(g[0]), c) + value(opposite(g[1]), c))
            } else {
                0.5 * (a + b)
            };
            p as f32
        }));
        Attribute {
            name: attribute.name.clone(),
            components: k,
            values,
        }
    }
}

/// One Loop step of per-vertex `values` (`components` per vertex) of a closed mesh whose
/// step is already known as its result: `fine` holds the children of every control
/// triangle as [`children`] writes them (control triangle `t` → `fine[4t .. 4t + 4]`),
/// the `control` control vertices are numbered first and keep their numbers, and the
/// edge points (numbers `control ..`) are what the values are written for after them.
/// The masks are those of the positions (interior vertex and edge rules: every edge of a
/// closed mesh has two sides). Returns the `fine_vertices × components` values, or
/// `None` when `fine` is not such a layout (a damaged frame).
pub(crate) fn loop_values_of_closed(
    fine: &[[u32; 3]],
    control: usize,
    fine_vertices: usize,
    values: &[f32],
    components: usize,
) -> Option<Vec<f32>> {
    let k = components;
    if fine.len() % 4 != 0 || fine_vertices < control || values.len() != control * k {
        return None;
    }
    let edges = fine_vertices - control;
    let mut valence = vec![0u32; control];
    let mut sum = vec![0f64; control * k];
    let mut edge = vec![0f64; edges * k];
    let mut sides = vec![0u8; edges];
    let value = |v: usize, c: usize| values[v * k + c] as f64;
    for family in fine.chunks_exact(4) {
        let tri = [family[0][0], family[1][0], family[2][0]].map(|v| v as usize);
        let m = [family[0][1], family[1][1], family[2][1]].map(|v| v as usize);
        if tri.iter().any(|&v| v >= control) || m.iter().any(|&e| e < control || e >= fine_vertices)
        {
            return None;
        }
        for j in 0..3 {
            let (a, b, apex, e) = (tri[j], tri[(j + 1) % 3], tri[(j + 2) % 3], m[j] - control);
            sides[e] = sides[e].saturating_add(1);
            // Each of the edge's two sides adds half of 3/8 (a + b) and its apex's 1/8;
            // each adds both ends to each other's neighbourhood (halved below).
            valence[a] += 1;
            valence[b] += 1;
            for c in 0..k {
                let (va, vb) = (value(a, c), value(b, c));
                edge[e * k + c] += 0.1875 * (va + vb) + 0.125 * value(apex, c);
                sum[a * k + c] += vb;
                sum[b * k + c] += va;
            }
        }
    }
    if sides.iter().any(|&n| n != 2) {
        return None;
    }
    let half_valence: Vec<u32> = valence.iter().map(|n| n / 2).collect();
    let beta = loop_betas(&half_valence);
    let mut out = Vec::with_capacity(fine_vertices * k);
    for v in 0..control {
        let n = half_valence[v];
        for c in 0..k {
            let p = value(v, c);
            let moved = if n == 0 {
                p
            } else {
                let (nf, b) = (n as f64, beta[n as usize]);
                (1.0 - nf * b) * p + b * (0.5 * sum[v * k + c])
            };
            out.push(moved as f32);
        }
    }
    out.extend(edge.iter().map(|&x| x as f32));
    Some(out)
}

/// Loop's β for every valence up to the largest in `valence`, computed once:
/// `β(n) = (5/8 − (3/8 + 1/4 cos(2π/n))²) / n` (entry 0 is never used).
pub(crate) fn loop_betas(valence: &[u32]) -> Vec<f64> {
    let max_valence = valence.iter().copied().max().unwrap_or(0) as usize;
    (0..=max_valence)
        .map(|n| {
            let nf = n.max(1) as f64;
            let c = 0.375 + 0.25 * (2.0 * std::f64::consts::PI / nf).cos();
            (0.625 - c * c) / nf
        })
        .collect()
}

/// The four children of triangle `tri` whose sides have the edge points `m` (`m[k]` on
/// side `(tri[k], tri[k+1])`), orientation kept.
pub(crate) fn children(tri: [u32; 3], m: [u32; 3]) -> [[u32; 3]; 4] {
    [
        [tri[0], m[0], m[2]],
        [tri[1], m[1], m[0]],
        [tri[2], m[2], m[1]],
        [m[0], m[1], m[2]],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::isolated::icosphere;
    use crate::mesh::validate;
    use glam::Vec3;

    #[test]
    fn closed_meshes_stay_closed_and_shrink_towards_the_limit_surface() {
        let mut m = icosphere(0, 1.0);
        let stats = subdivide(&mut m, &SubdivideOptions { levels: 3 });
        assert_eq!(stats.triangles_after, 20 * 64);
        let report = validate(&m);
        assert!(report.is_closed_manifold(), "{report:?}");
        assert!(m.signed_volume() > 0.0);
        // Loop's limit position of an icosahedron vertex (valence 5, β = 0.0841,
        // γ = 1/(3/(8β) + 5) = 0.1057) is (1 − 5γ)·1 + γ·5·cos 63.43° = 0.708 of the
        // circumradius; after three steps every vertex is within a few per cent of it.
        let (lo, hi) = m.positions.iter().fold((f32::MAX, 0.0f32), |(l, h), p| {
            (l.min(p.length()), h.max(p.length()))
        });
        assert!(lo > 0.69 && hi < 0.73 && hi - lo < 0.02, "radii {lo}..{hi}");
    }

    #[test]
    fn straight_boundaries_stay_straight() {
        // A flat 4×4 grid patch in z = 0 with a boundary along y = 0.
        let mut positions = Vec::new();
        for j in 0..5 {
            for i in 0..5 {
                positions.push(Vec3::new(i as f32, j as f32, 0.0));
            }
        }
        let mut triangles = Vec::new();
        for j in 0..4u32 {
            for i in 0..4u32 {
                let a = j * 5 + i;
                triangles.push([a, a + 1, a + 6]);
                triangles.push([a, a + 6, a + 5]);
            }
        }
        let mut m = TriMesh {
            positions,
            triangles,
            normals: vec![],
            attributes: Vec::new(),
        };
        subdivide(&mut m, &SubdivideOptions::default());
        assert!(
            m.positions.iter().all(|p| p.z == 0.0),
            "a flat patch stays flat"
        );
        // The boundary curve is the cubic B-spline of the boundary polygon: the straight run
        // y = 0 keeps its 3 inner old vertices and gains 4 edge points, all on y = 0 (the two
        // corners are rounded off, as the boundary rule does).
        let on_edge: Vec<&Vec3> = m.positions.iter().filter(|p| p.y.abs() < 1e-6).collect();
        assert_eq!(on_edge.len(), 7, "boundary vertices on y = 0 stay on it");
        let report = validate(&m);
        assert_eq!(report.non_manifold_edges + report.inconsistent_edges, 0);
        assert_eq!(report.boundary_edges, 32);
    }

    #[test]
    fn attributes_follow_the_masks_of_the_positions() {
        // A closed sphere with uneven vertices, and an open patch (boundary and corner
        // rules), each with a linear function of the positions and a constant.
        let mut closed = icosphere(2, 1.0);
        for (i, p) in closed.positions.iter_mut().enumerate() {
            *p *= 1.0 + 0.05 * ((i * 37 % 11) as f32 / 11.0);
        }
        let mut open = closed.clone();
        open.triangles.truncate(open.triangles.len() - 7);
        let linear = |p: Vec3| [2.0 * p.x - p.y + 0.5, 0.25 * p.z - 3.0];
        for mut mesh in [closed, open] {
            mesh.attributes = vec![
                Attribute {
                    name: "linear".into(),
                    components: 2,
                    values: mesh.positions.iter().flat_map(|&p| linear(p)).collect(),
                },
                Attribute {
                    name: "constant".into(),
                    components: 1,
                    values: vec![0.7; mesh.positions.len()],
                },
                // Not one item per vertex: dropped.
                Attribute {
                    name: "short".into(),
                    components: 1,
                    values: vec![1.0],
                },
            ];
            subdivide(&mut mesh, &SubdivideOptions { levels: 2 });
            assert_eq!(mesh.attributes.len(), 2);
            assert_eq!(mesh.attributes[0].len(), mesh.vertex_count());
            for (v, &p) in mesh.positions.iter().enumerate() {
                let got = mesh.attributes[0].item(v);
                let want = linear(p);
                for c in 0..2 {
                    assert!(
                        (got[c] - want[c]).abs() < 1e-5,
                        "vertex {v}: {got:?} vs {want:?}"
                    );
                }
                assert_eq!(mesh.attributes[1].item(v), [0.7]);
            }
        }
    }

    #[test]
    fn the_closed_step_of_values_is_the_general_one() {
        let mut mesh = icosphere(1, 1.0);
        mesh.positions[3] *= 1.3;
        let nv = mesh.vertex_count();
        let values: Vec<f32> = (0..nv)
            .flat_map(|i| [(i * i % 7) as f32, i as f32])
            .collect();
        mesh.attributes = vec![Attribute {
            name: "a".into(),
            components: 2,
            values: values.clone(),
        }];
        let mut general = mesh.clone();
        subdivide(&mut general, &SubdivideOptions { levels: 1 });
        let closed =
            loop_values_of_closed(&general.triangles, nv, general.vertex_count(), &values, 2)
                .unwrap();
        for (a, b) in closed.iter().zip(&general.attributes[0].values) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
        // Not a layout of children.
        let mut bad = general.triangles.clone();
        bad[0][0] = (nv + 1) as u32;
        assert!(loop_values_of_closed(&bad, nv, general.vertex_count(), &values, 2).is_none());
    }

    #[test]
    fn output_does_not_depend_on_thread_count() {
        let mesh = icosphere(3, 2.0);
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    let mut m = mesh.clone();
                    subdivide(&mut m, &SubdivideOptions { levels: 2 });
                    m
                })
        };
        assert_eq!(run(1), run(3));
    }
}
