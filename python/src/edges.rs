//! Blender's edges of a triangle mesh: each unordered vertex pair once, and the edge of
//! every triangle side (what `Mesh.fluid_edges` returns, so that a player need not have
//! Blender compute them).

use rayon::prelude::*;

/// The edges of `triangles` over `vertices` vertices, each unordered vertex pair once,
/// and the edge of every triangle side (side k of triangle t joins corners k and
/// k + 1 mod 3) at 3t + k: [`number_edges_loop`] where the triangles are a Loop step's
/// layout (a subdivided fluid surface), else [`number_edges_manifold`] where the surface
/// is a closed, consistently oriented manifold (meniscus's fluid surface), else
/// [`number_edges_sorted`]. The first two number the same edges in the same order.
pub(crate) fn number_edges(triangles: &[[u32; 3]], vertices: usize) -> (Vec<[i32; 2]>, Vec<i32>) {
    number_edges_loop(triangles, vertices)
        .or_else(|| number_edges_manifold(triangles, vertices))
        .unwrap_or_else(|| number_edges_sorted(triangles, vertices))
}

/// [`number_edges`] of a mesh laid out as one Loop subdivision step of a closed,
/// consistently oriented manifold (what meniscus's subdivision and an archive's decoder
/// write: control triangle `t` becomes triangles `4t .. 4t + 3` as
/// `meniscus::subdivision::children` orders them, the control vertices first, the edge
/// points after), numbered as [`number_edges_manifold`] numbers them, without looking
/// any side's twin up: each family of four numbers six edges (the first halves of its
/// three control sides and its three inner edges, in side order), so family `t`'s edges
/// are `6t .. 6t + 5`; a second half's twin is the first half of the control side across
/// (found through the two control sides of each edge point) and an inner side's twin is
/// in its own family. `None` when the triangles are not such a layout: a family not
/// `children`'s, an edge point not on exactly two opposite control sides, a degenerate
/// control triangle, or two control triangles on the same three vertices (their inner
/// edges would coincide).
fn number_edges_loop(triangles: &[[u32; 3]], vertices: usize) -> Option<(Vec<[i32; 2]>, Vec<i32>)> {
    const NONE: u32 = u32::MAX;
    if triangles.is_empty() || !triangles.len().is_multiple_of(4) {
        return None;
    }
    // A family's control triangle and edge points, when it is children()'s layout.
    let family = |f: &[[u32; 3]]| -> Option<([u32; 3], [u32; 3])> {
        let tri = [f[0][0], f[1][0], f[2][0]];
        let m = [f[0][1], f[1][1], f[2][1]];
        let ok = f[0] == [tri[0], m[0], m[2]]
            && f[1] == [tri[1], m[1], m[0]]
            && f[2] == [tri[2], m[2], m[1]]
            && f[3] == [m[0], m[1], m[2]]
            && tri[0] != tri[1]
            && tri[1] != tri[2]
            && tri[2] != tri[0];
        ok.then_some((tri, m))
    };
    // The control vertices are those below every edge point.
    let (low_point, high_point, high_control) = triangles
        .par_chunks_exact(4)
        .map(|f| {
            family(f).map(|(tri, m)| {
                (
                    *m.iter().min().unwrap(),
                    *m.iter().max().unwrap(),
                    *tri.iter().max().unwrap(),
                )
            })
        })
        .try_reduce(
            || (u32::MAX, 0, 0),
            |a, b| Some((a.0.min(b.0), a.1.max(b.1), a.2.max(b.2))),
        )?;
    if high_control >= low_point || high_point as usize >= vertices {
        return None;
    }
    let control = low_point;
    // The two control sides (3t + k) of every edge point.
    let points = vertices - control as usize;
    let mut sides_of = vec![[NONE; 2]; points];
    for (t, f) in triangles.chunks_exact(4).enumerate() {
        for (k, m) in [f[0][1], f[1][1], f[2][1]].into_iter().enumerate() {
            let s = (3 * t + k) as u32;
            let slot = &mut sides_of[(m - control) as usize];
            if slot[0] == NONE {
                slot[0] = s;
            } else if slot[1] == NONE {
                slot[1] = s;
            } else {
                return None;
            }
        }
    }
    let tri_of = |t: usize| {
        [
            triangles[4 * t][0],
            triangles[4 * t + 1][0],
            triangles[4 * t + 2][0],
        ]
    };
    let m_of = |t: usize| {
        [
            triangles[4 * t][1],
            triangles[4 * t + 1][1],
            triangles[4 * t + 2][1],
        ]
    };
    let opposite = |s: u32, other: u32| {
        let (t, k) = (s as usize / 3, s as usize % 3);
        let (u, j) = (other as usize / 3, other as usize % 3);
        let (a, b) = (tri_of(t)[k], tri_of(t)[(k + 1) % 3]);
        let (c, d) = (tri_of(u)[j], tri_of(u)[(j + 1) % 3]);
        a == d && b == c
    };
    let sound = sides_of
        .par_iter()
        .all(|&[s, other]| s == NONE || (other != NONE && opposite(s, other)));
    if !sound {
        return None;
    }
    // The control side across control side s (through its edge point).
    let across = |s: usize| -> usize {
        let m = m_of(s / 3)[s % 3];
        let [x, y] = sides_of[(m - control) as usize];
        (if x as usize == s { y } else { x }) as usize
    };
    // The first-half edge of control side (t, k): child k's side 0, after the sides
    // numbered before it in the family (child 0's side 1 when m0 < m2, child 1's side 1
    // when m1 < m0).
    let first_half = |s: usize| -> i32 {
        let (t, k) = (s / 3, s % 3);
        let m = m_of(t);
        let before = match k {
            0 => 0,
            1 => 1 + u32::from(m[0] < m[2]),
            _ => 2 + u32::from(m[0] < m[2]) + u32::from(m[1] < m[0]),
        };
        (6 * t) as i32 + before as i32
    };
    let mut edges = vec![[0i32; 2]; triangles.len() / 4 * 6];
    let mut corners = vec![0i32; triangles.len() * 3];
    let ok = edges
        .par_chunks_mut(6)
        .zip(corners.par_chunks_mut(12))
        .zip(triangles.par_chunks_exact(4))
        .enumerate()
        .all(|(t, ((edges, corners), f))| {
            let s = [3 * t, 3 * t + 1, 3 * t + 2];
            let neighbours = s.map(|s| across(s) / 3);
            if neighbours[0] == neighbours[1]
                || neighbours[1] == neighbours[2]
                || neighbours[2] == neighbours[0]
            {
                return false;
            }
            // The sides with a < b in side order get the family's six edges.
            let mut next = 0;
            for (i, tri) in f.iter().enumerate() {
                for k in 0..3 {
                    let (a, b) = (tri[k], tri[(k + 1) % 3]);
                    if a < b {
                        edges[next] = [a as i32, b as i32];
                        corners[3 * i + k] = (6 * t + next) as i32;
                        next += 1;
                    }
                }
            }
            debug_assert_eq!(next, 6);
            // Inner sides: the twin of child c's side 1 is child 3's side (c + 2) % 3.
            for (c, child) in f[..3].iter().enumerate() {
                let (x, y) = (3 * c + 1, 9 + (c + 2) % 3);
                if child[1] < child[2] {
                    corners[y] = corners[x];
                } else {
                    corners[x] = corners[y];
                }
            }
            // Second halves: child (k + 1)'s side 2 runs from the edge point of control
            // side k to its end; its twin is the first half of the control side across.
            for k in 0..3 {
                corners[3 * ((k + 1) % 3) + 2] = first_half(across(s[k]));
            }
            true
        });
    ok.then_some((edges, corners))
}

