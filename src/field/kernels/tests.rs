//! Tests of the anisotropic kernels.

use super::*;

fn anisotropic(r: f32) -> FieldOptions {
    FieldOptions {
        kernel: crate::field::Kernel::Anisotropic,
        ..FieldOptions::new(r)
    }
}

/// The common gather with the wide one for particles near a face gives the kernels
/// of the wide gather for all, bit for bit: particles in general position, and on a
/// lattice whose rows lie on the half-blocks' faces (half of them then scan the
/// wide gather); with several sizes too.
#[test]
fn the_narrow_gather_gives_the_kernels_of_the_wide_one() {
    let r = 0.01f32;
    let mut rng = crate::test_rng::TestRng::new(11);
    let mut positions = Vec::new();
    for z in 0..9 {
        for y in 0..7 {
            for x in 0..11 {
                let p = Vec3::new(x as f32, y as f32, z as f32) * 2.0 * r;
                positions.push(p);
                let j = Vec3::new(rng.unit_f32(), rng.unit_f32(), rng.unit_f32());
                positions.push(p + Vec3::new(0.3, 20.0, 0.0) + (j - 0.5) * r);
            }
        }
    }
    let field = anisotropic(r);
    let (_, sorted, sorted_halves) = super::super::canonical_order(&positions, &field);
    let edge = field.cell_size_world() * HALF_BLOCK_EDGE as f64;
    let ratios: Vec<f32> = (0..sorted.len())
        .map(|i| 0.6 + 0.1 * (i % 5) as f32)
        .collect();
    let wanted = vec![true; sorted.len()];
    let sized = super::super::Sizes {
        ratios: &ratios,
        largest: 1.0,
    };
    for sizes in [None, Some(sized)] {
        let reaches = Reaches::new(field.influence_radius_world() / edge);
        assert_eq!(
            (reaches.common, reaches.full),
            (1, 2),
            "R = 4 r is one edge"
        );
        let near_face = sorted
            .iter()
            .zip(&sorted_halves)
            .filter(|(p, c)| !reaches.within_common(**p, **c, edge))
            .count();
        assert!(
            near_face > sorted.len() / 4,
            "{near_face} of {}",
            sorted.len()
        );
        let wide = Reaches {
            common: reaches.full,
            ..reaches
        };
        let narrow = kernels_reaching(&sorted, &sorted_halves, &field, &wanted, sizes, reaches);
        let reference = kernels_reaching(&sorted, &sorted_halves, &field, &wanted, sizes, wide);
        assert_eq!(narrow, reference);
    }
    // The choice per particle carries the result: with R = 1.3 edges, a common gather
    // of one half-block holds the neighbours of the particles in the middle 0.4 of
    // their half-block only; the others need the wide gather.
    let field = FieldOptions {
        influence_radius: 5.2,
        ..anisotropic(r)
    };
    let reaches = Reaches {
        common: 1,
        full: 2,
        span: 1.3 * (1.0 + Reaches::HAIR),
    };
    let wide = Reaches {
        common: 2,
        ..reaches
    };
    let narrow = kernels_reaching(&sorted, &sorted_halves, &field, &wanted, None, reaches);
    let reference = kernels_reaching(&sorted, &sorted_halves, &field, &wanted, None, wide);
    assert_eq!(narrow, reference);
    let everyone_common = Reaches {
        span: 1.0,
        ..reaches
    };
    let short = kernels_reaching(
        &sorted,
        &sorted_halves,
        &field,
        &wanted,
        None,
        everyone_common,
    );
    assert_ne!(
        short, reference,
        "a gather of one half-block misses neighbours"
    );
}

/// The weighted covariance of particle `i`, straight from its definition over every
/// pair (O(N²)): (neighbours, mean offset, covariance).
fn oracle(positions: &[Vec3], i: usize, radius: f64) -> (u32, DVec3, DMat3) {
    let x = positions[i].as_dvec3();
    let near: Vec<(f64, DVec3)> = positions
        .iter()
        .map(|q| q.as_dvec3() - x)
        .filter(|d| d.length() < radius)
        .map(|d| (1.0 - (d.length() / radius).powi(3), d))
        .collect();
    let sw: f64 = near.iter().map(|n| n.0).sum();
    let mean = near.iter().map(|n| n.0 * n.1).sum::<DVec3>() / sw;
    let mut cov = DMat3::ZERO;
    for (w, d) in &near {
        let e = *d - mean;
        cov += DMat3::from_cols(e * e.x, e * e.y, e * e.z) * (*w / sw);
    }
    let count = near.iter().filter(|n| n.1.length() > 0.0).count() as u32;
    (count, mean, cov)
}

