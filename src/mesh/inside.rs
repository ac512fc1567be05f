//! Point-in-mesh queries for closed meshes by ray parity, accelerated by a 2D bucket grid.

use super::TriMesh;
use glam::{DQuat, DVec2, DVec3, Vec3};
use hashbrown::HashMap;

/// Answers "is this point inside the closed mesh?" by counting crossings of a ray from
/// the point. The ray direction is generic (a fixed irrational-looking rotation of +x), so
/// rays from points on lattice planes do not run through the lattice-aligned vertices of
/// marching-cubes meshes. Triangles are bucketed by their projected bounding box; points
/// on a shared edge's projection are counted once by a top-left rule.
pub struct InsideTest<'a> {
    mesh: &'a TriMesh,
    rotation: DQuat,
    rotated: Vec<DVec3>,
    bucket: f64,
    buckets: HashMap<(i64, i64), Vec<u32>>,
}

impl<'a> InsideTest<'a> {
    /// Builds the acceleration grid; `bucket` is the bucket edge in world units (about
    /// twice the median edge length is a good choice).
    pub fn new(mesh: &'a TriMesh, bucket: f32) -> Self {
        let bucket = bucket as f64;
        let rotation = DQuat::from_euler(glam::EulerRot::XYZ, 0.3713, 0.2291, 0.1187);
        let rotated: Vec<DVec3> = mesh
            .positions
            .iter()
            .map(|p| rotation * p.as_dvec3())
            .collect();
        let mut buckets: HashMap<(i64, i64), Vec<u32>> = HashMap::new();
        for (ti, t) in mesh.triangles.iter().enumerate() {
            let ps = t.map(|i| rotated[i as usize]);
            let (mut lo, mut hi) = (ps[0], ps[0]);
            for p in &ps[1..] {
                lo = lo.min(*p);
                hi = hi.max(*p);
            }
            let cell = |v: f64| (v / bucket).floor() as i64;
            for y in cell(lo.y)..=cell(hi.y) {
                for z in cell(lo.z)..=cell(hi.z) {
                    buckets.entry((y, z)).or_default().push(ti as u32);
                }
            }
        }
        InsideTest {
            mesh,
            rotation,
            rotated,
            bucket,
            buckets,
        }
    }

    /// True when `p` is inside (odd number of crossings towards +x).
    pub fn contains(&self, p: Vec3) -> bool {
        let p = self.rotation * p.as_dvec3();
        let key = (
            (p.y / self.bucket).floor() as i64,
            (p.z / self.bucket).floor() as i64,
        );
        let Some(tris) = self.buckets.get(&key) else {
            return false;
        };
        let q = DVec2::new(p.y, p.z);
        let mut crossings = 0usize;
        for &ti in tris {
            let t = self.mesh.triangles[ti as usize];
            let v = t.map(|i| self.rotated[i as usize]);
            let mut a = DVec2::new(v[0].y, v[0].z);
            let mut b = DVec2::new(v[1].y, v[1].z);
            let c = DVec2::new(v[2].y, v[2].z);
            let area = (b - a).perp_dot(c - a);
            if area == 0.0 {
                continue;
            }
            let (mut va, mut vb) = (v[0], v[1]);
            if area < 0.0 {
                std::mem::swap(&mut a, &mut b);
                std::mem::swap(&mut va, &mut vb);
            }
            let w = [
                edge_function(b, c, q),
                edge_function(c, a, q),
                edge_function(a, b, q),
            ];
            let edges = [(b, c), (c, a), (a, b)];
            let inside = w
                .iter()
                .zip(edges.iter())
                .all(|(&wi, &(s, e))| wi > 0.0 || (wi == 0.0 && is_top_left(s, e)));
            if !inside {
                continue;
            }
            let total = w[0] + w[1] + w[2];
            let vs = [va, vb, v[2]];
            let x = (w[0] * vs[0].x + w[1] * vs[1].x + w[2] * vs[2].x) / total;
            if x > p.x {
                crossings += 1;
            }
        }
        crossings % 2 == 1
    }
}

fn edge_function(a: DVec2, b: DVec2, p: DVec2) -> f64 {
    (b - a).perp_dot(p - a)
}

/// The top-left rule for counter-clockwise triangles: an edge owns the points on it when
/// it is a "top" edge (horizontal, pointing left) or a "left" edge (pointing down).
fn is_top_left(s: DVec2, e: DVec2) -> bool {
    let d = e - s;
    (d.y == 0.0 && d.x < 0.0) || d.y < 0.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn octahedron_contains_its_centre_and_not_far_points() {
        let mesh = TriMesh {
            positions: vec![Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z],
            triangles: vec![
                [0, 2, 4],
                [2, 1, 4],
                [1, 3, 4],
                [3, 0, 4],
                [2, 0, 5],
                [1, 2, 5],
                [3, 1, 5],
                [0, 3, 5],
            ],
            normals: vec![],
            attributes: Vec::new(),
        };
        let test = InsideTest::new(&mesh, 0.5);
        assert!(
            test.contains(Vec3::ZERO),
            "the centre lies on the ray through a vertex"
        );
        assert!(test.contains(Vec3::new(0.1, 0.2, 0.3)));
        assert!(!test.contains(Vec3::new(0.5, 0.5, 0.5)));
        assert!(!test.contains(Vec3::new(-2.0, 0.1, 0.1)));
        assert!(!test.contains(Vec3::new(2.0, 0.0, 0.0)));
    }
}
