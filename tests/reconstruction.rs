//! End-to-end invariants of the reconstruction on the shipped datasets (`datasets/`):
//! closed 2-manifold output, distance to analytic surfaces, particles inside the surface,
//! thread-count independence.

mod support;

use glam::Vec3;
use meniscus::mesh::{validate, InsideTest, TriMesh};
use meniscus::pipeline::{reconstruct, ReconstructOptions};
use support::split_isolated;
use support::{in_pool, positions};

/// Field + marching cubes only (no decimation or subdivision), isolated spheres on.
/// Field, marching cubes and spheres with the paper's (isotropic) field, which these
/// tests describe.
fn raw_options(r: f32) -> ReconstructOptions {
    let mut options = ReconstructOptions::raw(r);
    options.field.kernel = meniscus::field::Kernel::Isotropic;
    options
}

fn assert_closed_manifold(mesh: &TriMesh, what: &str) {
    let report = validate(mesh);
    assert!(report.is_closed_manifold(), "{what}: {report:?}");
    assert_eq!(report.unreferenced_vertices, 0, "{what}");
    assert!(mesh.signed_volume() > 0.0, "{what}: outward orientation");
}

fn median_edge(mesh: &TriMesh) -> f32 {
    let mut lengths: Vec<f32> = mesh
        .triangles
        .iter()
        .map(|t| (mesh.positions[t[0] as usize] - mesh.positions[t[1] as usize]).length())
        .collect();
    lengths.sort_by(f32::total_cmp);
    lengths[lengths.len() / 2]
}

#[test]
fn analytic_sphere_is_one_closed_component_near_the_true_sphere() {
    let r = 0.025f32;
    let (surface, _) = reconstruct(&positions("analytic/sphere.xyz"), &raw_options(r)).unwrap();
    let mesh = &surface.fluid;
    assert_closed_manifold(mesh, "sphere");
    assert_eq!(validate(mesh).components, 1);
    assert!(surface.spheres.centers.is_empty());
    // Inside: the particles fill the lattice cubes strictly inside radius 0.5, jittered by
    // 0.1 r, so the particle envelope is a staircase whose dents reach about one lattice
    // cube (2r) below the sphere; the Solenthaler surface sits about r outside the
    // outermost centres and smooths the dents. Measured: 0.62 r below.
    // Outside: outermost centres lie on the sphere (up to 0.5004); coverage encloses such
    // a particle in a ball of 0.9 r where the paper's surface would cut through it, plus at
    // most a few hundredths of r of marching-cubes interpolation error. Measured: 0.83 r.
    let (mut below, mut above) = (0.0f32, 0.0f32);
    for p in &mesh.positions {
        let d = p.length() - 0.5;
        below = below.max(-d);
        above = above.max(d);
    }
    assert!(
        below < 0.75 * r,
        "max depth below the sphere {} r",
        below / r
    );
    assert!(
        above < 0.95 * r,
        "max height above the sphere {} r",
        above / r
    );
    // Volume: the particles' cubes hold 0.528 (0.8 % above the sphere's 0.5236); measured
    // mesh volume is 1.4 % below. Allow 3 %.
    let exact = 4.0 / 3.0 * std::f64::consts::PI * 0.125;
    let rel = mesh.signed_volume() / exact - 1.0;
    assert!(rel.abs() < 0.03, "volume error {rel}");
}

#[test]
fn analytic_box_is_one_closed_component_near_the_true_box() {
    let r = 0.025f32;
    let (surface, _) = reconstruct(&positions("analytic/box.xyz"), &raw_options(r)).unwrap();
    let mesh = &surface.fluid;
    assert_closed_manifold(mesh, "box");
    assert_eq!(validate(mesh).components, 1);
    let half = Vec3::new(0.5, 0.3, 0.2);
    // Distance to the box surface; edges and corners are rounded by the kernel (radius
    // of curvature about R = 4r), which puts vertices near edges inside the box, and
    // corners up to (√3 − 1)·R·0.5 ≈ 1.5 r inside.
    let mut max_flat = 0.0f32;
    let mut max_any = 0.0f32;
    for p in &mesh.positions {
        let q = p.abs() - half;
        let outside = q.max(Vec3::ZERO).length();
        let dist = if outside > 0.0 {
            outside
        } else {
            -q.max_element()
        };
        max_any = max_any.max(dist);
        // Flat regions: at least 3r from every box edge.
        let near_edge = {
            let m = half - p.abs();
            let mut s = [m.x, m.y, m.z];
            s.sort_by(f32::total_cmp);
            s[1] < 3.0 * r
        };
        if !near_edge {
            max_flat = max_flat.max(dist);
        }
    }
    assert!(
        max_flat < 0.5 * r,
        "flat-region deviation {} r",
        max_flat / r
    );
    assert!(max_any < 1.6 * r, "any deviation {} r", max_any / r);
    let rel = mesh.signed_volume() / 0.24 - 1.0;
    assert!(rel.abs() < 0.08, "volume error {rel}");
}