#[test]
fn kernels_match_the_covariance_computed_pair_by_pair() {
    // A jittered slab with a free top face, a few strays and a short filament.
    let r = 0.01f32;
    let mut rng = crate::test_rng::TestRng::new(9);
    let mut positions = Vec::new();
    for z in 0..9 {
        for y in 0..5 {
            for x in 0..9 {
                let j = Vec3::new(rng.unit_f32(), rng.unit_f32(), rng.unit_f32()) - 0.5;
                positions.push((Vec3::new(x as f32, y as f32, z as f32) * 2.0 + j * 0.4) * r);
            }
        }
    }
    for k in 0..6 {
        positions.push(Vec3::new(0.3 + 0.02 * k as f32, 0.3, 0.05));
    }
    let mut options = anisotropic(r);
    options.anisotropy.centre_smoothing = 0.4;
    let (kernels, stats) = compute_kernels(&positions, &options).unwrap();
    assert_eq!(stats.particles, positions.len());
    assert!(stats.spherical >= 6, "the filament has too few neighbours");
    let radius = options.influence_radius_world();
    let a = &options.anisotropy;
    let (mut stretched, mut checked) = (0, 0);
    for (i, k) in kernels.iter().enumerate() {
        let (count, mean, cov) = oracle(&positions, i, radius);
        assert_eq!(k.neighbours, count, "particle {i}");
        let mut shift = mean * a.centre_smoothing as f64;
        let cap = a.max_shift as f64 * r as f64;
        if shift.length() > cap {
            shift *= cap / shift.length();
        }
        let centre = positions[i].as_dvec3() + shift;
        assert!(
            (k.centre.as_dvec3() - centre).length() < 1e-6,
            "particle {i}"
        );
        let h_a = a.kernel_radius as f64 * r as f64;
        if count < a.min_neighbours {
            assert!(k.axes.iter().all(|&x| (x as f64 - h_a).abs() < 1e-6));
            continue;
        }
        // Eigen-decomposition of the oracle's matrix by another route: the axes
        // must satisfy C v = σ v with σ ∝ the axis before clamping, and the volume
        // of the ellipsoid is that of the sphere of radius h_a.
        let volume = k.axes.iter().map(|&x| x as f64).product::<f64>();
        assert!((volume / h_a.powi(3) - 1.0).abs() < 1e-4, "particle {i}");
        assert!(k.axes[0] as f64 / k.axes[2] as f64 <= a.max_stretch as f64 * (1.0 + 1e-5));
        let s1 = (cov * k.directions[0].as_dvec3()).length();
        let v0 = k.directions[0].as_dvec3();
        assert!(
            (cov * v0 - v0 * s1).length() <= 1e-4 * s1,
            "particle {i}: the longest axis is not the top eigenvector"
        );
        // Unclamped axes are proportional to their eigenvalues.
        let v2 = k.directions[2].as_dvec3();
        let s3 = v2.dot(cov * v2);
        if s3 > s1 / a.max_stretch as f64 {
            let ratio = k.axes[0] as f64 / k.axes[2] as f64;
            assert!((ratio - s1 / s3).abs() < 1e-3 * ratio, "particle {i}");
        }
        if k.axes[0] > 1.2 * k.axes[2] {
            stretched += 1;
        }
        checked += 1;
    }
    // The top and bottom faces' particles are stretched along the slab.
    assert!(checked > 300 && stretched > 100, "{checked} {stretched}");
}

#[test]
fn degenerate_neighbourhoods_give_finite_clamped_kernels() {
    let r = 0.01f32;
    let options = anisotropic(r);
    let a = &options.anisotropy;
    let h_a = a.kernel_radius * r;
    let line: Vec<Vec3> = (0..30)
        .map(|k| Vec3::new(k as f32 * 0.5 * r, 0.1, 0.2))
        .collect();
    let plane: Vec<Vec3> = (0..400)
        .map(|k| Vec3::new((k % 20) as f32, 0.0, (k / 20) as f32) * 2.0 * r)
        .collect();
    let pair = vec![Vec3::ZERO, Vec3::new(r, 0.0, 0.0)];
    let coincident = vec![Vec3::splat(0.5); 12];
    for (name, cloud) in [
        ("collinear", line),
        ("coplanar", plane),
        ("one neighbour", pair),
        ("coincident", coincident),
    ] {
        let (kernels, _) = compute_kernels(&cloud, &options).unwrap();
        for k in &kernels {
            assert!(
                k.axes.iter().all(|x| x.is_finite() && *x > 0.0)
                    && k.centre.is_finite()
                    && k.directions.iter().all(|d| d.is_finite()),
                "{name}: {k:?}"
            );
            let ratio = k.axes[0] / k.axes[2];
            assert!(ratio <= a.max_stretch * 1.0001, "{name}: {k:?}");
            let volume: f32 = k.axes.iter().product();
            assert!((volume / h_a.powi(3) - 1.0).abs() < 1e-3, "{name}: {k:?}");
            let form = k.quadratic_form(1.0);
            assert!(form.iter().all(|v| v.is_finite()), "{name}");
        }
        match name {
            // A line: the long axis along it, the two others clamped to k_r.
            "collinear" => {
                let k = &kernels[15];
                assert!(k.directions[0].x.abs() > 0.999, "{k:?}");
                assert!(
                    (k.axes[0] / k.axes[1] - a.max_stretch).abs() < 1e-3,
                    "{k:?}"
                );
            }
            // A plane: the short axis across it, clamped.
            "coplanar" => {
                let k = &kernels[210];
                assert!(k.directions[2].y.abs() > 0.999, "{k:?}");
                assert!(
                    (k.axes[0] / k.axes[2] - a.max_stretch).abs() < 1e-2,
                    "{k:?}"
                );
            }
            // Too few neighbours (or none apart from coincident copies): spheres.
            _ => assert!(kernels.iter().all(|k| k.axes == [h_a; 3]), "{name}"),
        }
    }
}
