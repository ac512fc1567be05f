//! Marching-cubes triangulations generated from a face-consistency rule instead of a
//! hand-written table.
//!
//! For a cube configuration (8 inside/outside bits) and a decision for every ambiguous
//! face, the surface's trace on each of the 6 faces is a set of segments between the
//! crossing points of that face's edges. A face with two crossings has one segment; an
//! ambiguous face (diagonal corners alike) has two, paired either to *separate* or to
//! *connect* its inside corners. The decision depends only on the four values of that face
//! (the asymptotic decider, see [`super`]), so the two cubes sharing a face trace the same
//! segments, in opposite directions. The segments of a cube form disjoint closed loops.
//! Each loop is triangulated with *face-free* diagonals only: a diagonal may join two
//! points only if no cube face holds both, so no neighbouring cube can produce the same
//! edge. A loop that has no such triangulation gets a centre vertex (the mean of its
//! points, owned by the cell) and a fan around it. Hence, for any field:
//! * every mesh edge on a cube face is shared by exactly the two cubes of that face, with
//!   opposite directions, and every other edge lies inside one cube and is shared by two
//!   of its triangles — no boundary, no non-manifold edge, consistent orientation;
//! * loops in one cube share no vertex, and the four cubes around a grid edge chain their
//!   triangle fans around the vertex on it — every vertex is manifold.
//!
//! Corner `c = x + 2y + 4z`. Edge `axis·4 + (bit of the first other axis) + 2·(bit of the
//! second)`, the other axes taken in increasing order.

use std::sync::OnceLock;

/// One cube edge: lower corner and axis (the upper corner is `lo | 1 << axis`).
#[derive(Clone, Copy, Debug)]
pub(crate) struct CubeEdge {
    pub lo: u8,
    pub axis: u8,
}

#[cfg(test)]
impl CubeEdge {
    /// The upper corner.
    pub fn hi(&self) -> u8 {
        self.lo | (1 << self.axis)
    }
}

/// The 12 cube edges in table order.
pub(crate) fn cube_edges() -> [CubeEdge; 12] {
    let mut edges = [CubeEdge { lo: 0, axis: 0 }; 12];
    for axis in 0..3u8 {
        let others: Vec<u8> = (0..3u8).filter(|&a| a != axis).collect();
        for k in 0..4u8 {
            let lo = ((k & 1) << others[0]) | (((k >> 1) & 1) << others[1]);
            edges[(axis * 4 + k) as usize] = CubeEdge { lo, axis };
        }
    }
    edges
}

fn edge_between(a: u8, b: u8) -> u8 {
    let diff = a ^ b;
    let axis = diff.trailing_zeros() as u8;
    let lo = a.min(b);
    let others: Vec<u8> = (0..3u8).filter(|&x| x != axis).collect();
    let k = ((lo >> others[0]) & 1) | (((lo >> others[1]) & 1) << 1);
    axis * 4 + k
}

/// Corners of face `f = axis·2 + side` in the face's canonical order
/// `(0,0), (1,0), (1,1), (0,1)` over its axes `u = (axis+1)%3`, `v = (axis+2)%3`.
pub(crate) fn face_corners(face: usize) -> [u8; 4] {
    let axis = face / 2;
    let side = (face % 2) as u8;
    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
    let base = side << axis;
    [(0, 0), (1, 0), (1, 1), (0, 1)].map(|(a, b): (u8, u8)| base | (a << u) | (b << v))
}

/// Whether face `face` of configuration `case` is ambiguous (two diagonal corners inside,
/// the other two outside).
pub(crate) fn face_is_ambiguous(case: u8, face: usize) -> bool {
    let c = face_corners(face).map(|k| (case >> k) & 1);
    c[0] == c[2] && c[1] == c[3] && c[0] != c[1]
}

/// First point id of centre vertices: ids `0..12` are cube edges, id `CENTER + n` is the
/// centre vertex of the configuration's `n`-th centred loop.
pub(crate) const CENTER: u8 = 12;

/// The triangulation of one configuration.
#[derive(Clone, Debug, Default)]
pub(crate) struct Entry {
    /// Triangles as point ids (edges `0..12`, centres from [`CENTER`]).
    pub triangles: Vec<[u8; 3]>,
    /// The edges of every loop that needs a centre vertex.
    pub centered_loops: Vec<Vec<u8>>,
}

