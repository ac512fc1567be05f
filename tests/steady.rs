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
    // Measured (this ruler, frame 41): steady 0.128° / 0.562° (0.129° / 0.574° with the
    // inward bound at 0.35 r before 2026-12-02), still default 0.318° / 1.211°.
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
