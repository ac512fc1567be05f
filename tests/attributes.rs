//! Particle attributes on the surface: the kernel-weighted mean of the particles within R
//! at every final vertex, the same for any tiling and thread count, with clear errors for
//! bad attributes.

mod support;

use glam::{DVec3, Mat3, Vec3};
use meniscus::attributes::{Attribute, AttributeSelection};
use meniscus::io::particles::{read_particles, write_particles, ParticleFormat, Particles};
use meniscus::mesh::Surface;
use meniscus::pipeline::{reconstruct_source, ReconstructOptions, ReconstructionStats};
use meniscus::tiles::TileOptions;
use meniscus::CancelToken;
use std::path::Path;
use support::{
    dataset, dir_with_temp, in_pool, interrupt_once_spilled, meniscus, names_in, positions,
};

/// Particles at `positions` with a vector `velocity = f(x)` and a scalar `density`.
fn with_fields(
    positions: Vec<Vec3>,
    f: impl Fn(Vec3) -> Vec3,
    density: impl Fn(Vec3) -> f32,
) -> Particles {
    let velocity = Attribute {
        name: "velocity".into(),
        components: 3,
        values: positions.iter().flat_map(|p| f(*p).to_array()).collect(),
    };
    let density = Attribute {
        name: "density".into(),
        components: 1,
        values: positions.iter().map(|p| density(*p)).collect(),
    };
    Particles {
        positions,
        attributes: vec![velocity, density],
    }
}

fn run(
    particles: Particles,
    options: &ReconstructOptions,
    threads: usize,
) -> (Surface, ReconstructionStats) {
    in_pool(threads, || {
        reconstruct_source(particles, options, &|_| {}, &CancelToken::new()).unwrap()
    })
}

fn bits(values: &[f32]) -> Vec<u32> {
    values.iter().map(|v| v.to_bits()).collect()
}

#[test]
fn a_constant_attribute_is_reproduced_at_every_vertex_and_sphere() {
    let c = Vec3::new(1.5, -2.25, 0.125);
    for rel in ["analytic/sphere.xyz", "analytic/droplets.xyz"] {
        let particles = with_fields(positions(rel), |_| c, |_| 997.0);
        let (surface, _) = run(particles, &ReconstructOptions::new(0.025), 2);
        let fluid = &surface.fluid;
        assert_eq!(fluid.attributes.len(), 2, "{rel}");
        let (v, d) = (&fluid.attributes[0], &fluid.attributes[1]);
        assert_eq!((v.name.as_str(), v.components), ("velocity", 3));
        assert_eq!((d.name.as_str(), d.components), ("density", 1));
        assert_eq!(v.len(), fluid.vertex_count());
        assert_eq!(d.len(), fluid.vertex_count());
        // The weights sum to one: a constant comes back to f32 rounding.
        for i in 0..fluid.vertex_count() {
            let got = Vec3::from_slice(v.item(i));
            assert!(
                (got - c).abs().max_element() <= 4.0 * f32::EPSILON * 2.25,
                "{rel} vertex {i}: {got}"
            );
            assert!((d.item(i)[0] - 997.0).abs() <= 4.0 * f32::EPSILON * 997.0);
        }
        // A sphere takes its particle's value exactly.
        let spheres = &surface.spheres;
        if rel.contains("droplets") {
            assert!(
                !spheres.centers.is_empty(),
                "droplets have isolated particles"
            );
        }
        if !spheres.centers.is_empty() {
            assert_eq!(spheres.attributes.len(), 2);
            assert_eq!(spheres.attributes[0].len(), spheres.centers.len());
            for i in 0..spheres.centers.len() {
                assert_eq!(spheres.attributes[0].item(i), &c.to_array());
                assert_eq!(spheres.attributes[1].item(i), &[997.0]);
            }
        }
    }
}

/// The kernel-weighted mean of `particles` within `radius` of `x` (f64, brute force).
fn weighted_mean_position(particles: &[Vec3], x: Vec3, radius: f64) -> Option<DVec3> {
    let (mut sum, mut weights) = (DVec3::ZERO, 0.0);
    for p in particles {
        let d2 = (p.as_dvec3() - x.as_dvec3()).length_squared();
        if d2 < radius * radius {
            let q = 1.0 - d2 / (radius * radius);
            sum += q * q * q * p.as_dvec3();
            weights += q * q * q;
        }
    }
    (weights > 0.0).then(|| sum / weights)
}