/// Triangulations for every (configuration, face decisions) pair.
pub(crate) struct Table {
    entries: Vec<Entry>,
}

impl Table {
    /// Triangulation of `case` with ambiguous-face decisions `connect` (bit f set: the
    /// inside corners of face f are connected). Bits of unambiguous faces must be zero.
    #[inline]
    pub fn entry(&self, case: u8, connect: u8) -> &Entry {
        &self.entries[(case as usize) | ((connect as usize) << 8)]
    }
}

/// The table, built once on first use.
pub(crate) fn table() -> &'static Table {
    static TABLE: OnceLock<Table> = OnceLock::new();
    TABLE.get_or_init(build)
}

fn build() -> Table {
    let mut entries = vec![Entry::default(); 256 * 64];
    for case in 0..=255u8 {
        let ambiguous = (0..6).fold(0u8, |m, f| m | ((face_is_ambiguous(case, f) as u8) << f));
        // Every subset of the ambiguous faces; other bits are never set by the caller.
        let mut connect = 0u8;
        loop {
            entries[(case as usize) | ((connect as usize) << 8)] = triangulate(case, connect);
            if connect == ambiguous {
                break;
            }
            connect = (connect.wrapping_sub(ambiguous)) & ambiguous;
        }
    }
    Table { entries }
}

/// Whether some cube face holds both edges (then a chord between their points could be
/// produced by the neighbouring cube too).
fn share_a_face(a: u8, b: u8) -> bool {
    let edges = cube_edges();
    let (ea, eb) = (edges[a as usize], edges[b as usize]);
    // A face is fixed by (axis, side); an edge lies on the faces of its two other axes,
    // at the sides given by its lower corner's bits.
    (0..3u8).any(|axis| {
        axis != ea.axis && axis != eb.axis && ((ea.lo >> axis) & 1) == ((eb.lo >> axis) & 1)
    })
}

/// A triangulation of the polygon `poly` (in order) using only face-free chords, or `None`.
fn triangulate_face_free(poly: &[u8]) -> Option<Vec<[u8; 3]>> {
    let k = poly.len();
    // best[i][j]: split vertex of a triangulation of the sub-polygon i..=j whose closing
    // side (i, j) is a polygon side or a face-free chord.
    let side_ok = |i: usize, j: usize| {
        j == i + 1 || (i == 0 && j == k - 1) || !share_a_face(poly[i], poly[j])
    };
    let mut split = vec![vec![None::<usize>; k]; k];
    let mut solvable = vec![vec![false; k]; k];
    for i in 0..k - 1 {
        solvable[i][i + 1] = true;
    }
    for len in 2..k {
        for i in 0..k - len {
            let j = i + len;
            if !side_ok(i, j) {
                continue;
            }
            // Prefer splits near the middle: balanced triangulations avoid long fans.
            let mut ms: Vec<usize> = (i + 1..j).collect();
            ms.sort_by_key(|&m| (2 * m).abs_diff(i + j));
            if let Some(m) = ms
                .into_iter()
                .find(|&m| side_ok(i, m) && side_ok(m, j) && solvable[i][m] && solvable[m][j])
            {
                split[i][j] = Some(m);
                solvable[i][j] = true;
            }
        }
    }
    if !solvable[0][k - 1] {
        return None;
    }
    let mut out = Vec::with_capacity(k - 2);
    let mut stack = vec![(0, k - 1)];
    while let Some((i, j)) = stack.pop() {
        if let Some(m) = split[i][j] {
            out.push([poly[i], poly[m], poly[j]]);
            stack.push((i, m));
            stack.push((m, j));
        }
    }
    Some(out)
}

