//! Surface quality of the full pipeline (default post-processing) on the analytic
//! datasets, whose true surface is known (`datasets/analytic/*.json`), for both kernels:
//! enclosed volume, normal error against the true normals, waviness, particles inside.
//! The figures these bounds come from are in `docs/quality.md` (measured there with the
//! independent `meshq.py`; the measures here are simpler and computed in the test).

mod support;

use glam::DVec3;
use meniscus::field::Kernel;
use meniscus::mesh::{InsideTest, TriMesh};
use meniscus::pipeline::{reconstruct, ReconstructOptions};
use support::positions;

fn surface(rel: &str, kernel: Kernel) -> TriMesh {
    let mut options = ReconstructOptions::new(0.025);
    options.field.kernel = kernel;
    let (surface, _) = reconstruct(&positions(rel), &options).unwrap();
    assert!(surface.spheres.centers.is_empty(), "{rel}");
    surface.fluid
}

/// Per triangle: centroid, unit normal and area.
fn faces(mesh: &TriMesh) -> impl Iterator<Item = (DVec3, DVec3, f64)> + '_ {
    mesh.triangles.iter().map(|t| {
        let [a, b, c] = t.map(|i| mesh.positions[i as usize].as_dvec3());
        let n = (b - a).cross(c - a);
        ((a + b + c) / 3.0, n.normalize(), n.length() / 2.0)
    })
}

/// Area-weighted mean angle (degrees) between the face normals and the true normals
/// `truth(centroid)` over the faces where `truth` gives one.
fn normal_error(mesh: &TriMesh, truth: impl Fn(DVec3) -> Option<DVec3>) -> f64 {
    let (mut sum, mut area) = (0.0, 0.0);
    for (c, n, a) in faces(mesh) {
        if let Some(t) = truth(c) {
            sum += a * n.dot(t).clamp(-1.0, 1.0).acos().to_degrees();
            area += a;
        }
    }
    assert!(area > 0.0);
    sum / area
}

/// True outward normal of the box [lo, hi] at `c`, on faces only: `None` within `margin`
/// of an edge.
fn box_normal(c: DVec3, lo: DVec3, hi: DVec3, margin: f64) -> Option<DVec3> {
    let centre = (lo + hi) / 2.0;
    let half = (hi - lo) / 2.0;
    let d = (c - centre).abs() - half;
    let axis = (0..3).max_by(|&a, &b| d[a].total_cmp(&d[b]))?;
    let others_clear = (0..3).filter(|&a| a != axis).all(|a| d[a] < -margin);
    others_clear.then(|| {
        let mut n = DVec3::ZERO;
        n[axis] = (c[axis] - centre[axis]).signum();
        n
    })
}

struct Figures {
    volume_error: f64,
    normal_error: f64,
    /// RMS of the distance to the true surface about its mean, multiples of r.
    waviness: f64,
}

fn sphere_figures(mesh: &TriMesh) -> Figures {
    let truth = 4.0 / 3.0 * std::f64::consts::PI * 0.125;
    let radii: Vec<f64> = mesh
        .positions
        .iter()
        .map(|p| p.as_dvec3().length())
        .collect();
    let mean = radii.iter().sum::<f64>() / radii.len() as f64;
    let var = radii.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / radii.len() as f64;
    Figures {
        volume_error: mesh.signed_volume() / truth - 1.0,
        normal_error: normal_error(mesh, |c| Some(c.normalize())),
        waviness: var.sqrt() / 0.025,
    }
}

fn box_figures(mesh: &TriMesh) -> Figures {
    let (lo, hi) = (DVec3::new(-0.5, -0.3, -0.2), DVec3::new(0.5, 0.3, 0.2));
    let margin = 3.0 * 0.025;
    let truth = (hi - lo).element_product();
    // Distance to the face plane of vertices on faces (away from edges).
    let heights: Vec<f64> = mesh
        .positions
        .iter()
        .filter_map(|p| {
            let p = p.as_dvec3();
            let n = box_normal(p, lo, hi, margin)?;
            let axis = (0..3).find(|&a| n[a] != 0.0)?;
            Some((p[axis] - if n[axis] > 0.0 { hi[axis] } else { lo[axis] }) * n[axis])
        })
        .collect();
    let mean = heights.iter().sum::<f64>() / heights.len() as f64;
    let var = heights.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / heights.len() as f64;
    Figures {
        volume_error: mesh.signed_volume() / truth - 1.0,
        normal_error: normal_error(mesh, |c| box_normal(c, lo, hi, margin)),
        waviness: var.sqrt() / 0.025,
    }
}

fn assert_particles_inside(mesh: &TriMesh, rel: &str) {
    let inside = InsideTest::new(mesh, 0.05);
    let outside = positions(rel)
        .iter()
        .filter(|p| !inside.contains(**p))
        .count();
    assert_eq!(outside, 0, "{rel}: particle centres outside the surface");
}

#[test]
fn anisotropic_kernels_fill_the_box() {
    let iso = box_figures(&surface("analytic/box.xyz", Kernel::Isotropic));
    let mesh = surface("analytic/box.xyz", Kernel::Anisotropic);
    let aniso = box_figures(&mesh);
    // Measured (meshq, docs/quality.md): isotropic −5.9 % volume, 0.88° on the faces;
    // the default −0.60 %, 0.56° (0.65° without smoothing; 0.97° and −1.0 % when the
    // field took the whole length of v − vbar as depth, sideways parts included).
    assert!(
        iso.volume_error < -0.04,
        "isotropic {:.4}",
        iso.volume_error
    );
    assert!(
        aniso.volume_error.abs() < 0.01,
        "anisotropic volume error {:.4}",
        aniso.volume_error
    );
    assert!(
        aniso.normal_error < 0.6 && aniso.normal_error < iso.normal_error && aniso.waviness < 0.04,
        "faces: anisotropic {:.3}° {:.4} r, isotropic {:.3}°",
        aniso.normal_error,
        aniso.waviness,
        iso.normal_error
    );
    assert_particles_inside(&mesh, "analytic/box.xyz");
}

#[test]
fn anisotropic_kernels_round_the_sphere_better_than_spheres_do() {
    let iso = sphere_figures(&surface("analytic/sphere.xyz", Kernel::Isotropic));
    let mesh = surface("analytic/sphere.xyz", Kernel::Anisotropic);
    let aniso = sphere_figures(&mesh);
    // The particles fill a lattice staircase inside the sphere: its facets are what both
    // kernels follow; the stretched kernels bridge more of them (measured 7.0° against
    // 9.7°), which also adds volume: +5.0 % (the particles' own cubes are +0.8 % over the
    // sphere, the isotropic surface −1.2 %).
    assert!(
        aniso.normal_error < 0.8 * iso.normal_error && aniso.normal_error < 8.0,
        "normal error: anisotropic {:.2}°, isotropic {:.2}°",
        aniso.normal_error,
        iso.normal_error
    );
    assert!(
        aniso.waviness < iso.waviness,
        "waviness: anisotropic {:.3} r, isotropic {:.3} r",
        aniso.waviness,
        iso.waviness
    );
    assert!(
        aniso.volume_error.abs() < 0.055,
        "volume error {:.4}",
        aniso.volume_error
    );
    assert_particles_inside(&mesh, "analytic/sphere.xyz");
}
