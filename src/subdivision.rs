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

use crate::mesh::TriMesh;
use glam::DVec3;
use rayon::prelude::*;

/// Options of [`subdivide`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SubdivideOptions {
    /// Subdivision steps. Default 1.
    pub levels: u32,
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
        ..
    } = mesh;
    let nv = old_positions.len();
    let tris = &old_triangles;
    // Triangle side `s` is side `s % 3` of triangle `s / 3`, from corner `s % 3` to the
    // next; its undirected edge is (smaller vertex, larger vertex).
    let ends = |s: u32| -> (u32, u32) {
        let t = &tris[s as usize / 3];
        let k = s as usize % 3;
        let (a, b) = (t[k], t[(k + 1) % 3]);
        (a.min(b), a.max(b))
    };
    // Every side once, sorted by (edge, side): bucketed by the smaller vertex (4 bytes
    // per side, no sort of wide records), each bucket ordered by the larger one.
    let mut bucket_start = vec![0u32; nv + 1];
    for s in 0..tris.len() as u32 * 3 {
        bucket_start[ends(s).0 as usize + 1] += 1;
    }
    for v in 0..nv {
        bucket_start[v + 1] += bucket_start[v];
    }
    let mut sides = vec![0u32; tris.len() * 3];
    {
        let mut fill = bucket_start.clone();
        for s in 0..tris.len() as u32 * 3 {
            let a = ends(s).0 as usize;
            sides[fill[a] as usize] = s;
            fill[a] += 1;
        }
    }
    let pos = |i: u32| old_positions[i as usize].as_dvec3();
    let opposite = |s: u32| tris[s as usize / 3][(s as usize % 3 + 2) % 3];
    // One pass over the buckets in vertex order: sort each by the larger vertex (sides of
    // one edge stay in side order), number the edges in (min, max) order, give every side
    // its edge, and gather the vertex neighbourhoods (valence, neighbour sum, boundary
    // neighbours) edge by edge.
    let mut edge_start: Vec<u32> = Vec::with_capacity(sides.len() / 2 + 1);
    let mut side_edge = vec![0u32; tris.len() * 3];
    let mut valence = vec![0u32; nv];
    let mut sum = vec![DVec3::ZERO; nv];
    let mut boundary_count = vec![0u32; nv];
    let mut boundary_sum = vec![DVec3::ZERO; nv];
    let mut non_manifold = vec![false; nv];
    let mut bucket: Vec<(u32, u32)> = Vec::new();
    for a in 0..nv {
        let range = bucket_start[a] as usize..bucket_start[a + 1] as usize;
        bucket.clear();
        bucket.extend(sides[range.clone()].iter().map(|&s| (ends(s).1, s)));
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
            valence[a] += 1;
            valence[b] += 1;
            sum[a] += pos(b as u32);
            sum[b] += pos(a32);
            match j - i {
                1 => {
                    boundary_count[a] += 1;
                    boundary_count[b] += 1;
                    boundary_sum[a] += pos(b as u32);
                    boundary_sum[b] += pos(a32);
                }
                2 => {}
                _ => {
                    non_manifold[a] = true;
                    non_manifold[b] = true;
                }
            }
            i = j;
        }
    }
    drop(bucket);
    drop(bucket_start);
    let ne = edge_start.len();
    edge_start.push(sides.len() as u32);
    let beta = loop_betas(&valence);
    // Vertex points, then edge points, written straight into the output's positions.
    let mut positions: Vec<glam::Vec3> = Vec::with_capacity(nv + ne);
    positions.par_extend((0..nv).into_par_iter().map(|v| {
        let p = pos(v as u32);
        let n = valence[v];
        let moved = if non_manifold[v] || boundary_count[v] > 2 || n == 0 {
            p
        } else if boundary_count[v] == 2 {
            0.75 * p + 0.125 * boundary_sum[v]
        } else if boundary_count[v] == 0 {
            let (nf, beta) = (n as f64, beta[n as usize]);
            (1.0 - nf * beta) * p + beta * sum[v]
        } else {
            p
        };
        moved.as_vec3()
    }));
    drop((valence, sum, boundary_count, boundary_sum, non_manifold));
    positions.par_extend((0..ne).into_par_iter().map(|e| {
        let group = &sides[edge_start[e] as usize..edge_start[e + 1] as usize];
        let (a, b) = ends(group[0]);
        let (a, b) = (pos(a), pos(b));
        let p = if group.len() == 2 {
            0.375 * (a + b) + 0.125 * (pos(opposite(group[0])) + pos(opposite(group[1])))
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
        attributes: Vec::new(),
    }
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