#[test]
fn a_linear_velocity_field_is_the_field_at_the_weighted_mean_position() {
    // v = A·x + b. The weighted mean of a linear function is the function at the weighted
    // mean position x̄, which lies within R of the vertex: |v − (A·x + b)| ≤ ‖A‖·R.
    let a = Mat3::from_cols(
        Vec3::new(0.3, 2.0, -0.4),
        Vec3::new(-1.2, 0.1, 0.9),
        Vec3::new(0.5, -0.7, 1.1),
    );
    let b = Vec3::new(0.2, -0.1, 0.05);
    let norm_a = a.to_cols_array().iter().map(|v| v * v).sum::<f32>().sqrt() as f64;
    let r = 0.025f32;
    let options = ReconstructOptions::new(r);
    let radius = options.field.influence_radius_world();
    for rel in ["analytic/sphere.xyz", "analytic/box.xyz"] {
        let cloud = positions(rel);
        let particles = with_fields(cloud.clone(), |x| a * x + b, |x| x.y);
        let (surface, _) = run(particles, &options, 2);
        let fluid = &surface.fluid;
        let v = &fluid.attributes[0];
        let mut checked = 0;
        for (i, x) in fluid.positions.iter().enumerate() {
            let got = Vec3::from_slice(v.item(i)).as_dvec3();
            let exact = (a * *x + b).as_dvec3();
            assert!(
                (got - exact).length() <= norm_a * radius * (1.0 + 1e-4),
                "{rel} vertex {i}: {got} against {exact}"
            );
            // Against a brute-force oracle on a sample of the vertices.
            if i % 17 == 0 {
                let mean = weighted_mean_position(&cloud, *x, radius).expect("a particle within R");
                let oracle = a.as_dmat3() * mean + b.as_dvec3();
                assert!(
                    (got - oracle).length() <= 2e-5,
                    "{rel} vertex {i}: {got} against {oracle}"
                );
                let density = fluid.attributes[1].item(i)[0] as f64;
                assert!((density - mean.y).abs() <= 1e-5, "{rel} vertex {i}");
                checked += 1;
            }
        }
        assert!(checked > 100, "{rel}: {checked}");
    }
}

#[test]
fn attributes_do_not_depend_on_tiling_or_thread_count() {
    let particles = read_particles(&dataset("dambreak_small/ParticleData_Fluid_25.vtk"), None)
        .unwrap()
        .select(Path::new("frame 25"), &AttributeSelection::All)
        .unwrap();
    assert_eq!(particles.attributes[0].name, "velocity");
    // Marching cubes and one Loop step: the mesh is the same for every tiling, so the
    // attributes must be too, bit for bit.
    let mut raw = ReconstructOptions::raw(0.012);
    raw.subdivide.levels = 1;
    let (whole, _) = run(particles.clone(), &raw, 2);
    let velocity = &whole.fluid.attributes[0];
    assert_eq!(velocity.len(), whole.fluid.vertex_count());
    assert!(
        velocity.values.iter().any(|v| v.abs() > 0.1),
        "a moving fluid"
    );
    for tile in [32, 64] {
        let mut tiled = raw.clone();
        tiled.tiles = TileOptions::tile_size(tile);
        let (pieces, stats) = run(particles.clone(), &tiled, 2);
        assert!(stats.tiles.tiles > 1);
        assert_eq!(
            bits(&pieces.fluid.attributes[0].values),
            bits(&velocity.values),
            "tile {tile}"
        );
        assert_eq!(
            pieces.spheres.attributes, whole.spheres.attributes,
            "tile {tile}"
        );
    }
    // The full pipeline on one thread and on three.
    let full = ReconstructOptions::new(0.012);
    let (one, _) = run(particles.clone(), &full, 1);
    let (three, _) = run(particles, &full, 3);
    assert_eq!(one.fluid.positions, three.fluid.positions);
    assert_eq!(
        bits(&one.fluid.attributes[0].values),
        bits(&three.fluid.attributes[0].values)
    );
}

#[test]
fn separate_bodies_keep_their_own_values() {
    // Two particles far apart and isolation off: each becomes a small blob, and every
    // vertex of a blob takes its own particle's value, exactly.
    let particles = Particles {
        positions: vec![Vec3::ZERO, Vec3::new(1.0, 0.0, 0.0)],
        attributes: vec![Attribute {
            name: "id".into(),
            components: 1,
            values: vec![3.0, 7.0],
        }],
    };
    let mut options = ReconstructOptions::raw(0.025);
    options.isolated_sphere_level = None;
    let (surface, _) = run(particles, &options, 2);
    let ids = &surface.fluid.attributes[0];
    assert!(surface.fluid.vertex_count() > 10);
    for (i, p) in surface.fluid.positions.iter().enumerate() {
        let expected = if p.x < 0.5 { 3.0 } else { 7.0 };
        assert_eq!(ids.item(i)[0], expected, "vertex {i} at {p}");
    }
}

/// Runs the CLI expecting a failure of a file or its content (exit 1); returns stderr
/// after checking that no output exists.
fn fails(args: &[&str], input: &Path, out: &Path) -> String {
    fails_with(1, args, input, out)
}

