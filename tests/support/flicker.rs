//! The flicker of shading normals on consecutive frames, as `docs/quality.md` measures it
//! ("Steady in motion"): points `x` sampled uniformly by area on the middle frame's
//! surface, each with its closest points `q−`, `q+` on the frames before and after; the
//! second difference of the normals is the angle between the shading normal at `x` and the
//! normalised sum of the neighbours' shading normals at `q−` and `q+`. Shading normals are
//! the meshes' stored vertex normals interpolated across the face. Samples farther than
//! `near` from either neighbour (topology changes, spray) are left out. Smooth motion
//! changes the normals smoothly in time, so what is left is noise.

use super::Lcg;
use glam::DVec3;
use meniscus::mesh::TriMesh;
use std::collections::HashMap;

/// Closest-point queries on a mesh, through a hash of its triangles by cell.
pub struct Closest<'a> {
    mesh: &'a TriMesh,
    cell: f64,
    cells: HashMap<[i32; 3], Vec<u32>>,
}

impl<'a> Closest<'a> {
    /// An index for queries up to `reach` from the surface.
    pub fn new(mesh: &'a TriMesh, reach: f64) -> Self {
        let mut cells: HashMap<[i32; 3], Vec<u32>> = HashMap::new();
        let key = |p: DVec3| (p / reach).floor().as_ivec3().to_array();
        for (t, tri) in mesh.triangles.iter().enumerate() {
            let p = tri.map(|i| mesh.positions[i as usize].as_dvec3());
            let (lo, hi) = (key(p[0].min(p[1]).min(p[2])), key(p[0].max(p[1]).max(p[2])));
            for x in lo[0]..=hi[0] {
                for y in lo[1]..=hi[1] {
                    for z in lo[2]..=hi[2] {
                        cells.entry([x, y, z]).or_default().push(t as u32);
                    }
                }
            }
        }
        Closest {
            mesh,
            cell: reach,
            cells,
        }
    }

    /// The closest point within the reach: (triangle, point, distance).
    pub fn query(&self, p: DVec3) -> Option<(u32, DVec3, f64)> {
        let c = (p / self.cell).floor().as_ivec3();
        let mut best: Option<(u32, DVec3, f64)> = None;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(list) = self.cells.get(&[c.x + dx, c.y + dy, c.z + dz]) else {
                        continue;
                    };
                    for &t in list {
                        let tri = self.mesh.triangles[t as usize]
                            .map(|i| self.mesh.positions[i as usize].as_dvec3());
                        let q = closest_on_triangle(p, tri);
                        let d = (q - p).length();
                        if d <= self.cell && best.is_none_or(|b| d < b.2) {
                            best = Some((t, q, d));
                        }
                    }
                }
            }
        }
        best
    }
}

/// The vertex normals of triangle `t` interpolated at its point `q` (barycentric).
pub fn shading_normal(mesh: &TriMesh, t: u32, q: DVec3) -> DVec3 {
    let tri = mesh.triangles[t as usize];
    let [a, b, c] = tri.map(|i| mesh.positions[i as usize].as_dvec3());
    let area = |u: DVec3, v: DVec3, w: DVec3| (v - u).cross(w - u).length();
    let total = area(a, b, c).max(1e-300);
    let w = [area(q, b, c), area(a, q, c), area(a, b, q)].map(|x| x / total);
    let n = (0..3)
        .map(|k| w[k] * mesh.normals[tri[k] as usize].as_dvec3())
        .sum::<DVec3>();
    n.normalize_or_zero()
}

/// Closest point of triangle `[a, b, c]` to `p` (Ericson, Real-Time Collision Detection
/// 5.1.5).
pub fn closest_on_triangle(p: DVec3, [a, b, c]: [DVec3; 3]) -> DVec3 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}

/// `samples` points uniformly by area on `mesh` (seeded): (triangle, point).
pub fn sample(mesh: &TriMesh, samples: usize, seed: u64) -> Vec<(u32, DVec3)> {
    let mut cumulative = Vec::with_capacity(mesh.triangles.len());
    let mut total = 0.0;
    for tri in &mesh.triangles {
        let [a, b, c] = tri.map(|i| mesh.positions[i as usize].as_dvec3());
        total += (b - a).cross(c - a).length();
        cumulative.push(total);
    }
    let mut rng = Lcg(seed);
    (0..samples)
        .map(|_| {
            let u = rng.next_f64() * total;
            let t = cumulative
                .partition_point(|&c| c < u)
                .min(cumulative.len() - 1);
            let [a, b, c] = mesh.triangles[t].map(|i| mesh.positions[i as usize].as_dvec3());
            let (mut s, mut v) = (rng.next_f64(), rng.next_f64());
            if s + v > 1.0 {
                (s, v) = (1.0 - s, 1.0 - v);
            }
            (t as u32, a + s * (b - a) + v * (c - a))
        })
        .collect()
}

/// The second difference of the shading normals at the middle frame `now` (degrees):
/// (mean, 95th percentile, fraction of the samples kept).
pub fn normal_flicker(
    before: &TriMesh,
    now: &TriMesh,
    after: &TriMesh,
    near: f64,
    samples: usize,
) -> (f64, f64, f64) {
    let (prev, next) = (Closest::new(before, near), Closest::new(after, near));
    let mut angles = Vec::new();
    for (t, x) in sample(now, samples, 7) {
        let (Some((tp, qp, _)), Some((tn, qn, _))) = (prev.query(x), next.query(x)) else {
            continue;
        };
        let n = shading_normal(now, t, x);
        let mean =
            (shading_normal(before, tp, qp) + shading_normal(after, tn, qn)).normalize_or_zero();
        angles.push(n.dot(mean).clamp(-1.0, 1.0).acos().to_degrees());
    }
    let kept = angles.len() as f64 / samples as f64;
    angles.sort_by(f64::total_cmp);
    let mean = angles.iter().sum::<f64>() / angles.len().max(1) as f64;
    let p95 = angles
        .get((angles.len() as f64 * 0.95) as usize)
        .copied()
        .unwrap_or(f64::NAN);
    (mean, p95, kept)
}