/// [`number_edges`] of a closed, consistently oriented manifold, where each side (a, b)
/// has exactly one twin (b, a): the edges are the sides with a < b, numbered in side
/// order, and each other side looks its twin up among the few sides leaving its
/// smaller vertex. `None` (nothing numbered) at the first side without exactly one
/// twin. Half the random memory traffic of [`number_edges_sorted`]: 30-36 ms of CPU
/// instead of 39-45 ms on a 985 k-triangle archived frame.
fn number_edges_manifold(
    triangles: &[[u32; 3]],
    vertices: usize,
) -> Option<(Vec<[i32; 2]>, Vec<i32>)> {
    let side = |t: &[u32; 3], k: usize| (t[k], t[(k + 1) % 3]);
    let mut start = vec![0u32; vertices + 1];
    for t in triangles {
        for k in 0..3 {
            let (a, b) = side(t, k);
            if a < b {
                start[a as usize + 1] += 1;
            }
        }
    }
    for v in 0..vertices {
        start[v + 1] += start[v];
    }
    let owners = start[vertices] as usize;
    if 2 * owners != 3 * triangles.len() {
        return None;
    }
    // The sides with a < b, bucketed by a, each as (b << 32 | its edge).
    let mut fill = start.clone();
    let mut leaving = vec![0u64; owners];
    let mut edges: Vec<[i32; 2]> = Vec::with_capacity(owners);
    let mut corners = vec![0i32; 3 * triangles.len()];
    for (i, t) in triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = side(t, k);
            if a < b {
                let e = edges.len() as u32;
                edges.push([a as i32, b as i32]);
                corners[3 * i + k] = e as i32;
                leaving[fill[a as usize] as usize] = (u64::from(b) << 32) | u64::from(e);
                fill[a as usize] += 1;
            }
        }
    }
    drop(fill);
    let mut matched = vec![false; owners];
    for (i, t) in triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = side(t, k);
            if a == b {
                return None;
            }
            if a < b {
                continue;
            }
            let bucket = &leaving[start[b as usize] as usize..start[b as usize + 1] as usize];
            let mut twins = bucket.iter().filter(|&&s| (s >> 32) as u32 == a);
            let (Some(&twin), None) = (twins.next(), twins.next()) else {
                return None;
            };
            let e = (twin & 0xffff_ffff) as usize;
            if std::mem::replace(&mut matched[e], true) {
                return None;
            }
            corners[3 * i + k] = e as i32;
        }
    }
    Some((edges, corners))
}

