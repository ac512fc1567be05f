//! Particles of several sizes (issue 37): each particle meshed with its own radius.
//! A box of fine particles beside coarse ones (8 merged into one), a sphere of three
//! radius bands, isolated particles of different sizes, and the invariants: tiling and
//! thread count change nothing, radii equal to r give the plain run.

mod support;

use glam::{DVec3, Vec3};
use meniscus::cancel::CancelToken;
use meniscus::mesh::{triangle_components, InsideTest, TriMesh};
use meniscus::pipeline::{reconstruct_sized, ReconstructOptions};
use meniscus::radius::ParticleRadii;
use meniscus::tiles::TileOptions;
use support::in_pool;

/// The box of the issue: 0.6 × 0.3 × 0.3, fine particles (spacing 0.025, radius 0.0125)
/// for x < 0.3, coarse ones (spacing 0.05, radius 0.025) beyond; each fills its cube of
/// the lattice, so the particles' spheres fill the box.
fn two_size_box() -> (Vec<Vec3>, Vec<f32>) {
    let (mut positions, mut radii) = (Vec::new(), Vec::new());
    for (x0, x1, spacing) in [(0.0, 0.3, 0.025), (0.3, 0.6, 0.05)] {
        let n = |length: f64| (length / spacing).round() as usize;
        for i in 0..n(x1 - x0) {
            for j in 0..n(0.3) {
                for k in 0..n(0.3) {
                    let c = |m: usize| (m as f64 + 0.5) * spacing;
                    positions.push(DVec3::new(x0 + c(i), c(j), c(k)).as_vec3());
                    radii.push((spacing / 2.0) as f32);
                }
            }
        }
    }
    (positions, radii)
}

fn radii(values: Vec<f32>) -> ParticleRadii {
    ParticleRadii {
        attribute: "radius".into(),
        values,
    }
}

fn run(positions: &[Vec3], radii: &ParticleRadii, options: &ReconstructOptions) -> TriMesh {
    let (surface, stats) = reconstruct_sized(
        positions,
        Some(radii.clone()),
        options,
        &|_| {},
        &CancelToken::new(),
    )
    .unwrap();
    let containment = stats.containment.expect("containment ran");
    assert_eq!(containment.remaining, 0, "{containment:?}");
    surface.fluid
}

/// Whether every edge joins exactly two triangles, in opposite directions.
fn closed(mesh: &TriMesh) -> bool {
    let mut edges = std::collections::HashMap::new();
    for t in &mesh.triangles {
        for k in 0..3 {
            *edges.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
        }
    }
    edges
        .iter()
        .all(|(&(a, b), &n)| n == 1 && edges.get(&(b, a)) == Some(&1))
}

/// Distance from `p` to the nearest point of triangle `abc`.
fn distance_to_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let n = (b - a).cross(c - a);
    let inside_edges = [(a, b), (b, c), (c, a)]
        .iter()
        .all(|&(u, v)| (v - u).cross(p - u).dot(n) >= 0.0);
    if inside_edges {
        return ((p - a).dot(n) / n.length()).abs();
    }
    [(a, b), (b, c), (c, a)]
        .iter()
        .map(|&(u, v)| {
            let t = ((p - u).dot(v - u) / (v - u).length_squared()).clamp(0.0, 1.0);
            (p - (u + (v - u) * t)).length()
        })
        .fold(f64::INFINITY, f64::min)
}

/// Every centre inside `mesh` and at least `depth_factor` times its own radius from it.
fn assert_centres_inside(mesh: &TriMesh, positions: &[Vec3], radii: &[f32], depth_factor: f64) {
    let inside = InsideTest::new(mesh, 0.05);
    let corners: Vec<[DVec3; 3]> = mesh
        .triangles
        .iter()
        .map(|t| t.map(|v| mesh.positions[v as usize].as_dvec3()))
        .collect();
    for (i, (&p, &r)) in positions.iter().zip(radii).enumerate() {
        assert!(inside.contains(p), "centre {i} at {p} is outside");
        let q = p.as_dvec3();
        let depth = corners
            .iter()
            .map(|[a, b, c]| distance_to_triangle(q, *a, *b, *c))
            .fold(f64::INFINITY, f64::min);
        // The depth is met on the surface containment measures (one Loop step); the
        // output adds a hair of smoothing after it.
        assert!(
            depth >= depth_factor * r as f64 * 0.98,
            "centre {i} (radius {r}) only {depth} deep"
        );
    }
}