fn check_frame(rel: &str, r: f32) {
    let particles = positions(rel);
    let options = raw_options(r);
    let (surface, stats) = reconstruct(&particles, &options).unwrap();
    assert_closed_manifold(&surface.fluid, rel);
    let (fluid, isolated) =
        split_isolated(&particles, options.field.influence_radius_world() as f32);
    assert_eq!(isolated.len(), stats.isolated_particles, "{rel}");
    let inside = InsideTest::new(&surface.fluid, 2.0 * median_edge(&surface.fluid));
    let outside: Vec<usize> = (0..fluid.len())
        .filter(|&i| !inside.contains(fluid[i]))
        .collect();
    assert!(
        outside.is_empty(),
        "{rel}: {} particles outside, first {:?}",
        outside.len(),
        &outside[..outside.len().min(5)]
    );
}

#[test]
fn every_dambreak_frame_is_closed_with_all_particles_inside() {
    for k in [1, 9, 17, 25, 31, 45] {
        check_frame(&format!("dambreak_small/ParticleData_Fluid_{k}.xyz"), 0.012);
    }
}

#[test]
fn every_double_dambreak_frame_is_closed_with_all_particles_inside() {
    for k in [1, 6, 9, 13, 20] {
        check_frame(
            &format!("double_dambreak/ParticleData_Fluid_{k}.xyz"),
            0.025,
        );
    }
}

#[test]
fn reconstruction_does_not_depend_on_thread_count() {
    let particles = positions("dambreak_small/ParticleData_Fluid_31.xyz");
    let run = |threads: usize| {
        in_pool(threads, || {
            reconstruct(&particles, &ReconstructOptions::new(0.012))
                .unwrap()
                .0
        })
    };
    let one = run(1);
    assert!(one.fluid.triangle_count() > 10_000);
    assert_eq!(one, run(2));
    assert_eq!(one, run(4));
}

#[test]
fn the_iso_offset_moves_the_surface_outwards_onto_the_true_box() {
    // The paper's surface lies inside the outer particles; an offset of 0.133 r moves it
    // out (by 0.19 r on these faces): the flat faces then sit on the true box faces.
    let r = 0.025f32;
    let particles = positions("analytic/box.xyz");
    let half = Vec3::new(0.5, 0.3, 0.2);
    // Mean signed distance (positive outside) of the vertices of the flat faces (at least
    // 3r from every box edge) to the true box.
    let flat_offset = |iso_offset: f32| -> (f32, f64) {
        let mut options = raw_options(r);
        options.field.iso_offset = iso_offset;
        let (surface, _) = reconstruct(&particles, &options).unwrap();
        assert_closed_manifold(&surface.fluid, "box");
        let (mut sum, mut n) = (0.0f32, 0);
        for p in &surface.fluid.positions {
            let m = half - p.abs();
            let mut s = [m.x, m.y, m.z];
            s.sort_by(f32::total_cmp);
            if s[1] >= 3.0 * r {
                sum += -s[0];
                n += 1;
            }
        }
        (sum / n as f32, surface.fluid.signed_volume())
    };
    let (paper, paper_volume) = flat_offset(0.0);
    let (shifted, shifted_volume) = flat_offset(0.133);
    assert!(
        paper < -0.1 * r,
        "paper's flat faces {} r from the box",
        paper / r
    );
    assert!(
        shifted.abs() < 0.05 * r,
        "shifted flat faces {} r from the box",
        shifted / r
    );
    // By δ·r / |∇phi|, with |∇phi| between 1/2 and 1 near the surface.
    let moved = (shifted - paper) / r;
    assert!((0.133..0.27).contains(&moved), "moved by {moved} r");
    assert!((shifted_volume / 0.24 - 1.0).abs() < (paper_volume / 0.24 - 1.0).abs());
    let mut bad = raw_options(r);
    bad.field.iso_offset = 1.5;
    assert!(reconstruct(&particles, &bad).is_err());
}

/// A particle source whose reading panics (a bug in a caller's source, or in ours).
struct PanickingSource;

impl meniscus::io::particles::ParticleSource for PanickingSource {
    fn particle_count(&self) -> usize {
        1000
    }
    fn visit_chunks(
        &self,
        _visit: &mut dyn FnMut(meniscus::io::particles::ParticleChunk<'_>) -> meniscus::Result<()>,
    ) -> meniscus::Result<()> {
        panic!("the source broke at particle 7");
    }
}

#[test]
fn a_panic_inside_reconstruct_is_an_internal_error_not_a_crash() {
    let r = 0.025;
    let options = raw_options(r);
    let cancel = meniscus::CancelToken::new();
    let e = meniscus::pipeline::reconstruct_source(PanickingSource, &options, &|_| {}, &cancel)
        .expect_err("the source panics");
    assert!(
        matches!(&e, meniscus::Error::Internal { message, .. } if message.contains("particle 7")),
        "{e:?}"
    );
    let text = e.to_string();
    assert!(
        text.contains("particles given to reconstruct") && text.contains("internal error"),
        "{text}"
    );
    // The library is still usable afterwards.
    let (surface, _) = reconstruct(&positions("analytic/sphere.xyz"), &options).unwrap();
    assert!(!surface.fluid.triangles.is_empty());
}