/// [`number_edges`] of any triangles: the sides bucketed by their smaller vertex, each
/// bucket sorted, the edges numbered in order of their smaller, then larger vertex.
fn number_edges_sorted(triangles: &[[u32; 3]], vertices: usize) -> (Vec<[i32; 2]>, Vec<i32>) {
    // Sides bucketed by their smaller vertex, then numbered bucket by bucket.
    let mut start = vec![0u32; vertices + 1];
    for t in triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            start[a.min(b) as usize + 1] += 1;
        }
    }
    for v in 0..vertices {
        start[v + 1] += start[v];
    }
    let mut fill = start.clone();
    // Each side as (larger vertex << 32 | side index): a bucket sorts without looking
    // its sides up.
    let mut sides = vec![0u64; 3 * triangles.len()];
    for (i, t) in triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let low = a.min(b) as usize;
            sides[fill[low] as usize] = (u64::from(a.max(b)) << 32) | (3 * i + k) as u64;
            fill[low] += 1;
        }
    }
    let mut edges: Vec<[i32; 2]> = Vec::with_capacity(3 * triangles.len() / 2 + 1);
    let mut corners = vec![0i32; 3 * triangles.len()];
    for a in 0..vertices {
        let bucket = &mut sides[start[a] as usize..start[a + 1] as usize];
        bucket.sort_unstable();
        let mut previous = None;
        for &s in bucket.iter() {
            let b = (s >> 32) as u32;
            if previous != Some(b) {
                edges.push([a as i32, b as i32]);
                previous = Some(b);
            }
            corners[(s & 0xffff_ffff) as usize] = (edges.len() - 1) as i32;
        }
    }
    (edges, corners)
}

