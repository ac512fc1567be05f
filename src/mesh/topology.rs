//! Topology checks: closedness, edge and vertex manifoldness, orientation, components.

use super::TriMesh;
use hashbrown::HashMap;

/// What [`validate`] found. All counts are zero for a closed, consistently oriented
/// 2-manifold without degenerate triangles.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct TopologyReport {
    /// Edges used by exactly one triangle.
    pub boundary_edges: usize,
    /// Edges used by more than two triangles.
    pub non_manifold_edges: usize,
    /// Edges used by two triangles in the same direction (orientation flip).
    pub inconsistent_edges: usize,
    /// Vertices whose incident triangles form more than one fan (pinched vertices).
    pub non_manifold_vertices: usize,
    /// Triangles that repeat a vertex index or have zero area.
    pub degenerate_triangles: usize,
    /// Vertices referenced by no triangle.
    pub unreferenced_vertices: usize,
    /// Connected components (by shared vertices).
    pub components: usize,
}

impl TopologyReport {
    /// True for a closed, consistently oriented 2-manifold with no degenerate triangle.
    pub fn is_closed_manifold(&self) -> bool {
        self.boundary_edges == 0
            && self.non_manifold_edges == 0
            && self.inconsistent_edges == 0
            && self.non_manifold_vertices == 0
            && self.degenerate_triangles == 0
    }
}

/// Checks the topology of `mesh`. Runs in O(triangles) expected time.
pub fn validate(mesh: &TriMesh) -> TopologyReport {
    let n = mesh.positions.len();
    let mut report = TopologyReport::default();
    // Directed edge counts, keyed by (min, max) with the count of each direction.
    let mut edges: HashMap<(u32, u32), (u32, u32)> =
        HashMap::with_capacity(mesh.triangles.len() * 2);
    let mut referenced = vec![false; n];
    for t in &mesh.triangles {
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
            report.degenerate_triangles += 1;
            continue;
        }
        let [a, b, c] = t.map(|i| mesh.positions[i as usize].as_dvec3());
        if (b - a).cross(c - a).length_squared() == 0.0 {
            report.degenerate_triangles += 1;
        }
        for k in 0..3 {
            let (u, v) = (t[k], t[(k + 1) % 3]);
            referenced[u as usize] = true;
            let e = edges.entry((u.min(v), u.max(v))).or_insert((0, 0));
            if u < v {
                e.0 += 1;
            } else {
                e.1 += 1;
            }
        }
    }
    for &(fwd, bwd) in edges.values() {
        match fwd + bwd {
            1 => report.boundary_edges += 1,
            2 => {
                if fwd != 1 {
                    report.inconsistent_edges += 1
                }
            }
            _ => report.non_manifold_edges += 1,
        }
    }
    report.unreferenced_vertices = referenced.iter().filter(|r| !**r).count();

    // Vertex fans: union triangles around each vertex that share an edge through it; a
    // manifold vertex has exactly one group.
    let fans = super::VertexTriangles::new(mesh);
    let mut parent: Vec<u32> = Vec::new();
    for v in 0..n {
        let tris = fans.of(v as u32);
        if tris.len() < 2 {
            continue;
        }
        parent.clear();
        parent.extend(0..tris.len() as u32);
        // Map "other vertex" -> local triangle index; two triangles sharing an other
        // vertex share the edge (v, other).
        let mut seen: HashMap<u32, u32> = HashMap::with_capacity(tris.len() * 2);
        for (li, &ti) in tris.iter().enumerate() {
            for &w in &mesh.triangles[ti as usize] {
                if w as usize == v {
                    continue;
                }
                if let Some(&lj) = seen.get(&w) {
                    union(&mut parent, li as u32, lj);
                } else {
                    seen.insert(w, li as u32);
                }
            }
        }
        let groups = (0..tris.len() as u32)
            .filter(|&i| find(&mut parent, i) == i)
            .count();
        if groups > 1 {
            report.non_manifold_vertices += 1;
        }
    }

    // Components by vertex union-find over triangles.
    let mut comp: Vec<u32> = (0..n as u32).collect();
    for t in &mesh.triangles {
        union(&mut comp, t[0], t[1]);
        union(&mut comp, t[0], t[2]);
    }
    report.components = (0..n as u32)
        .filter(|&i| referenced[i as usize] && find(&mut comp, i) == i)
        .count();
    report
}

/// Connected component label of every triangle (components by shared vertices), labels
/// numbered 0.. in order of first triangle.
pub fn triangle_components(mesh: &TriMesh) -> (Vec<u32>, usize) {
    let n = mesh.positions.len();
    let mut comp: Vec<u32> = (0..n as u32).collect();
    for t in &mesh.triangles {
        union(&mut comp, t[0], t[1]);
        union(&mut comp, t[0], t[2]);
    }
    let mut label: HashMap<u32, u32> = HashMap::new();
    let labels = mesh
        .triangles
        .iter()
        .map(|t| {
            let root = find(&mut comp, t[0]);
            let next = label.len() as u32;
            *label.entry(root).or_insert(next)
        })
        .collect();
    (labels, label.len())
}

fn find(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        let p = parent[parent[i as usize] as usize];
        parent[i as usize] = p;
        i = p;
    }
    i
}

fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        let (lo, hi) = if ra < rb { (ra, rb) } else { (rb, ra) };
        parent[hi as usize] = lo;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn tetrahedron() -> TriMesh {
        TriMesh {
            positions: vec![
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(0.0, 1.0, 0.0),
                Vec3::new(0.0, 0.0, 1.0),
            ],
            triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
            normals: vec![],
            attributes: Vec::new(),
        }
    }

    #[test]
    fn tetrahedron_is_closed_manifold_with_positive_volume() {
        let m = tetrahedron();
        let r = validate(&m);
        assert!(r.is_closed_manifold(), "{r:?}");
        assert_eq!(r.components, 1);
        assert!((m.signed_volume() - 1.0 / 6.0).abs() < 1e-12);
    }

    #[test]
    fn missing_triangle_shows_boundary_edges() {
        let mut m = tetrahedron();
        m.triangles.pop();
        let r = validate(&m);
        assert_eq!(r.boundary_edges, 3);
        assert!(!r.is_closed_manifold());
    }

    #[test]
    fn flipped_triangle_shows_inconsistent_edges() {
        let mut m = tetrahedron();
        m.triangles[3] = [1, 3, 2];
        let r = validate(&m);
        assert_eq!(r.inconsistent_edges, 3);
    }

    #[test]
    fn two_tetrahedra_sharing_a_vertex_pinch_it() {
        let mut m = tetrahedron();
        let mut other = tetrahedron();
        for p in &mut other.positions {
            *p = -*p;
        }
        // Reverse orientation of the mirrored copy so both are outward.
        for t in &mut other.triangles {
            t.swap(1, 2);
        }
        m.append(&other);
        // Weld vertex 4 (the mirrored origin) onto vertex 0.
        for t in &mut m.triangles {
            for i in t.iter_mut() {
                if *i == 4 {
                    *i = 0;
                }
            }
        }
        let r = validate(&m);
        assert_eq!(r.non_manifold_vertices, 1);
        assert_eq!(r.boundary_edges, 0);
    }
}
