//! Isolated particles: particles with no other particle within the influence radius `R`
//! leave the field (see `neighbors::find_isolated`) and are drawn as one
//! pre-tessellated icosphere of radius `r` instanced at every centre (Akinci et al. 2013,
//! § 3.4).

use crate::mesh::TriMesh;
#[cfg(test)]
use crate::neighbors::find_isolated;
use glam::Vec3;
use hashbrown::HashMap;

/// An icosphere: the icosahedron subdivided `level` times (each triangle into four, new
/// vertices projected onto the sphere), centred at the origin, radius `radius` (world
/// units), counter-clockwise seen from outside, with unit normals. `20·4^level` triangles.
pub fn icosphere(level: u32, radius: f32) -> TriMesh {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut positions: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut triangles: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..level {
        let mut midpoints: HashMap<(u32, u32), u32> = HashMap::new();
        let mut next = Vec::with_capacity(triangles.len() * 4);
        for t in &triangles {
            let mut mid = |a: u32, b: u32| {
                *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    positions
                        .push(((positions[a as usize] + positions[b as usize]) * 0.5).normalize());
                    positions.len() as u32 - 1
                })
            };
            let (ab, bc, ca) = (mid(t[0], t[1]), mid(t[1], t[2]), mid(t[2], t[0]));
            next.extend([[t[0], ab, ca], [t[1], bc, ab], [t[2], ca, bc], [ab, bc, ca]]);
        }
        triangles = next;
    }
    TriMesh {
        normals: positions.clone(),
        positions: positions.into_iter().map(|p| p * radius).collect(),
        triangles,
        attributes: Vec::new(),
    }
}

/// Splits `positions` into (particles with a neighbour closer than `radius`, isolated
/// particle centres), both in input order.
#[cfg(test)]
pub(crate) fn split_isolated(positions: &[Vec3], radius: f32) -> (Vec<Vec3>, Vec<Vec3>) {
    let isolated = find_isolated(positions, radius);
    let mut kept = Vec::with_capacity(positions.len());
    let mut alone = Vec::new();
    for (p, lonely) in positions.iter().zip(isolated) {
        if lonely {
            alone.push(*p);
        } else {
            kept.push(*p);
        }
    }
    (kept, alone)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::validate;

    #[test]
    fn icospheres_are_closed_outward_spheres() {
        for (level, count) in [(0, 20), (1, 80), (2, 320), (3, 1280)] {
            let s = icosphere(level, 0.5);
            assert_eq!(s.triangle_count(), count);
            let report = validate(&s);
            assert!(report.is_closed_manifold(), "{report:?}");
            assert_eq!(report.components, 1);
            assert!(s.positions.iter().all(|p| (p.length() - 0.5).abs() < 1e-6));
            assert!(s.signed_volume() > 0.0);
        }
        let v = icosphere(3, 1.0).signed_volume();
        let exact = 4.0 / 3.0 * std::f64::consts::PI;
        assert!((v / exact - 1.0).abs() < 0.02, "level-3 volume {v}");
    }
}