/// The pairs as one flat vector (2 values per pair), without copying.
pub(crate) fn flat_pairs(pairs: Vec<[i32; 2]>) -> Vec<i32> {
    let mut pairs = std::mem::ManuallyDrop::new(pairs);
    let (ptr, len, capacity) = (pairs.as_mut_ptr(), pairs.len(), pairs.capacity());
    // SAFETY: [i32; 2] is two i32 with the alignment of i32, so the allocation of
    // `capacity` pairs is that of 2 × `capacity` i32, of which 2 × `len` are initialized;
    // the vector's ownership passes to the new one.
    unsafe { Vec::from_raw_parts(ptr.cast::<i32>(), 2 * len, 2 * capacity) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use meniscus::isolated::icosphere;
    use meniscus::subdivision::{subdivide, SubdivideOptions};

    fn subdivided(triangles: Vec<[u32; 3]>, vertices: Vec<glam::Vec3>) -> meniscus::TriMesh {
        let mut mesh = meniscus::TriMesh {
            positions: vertices,
            triangles,
            normals: Vec::new(),
            attributes: Vec::new(),
        };
        subdivide(&mut mesh, &SubdivideOptions::levels(1));
        mesh
    }

    #[test]
    fn a_loop_step_is_numbered_as_the_closed_manifold_numbering_does() {
        for level in 0..3 {
            let control = icosphere(level, 1.0);
            let fine = subdivided(control.triangles.clone(), control.positions.clone());
            let n = fine.positions.len();
            let want = number_edges_manifold(&fine.triangles, n).unwrap();
            assert_eq!(number_edges_loop(&fine.triangles, n), Some(want.clone()));
            assert_eq!(number_edges(&fine.triangles, n), want);
            // Euler: a closed surface of T triangles has 3T/2 edges.
            assert_eq!(2 * want.0.len(), 3 * fine.triangles.len());
        }
    }

    #[test]
    fn other_layouts_are_left_to_the_other_numberings() {
        // Not subdivided (an icosahedron; icosphere(1) is its midpoint subdivision, laid
        // out as a Loop step).
        let ico = icosphere(0, 1.0);
        assert_eq!(number_edges_loop(&ico.triangles, ico.positions.len()), None);
        let control = icosphere(1, 1.0);
        let fine = subdivided(control.triangles.clone(), control.positions.clone());
        let nf = fine.positions.len();
        // Two families swapped within: not children()'s order.
        let mut shuffled = fine.triangles.clone();
        shuffled.swap(0, 1);
        assert_eq!(number_edges_loop(&shuffled, nf), None);
        // Not closed: one family dropped.
        let open = fine.triangles[4..].to_vec();
        assert_eq!(number_edges_loop(&open, nf), None);
        assert_eq!(
            number_edges(&open, nf),
            number_edges_sorted(&open, nf),
            "an open surface takes the sorted numbering"
        );
        // Two control triangles on the same three vertices (a closed pillow): their inner
        // edges coincide, so the mesh is no manifold and is numbered by sorting.
        let pillow = subdivided(vec![[0, 1, 2], [0, 2, 1]], vec![glam::Vec3::ZERO; 3]);
        let np = pillow.positions.len();
        assert_eq!(number_edges_loop(&pillow.triangles, np), None);
        let (edges, corners) = number_edges(&pillow.triangles, np);
        assert_eq!(corners.len(), 3 * pillow.triangles.len());
        let mut pairs: Vec<[i32; 2]> = edges.iter().map(|&[a, b]| [a.min(b), a.max(b)]).collect();
        pairs.sort_unstable();
        pairs.dedup();
        assert_eq!(pairs.len(), edges.len(), "each vertex pair once");
    }

    #[test]
    fn pairs_flatten_in_place() {
        let pairs = vec![[1, 2], [3, 4], [5, 6]];
        let ptr = pairs.as_ptr() as usize;
        let flat = flat_pairs(pairs);
        assert_eq!(flat, [1, 2, 3, 4, 5, 6]);
        assert_eq!(flat.as_ptr() as usize, ptr);
    }
}