/// The triangulation of one configuration.
fn triangulate(case: u8, connect: u8) -> Entry {
    let mut entry = Entry::default();
    let inside = |c: u8| (case >> c) & 1 == 1;
    // next[e] = the edge point following e on its loop.
    let mut next = [u8::MAX; 12];
    for face in 0..6 {
        let canonical = face_corners(face);
        // Walk the face counter-clockwise seen from outside the cube. The canonical order
        // runs counter-clockwise around +axis; the low side (side 0) faces −axis.
        let walk: [u8; 4] = if face % 2 == 1 {
            canonical
        } else {
            [canonical[0], canonical[3], canonical[2], canonical[1]]
        };
        // Crossings in walk order: (edge, entering the inside?).
        let mut crossings: Vec<(u8, bool)> = Vec::with_capacity(4);
        for i in 0..4 {
            let (a, b) = (walk[i], walk[(i + 1) % 4]);
            if inside(a) != inside(b) {
                crossings.push((edge_between(a, b), inside(b)));
            }
        }
        match crossings.len() {
            0 => {}
            2 => {
                let (ein, eout) = if crossings[0].1 {
                    (crossings[0].0, crossings[1].0)
                } else {
                    (crossings[1].0, crossings[0].0)
                };
                next[ein as usize] = eout;
            }
            4 => {
                let connected = (connect >> face) & 1 == 1;
                for i in 0..4 {
                    let (e, entering) = crossings[i];
                    if !entering {
                        continue;
                    }
                    // Separate: an entering crossing pairs with the next leaving one
                    // (cutting off one inside corner). Connect: with the previous one.
                    let j = if connected { (i + 3) % 4 } else { (i + 1) % 4 };
                    next[e as usize] = crossings[j].0;
                }
            }
            _ => unreachable!("a square face has an even number of sign changes"),
        }
    }
    let mut visited = [false; 12];
    for start in 0..12u8 {
        if next[start as usize] == u8::MAX || visited[start as usize] {
            continue;
        }
        let mut poly = Vec::with_capacity(12);
        let mut e = start;
        while !visited[e as usize] {
            visited[e as usize] = true;
            poly.push(e);
            e = next[e as usize];
        }
        // The loop runs counter-clockwise seen from outside the fluid (checked by a test);
        // triangles keep its direction, so normals point towards positive values.
        match triangulate_face_free(&poly) {
            Some(tris) => entry.triangles.extend(tris),
            None => {
                let center = CENTER + entry.centered_loops.len() as u8;
                for k in 0..poly.len() {
                    entry
                        .triangles
                        .push([center, poly[k], poly[(k + 1) % poly.len()]]);
                }
                entry.centered_loops.push(poly);
            }
        }
    }
    entry
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edges_connect_corners_differing_in_their_axis_bit() {
        for (i, e) in cube_edges().iter().enumerate() {
            assert_eq!(edge_between(e.lo, e.hi()) as usize, i);
        }
    }

    #[test]
    fn single_inside_corner_gives_one_triangle_facing_away_from_it() {
        let t = table();
        let tris = &t.entry(1, 0).triangles;
        assert_eq!(tris.len(), 1);
        let edges = cube_edges();
        let mid = |e: u8| {
            let ed = edges[e as usize];
            let p = |c: u8| {
                glam::Vec3::new((c & 1) as f32, ((c >> 1) & 1) as f32, ((c >> 2) & 1) as f32)
            };
            (p(ed.lo) + p(ed.hi())) * 0.5
        };
        let [a, b, c] = tris[0].map(mid);
        let n = (b - a).cross(c - a);
        assert!(
            n.dot(glam::Vec3::ONE) > 0.0,
            "normal {n} must point away from corner 0"
        );
    }

    #[test]
    fn every_configuration_has_euler_consistent_loops() {
        let t = table();
        for case in 0..=255u8 {
            let n_changes = cube_edges()
                .iter()
                .filter(|e| ((case >> e.lo) & 1) != ((case >> e.hi()) & 1))
                .count();
            // A fan over a loop of k points has k − 2 triangles; summed over loops the
            // triangle count is (crossing points) − 2·(loops) ≥ 0.
            let entry = t.entry(case, 0);
            let tris = entry.triangles.len();
            assert!(tris <= n_changes, "case {case}");
            assert_eq!(tris == 0, n_changes == 0, "case {case}");
            for tri in &entry.triangles {
                for k in 0..3 {
                    let (a, b) = (tri[k], tri[(k + 1) % 3]);
                    assert_ne!(a, b, "case {case}");
                }
            }
        }
    }
}