#[test]
fn a_box_of_fine_and_coarse_particles_is_one_closed_box() {
    let (positions, values) = two_size_box();
    let mut mesh = run(
        &positions,
        &radii(values.clone()),
        &ReconstructOptions::new(0.0125),
    );
    let (_, components) = triangle_components(&mesh);
    assert_eq!(components, 1);
    assert!(closed(&mesh), "holes or non-manifold edges");
    let volume = mesh.signed_volume();
    let true_volume = 0.6 * 0.3 * 0.3;
    assert!(
        (volume / true_volume - 1.0).abs() < 0.015,
        "volume {volume} against the box's {true_volume}"
    );
    // Face normals on the box's faces, away from its edges (one coarse spacing), against
    // the faces' own; area-weighted mean angle.
    let size = DVec3::new(0.6, 0.3, 0.3);
    let (mut sum, mut area) = (0.0, 0.0);
    mesh.compute_normals();
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|v| mesh.positions[v as usize].as_dvec3());
        let cross = (b - a).cross(c - a);
        let centre = (a + b + c) / 3.0;
        let mut planes: Vec<(f64, DVec3)> = (0..3)
            .flat_map(|k| {
                let axis = DVec3::AXES[k];
                [(centre[k], -axis), (size[k] - centre[k], axis)]
            })
            .collect();
        planes.sort_by(|x, y| x.0.total_cmp(&y.0));
        if planes[1].0 < 0.05 {
            continue;
        }
        let angle = cross.normalize().dot(planes[0].1).clamp(-1.0, 1.0).acos();
        sum += angle.to_degrees() * cross.length();
        area += cross.length();
    }
    let mean_angle = sum / area;
    assert!(mean_angle < 1.0, "face normals {mean_angle}° off the box's");
    assert_centres_inside(&mesh, &positions, &values, 0.25);
}

#[test]
fn a_sphere_of_three_radius_bands_is_round_and_holds_every_centre() {
    // Lattice particles in a ball of radius 0.3: spacing 0.02 in the core (r < 0.15),
    // 0.04 in the middle band and 0.06 in the outer one, each band's particles those of
    // its lattice inside the band.
    let (mut positions, mut values) = (Vec::new(), Vec::new());
    for (inner, outer, spacing) in [(0.0, 0.15, 0.02), (0.15, 0.24, 0.04), (0.24, 0.3, 0.06)] {
        let n = (0.3 / spacing as f64).ceil() as i32 + 1;
        for i in -n..=n {
            for j in -n..=n {
                for k in -n..=n {
                    let p = DVec3::new(i as f64, j as f64, k as f64) * spacing as f64;
                    let d = p.length() + spacing as f64 / 2.0;
                    if d > inner && d <= outer {
                        positions.push(p.as_vec3());
                        values.push(spacing / 2.0);
                    }
                }
            }
        }
    }
    let mesh = run(
        &positions,
        &radii(values.clone()),
        &ReconstructOptions::new(0.01),
    );
    let (_, components) = triangle_components(&mesh);
    assert_eq!(components, 1);
    assert!(closed(&mesh));
    // The volume of the particles' lattice cubes (the bands leave gaps between their
    // lattices), and a round surface: every vertex within one outer-band radius of the
    // sphere the outer particles reach.
    let expected: f64 = values.iter().map(|&r| (2.0 * r as f64).powi(3)).sum();
    let volume = mesh.signed_volume();
    assert!(
        (volume / expected - 1.0).abs() < 0.06,
        "volume {volume} vs {expected}"
    );
    for p in &mesh.positions {
        let d = p.length();
        assert!((d - 0.3).abs() < 0.03, "vertex at {d}");
    }
    assert_centres_inside(&mesh, &positions, &values, 0.25);
}

