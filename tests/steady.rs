//! The steady surface ([`ReconstructOptions::steady`], the default for sequences): its
//! shading normals flicker less from frame to frame than the still default's, it stays a
//! closed manifold with every centre inside, and it is as large as `docs/quality.md` says.
//! Three consecutive frames of the shipped pool sequence (60 fps, r = 0.01).

mod support;

use meniscus::mesh::{validate, TriMesh};
use meniscus::pipeline::{reconstruct, ReconstructOptions};
use support::flicker::normal_flicker;

const R: f32 = 0.01;

fn surfaces(options: &ReconstructOptions) -> Vec<TriMesh> {
    (40..=42)
        .map(|k| {
            let positions = support::positions(&format!("splash_pool/ParticleData_Fluid_{k}.xyz"));
            let (surface, stats) = reconstruct(&positions, options).unwrap();
            if options.containment.is_some() {
                assert_eq!(
                    stats.containment.as_ref().unwrap().remaining,
                    0,
                    "frame {k}"
                );
            }
            surface.fluid
        })
        .collect()
}

#[test]
fn the_steady_surface_flickers_less_than_the_still_default() {
    let steady = surfaces(&ReconstructOptions::steady(R));
    let still = surfaces(&ReconstructOptions::new(R));
    for mesh in &steady {
        assert!(validate(mesh).is_closed_manifold());
    }
    let near = R as f64;
    let (steady_mean, steady_p95, kept) =
        normal_flicker(&steady[0], &steady[1], &steady[2], near, 40_000);
    let (still_mean, still_p95, _) = normal_flicker(&still[0], &still[1], &still[2], near, 40_000);
    eprintln!(
        "N2 mean / p95: steady {steady_mean:.3}° / {steady_p95:.3}°, still default \
         {still_mean:.3}° / {still_p95:.3}° (kept {kept:.3})"
    );
    assert!(kept > 0.98, "{kept}");
    // Measured (this ruler, frame 41): steady 0.141° / 0.624° (0.128° / 0.562° before the
    // feature weights, session 18; 0.129° / 0.574° with the inward bound at 0.35 r before
    // 2026-12-02), still default 0.317° / 1.210°.
    assert!(
        steady_mean < 0.17 && steady_p95 < 0.7,
        "{steady_mean} {steady_p95}"
    );
    assert!(
        steady_mean < 0.6 * still_mean,
        "{steady_mean} vs {still_mean}"
    );
    assert!(steady_p95 < 0.6 * still_p95, "{steady_p95} vs {still_p95}");
}

/// Dimples on gently curved water: at `samples` points on `mesh`, the area-weighted mean
/// angle between the face normals within `ball` and their mean normal (degrees); the 90th
/// percentile over the flattest three quarters of the points (what a render of gently
/// curved water shows; shared/eval's `multiscale_bump.py` fits planes instead).
fn dimples(mesh: &TriMesh, ball: f64, samples: usize) -> f64 {
    use glam::{DVec3, IVec3};
    use std::collections::HashMap;
    let faces: Vec<(DVec3, DVec3)> = mesh
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize].as_dvec3());
            ((a + b + c) / 3.0, (b - a).cross(c - a))
        })
        .collect();
    let cell = |p: DVec3| (p / ball).floor().as_ivec3();
    let mut grid: HashMap<IVec3, Vec<usize>> = HashMap::new();
    for (i, (centre, _)) in faces.iter().enumerate() {
        grid.entry(cell(*centre)).or_default().push(i);
    }
    let mut deviations: Vec<f64> = support::flicker::sample(mesh, samples, 11)
        .into_iter()
        .map(|(_, x)| {
            let c = cell(x);
            let near: Vec<&(DVec3, DVec3)> = (-1..=1)
                .flat_map(|i| {
                    (-1..=1).flat_map(move |j| (-1..=1).map(move |k| IVec3::new(i, j, k)))
                })
                .filter_map(|d| grid.get(&(c + d)))
                .flatten()
                .map(|&f| &faces[f])
                .filter(|(centre, _)| centre.distance(x) <= ball)
                .collect();
            let mean = near.iter().map(|(_, n)| *n).sum::<DVec3>().normalize();
            let area: f64 = near.iter().map(|(_, n)| n.length()).sum();
            near.iter()
                .map(|(_, n)| n.length() * n.normalize().dot(mean).clamp(-1.0, 1.0).acos())
                .sum::<f64>()
                .to_degrees()
                / area
        })
        .collect();
    deviations.sort_by(f64::total_cmp);
    let flattest = &deviations[..deviations.len() * 3 / 4];
    flattest[flattest.len() * 9 / 10]
}

#[test]
fn the_steady_surface_keeps_a_resting_blocks_faces_flat() {
    // Dam break frame 1: a block of water at rest. Plain steps round its edges, and the
    // faces beside them tilt towards the rounding (dimples a render shows); the feature
    // weights keep the edges, and the faces flat.
    let r = 0.012;
    let positions = support::positions("dambreak_small/ParticleData_Fluid_1.xyz");
    let steady = ReconstructOptions::steady(r);
    let mut plain = steady.clone();
    plain.smooth.as_mut().unwrap().feature_angle = None;
    let [weighted, plain] = [steady, plain].map(|options| {
        let (surface, _) = reconstruct(&positions, &options).unwrap();
        assert!(validate(&surface.fluid).is_closed_manifold());
        dimples(&surface.fluid, 3.0 * r as f64, 4000)
    });
    eprintln!("dimples (3 r): feature weights {weighted:.3}°, plain steps {plain:.3}°");
    // Measured: 0.218° against 0.728° (shared/eval's multiscale_bump.py: 0.23° against
    // 0.66°, splashsurf smoothed 0.24°).
    assert!(weighted < 0.6 * plain, "{weighted} vs {plain}");
}