/// [`fails`] with exit code `code` (2: an option that cannot work).
fn fails_with(code: i32, args: &[&str], input: &Path, out: &Path) -> String {
    let result = meniscus()
        .arg("reconstruct")
        .arg(input)
        .args(args)
        .arg("-o")
        .arg(out)
        .output()
        .unwrap();
    assert_eq!(result.status.code(), Some(code), "{args:?}");
    assert!(!out.exists(), "{args:?} left {}", out.display());
    String::from_utf8_lossy(&result.stderr).into_owned()
}

#[test]
fn bad_attributes_are_clear_errors_naming_the_file_and_attribute() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s.ply");
    let vtk = dataset("dambreak_small/ParticleData_Fluid_25.vtk");
    // A name the input lacks: the error lists what it has.
    let err = fails(
        &["-r", "0.012", "--attributes", "velocity,pressure"],
        &vtk,
        &out,
    );
    assert!(err.contains("ParticleData_Fluid_25.vtk"), "{err}");
    assert!(
        err.contains("\"pressure\"") && err.contains("has: velocity"),
        "{err}"
    );
    // Raw positions hold none.
    let xyz = dataset("dambreak_small/ParticleData_Fluid_25.xyz");
    let err = fails(&["-r", "0.012", "--attributes", "velocity"], &xyz, &out);
    assert!(err.contains("no point attributes"), "{err}");
    // An empty list: an option that cannot work.
    let err = fails_with(2, &["-r", "0.012", "--attributes", "velocity,"], &vtk, &out);
    assert!(err.contains("--attributes"), "{err}");
    // NaN in an attribute.
    let mut particles = read_particles(&vtk, None).unwrap();
    particles.attributes[0].values[3 * 1234 + 1] = f32::NAN;
    let bad = dir.path().join("nan.vtk");
    write_particles(&bad, &particles, ParticleFormat::Vtk).unwrap();
    let err = fails(&["-r", "0.012"], &bad, &out);
    assert!(
        err.contains("nan.vtk") && err.contains("\"velocity\""),
        "{err}"
    );
    assert!(
        err.contains("particle 1234") && err.contains("non-finite"),
        "{err}"
    );
    // `none` skips the check and the attribute.
    let status = meniscus()
        .arg("reconstruct")
        .arg(&bad)
        .args(["-r", "0.012", "-q", "--attributes", "none", "-o"])
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success());
    // An attribute of the wrong length, through the library.
    let mut short = read_particles(&vtk, None).unwrap();
    short.attributes[0].values.pop();
    let err = short
        .select(&vtk, &AttributeSelection::Velocity)
        .unwrap_err();
    assert!(err.to_string().contains("\"velocity\""), "{err}");
}

#[test]
fn an_obj_output_warns_once_that_it_drops_the_attributes() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s.obj");
    let result = meniscus()
        .arg("reconstruct")
        .arg(dataset("dambreak_small/ParticleData_Fluid_25.vtk"))
        .args(["-r", "0.012", "-q", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(result.status.success());
    let err = String::from_utf8_lossy(&result.stderr);
    assert_eq!(err.matches("warning").count(), 1, "{err}");
    assert!(err.contains("velocity") && err.contains("s.obj"), "{err}");
    assert!(out.exists());
}

#[test]
fn spilled_runs_with_attributes_leave_no_temporary_file_on_success_error_or_ctrl_c() {
    let (dir, temp) = dir_with_temp();
    let vtk = dataset("dambreak_small/ParticleData_Fluid_25.vtk");
    let tiled = |out: &Path, tile: &str| {
        let mut cmd = meniscus();
        cmd.arg("reconstruct")
            .arg(&vtk)
            .args(["-r", "0.012", "-q", "--tile-size", tile, "--temp-dir"])
            .arg(&temp)
            .arg("-o")
            .arg(out);
        cmd
    };
    // Success: the velocity is in the output.
    let out = dir.path().join("s.ply");
    assert!(tiled(&out, "64").status().unwrap().success());
    let bytes = std::fs::read(&out).unwrap();
    let header = String::from_utf8_lossy(&bytes[..400]);
    assert!(header.contains("property float velocity_x"), "{header}");
    assert!(names_in(&temp).is_empty(), "{:?}", names_in(&temp));
    // An error after the spill (the output is a directory).
    let blocked = dir.path().join("blocked.ply");
    std::fs::create_dir(&blocked).unwrap();
    let result = tiled(&blocked, "64").output().unwrap();
    assert_eq!(result.status.code(), Some(1));
    assert!(names_in(&temp).is_empty(), "{:?}", names_in(&temp));
    // Ctrl-C during one-block tiles.
    let out = dir.path().join("c.ply");
    let mut child = tiled(&out, "8")
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    interrupt_once_spilled(&mut child, &temp);
    let result = child.wait_with_output().unwrap();
    assert_eq!(result.status.code(), Some(130));
    assert!(String::from_utf8_lossy(&result.stderr).contains("interrupted"));
    assert!(!out.exists());
    assert!(names_in(&temp).is_empty(), "{:?}", names_in(&temp));
}