#[test]
fn tiles_and_threads_do_not_change_a_sized_run() {
    let (positions, values) = two_size_box();
    let radii = radii(values);
    let raw = ReconstructOptions::raw(0.0125);
    let untiled = in_pool(2, || {
        reconstruct_sized(
            &positions,
            Some(radii.clone()),
            &raw,
            &|_| {},
            &CancelToken::new(),
        )
    })
    .unwrap()
    .0;
    let mut tiled_options = raw.clone();
    tiled_options.tiles = TileOptions::tile_size(16);
    let tiled = in_pool(1, || {
        reconstruct_sized(
            &positions,
            Some(radii.clone()),
            &tiled_options,
            &|_| {},
            &CancelToken::new(),
        )
    })
    .unwrap()
    .0;
    assert_eq!(untiled.fluid.positions, tiled.fluid.positions);
    assert_eq!(untiled.fluid.triangles, tiled.fluid.triangles);
    let default = ReconstructOptions::new(0.0125);
    let one = in_pool(1, || run(&positions, &radii, &default));
    let two = in_pool(2, || run(&positions, &radii, &default));
    assert_eq!(one.positions, two.positions);
    assert_eq!(one.triangles, two.triangles);
}

#[test]
fn radii_equal_to_r_give_the_plain_run_and_bad_radii_are_refused() {
    let (positions, _) = two_size_box();
    let options = ReconstructOptions::new(0.0125);
    let uniform = radii(vec![0.0125; positions.len()]);
    let cancel = CancelToken::new();
    let sized = reconstruct_sized(
        &positions,
        Some(uniform.clone()),
        &options,
        &|_| {},
        &cancel,
    )
    .unwrap();
    let plain = reconstruct_sized(&positions, None, &options, &|_| {}, &cancel).unwrap();
    assert_eq!(sized.0, plain.0);
    let mut bad = uniform.clone();
    bad.values[5] = f32::NAN;
    let e = reconstruct_sized(&positions, Some(bad), &options, &|_| {}, &cancel).unwrap_err();
    assert!(e.to_string().contains("particle 5"), "{e}");
    let short = radii(vec![0.0125; 3]);
    let e = reconstruct_sized(&positions, Some(short), &options, &|_| {}, &cancel).unwrap_err();
    assert!(e.to_string().contains("holds 3 values"), "{e}");
}
#[test]
fn isolated_particles_get_spheres_of_their_own_radius() {
    // Three lone particles of radii r, 2r and r/2 far apart, beside a small block.
    let r = 0.01f32;
    let mut positions = vec![
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(0.0, 1.0, 0.0),
        Vec3::new(0.0, 0.0, 1.0),
    ];
    let mut values = vec![r, 2.0 * r, 0.5 * r];
    for i in 0..6 {
        for j in 0..6 {
            for k in 0..6 {
                positions.push(Vec3::new(i as f32, j as f32, k as f32) * 2.0 * r);
                values.push(r);
            }
        }
    }
    let (surface, _) = reconstruct_sized(
        &positions,
        Some(radii(values)),
        &ReconstructOptions::new(r),
        &|_| {},
        &CancelToken::new(),
    )
    .unwrap();
    let spheres = &surface.spheres;
    assert_eq!(spheres.centers, positions[..3]);
    assert_eq!(spheres.scales, [1.0, 2.0, 0.5]);
    let merged = spheres.merged();
    for (k, c) in spheres.centers.iter().enumerate() {
        let farthest = merged
            .positions
            .iter()
            .filter(|p| (**p - *c).length() < 0.2)
            .map(|p| (*p - *c).length())
            .fold(0.0f32, f32::max);
        let want = r * spheres.scales[k];
        assert!(
            (farthest - want).abs() < 1e-3 * want.max(r),
            "sphere {k}: {farthest} vs {want}"
        );
    }
}
