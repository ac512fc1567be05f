//! The particle radius estimated from a frame's spacing, and the check of a given radius.

mod support;

use meniscus::io::particles::read_particles;
use meniscus::radius::{check_radius, estimate_radius, estimate_radius_of_file, RadiusCheck};
use std::path::PathBuf;
use support::{dataset, shipped_frames};

/// Every frame shipped in `datasets/` (the simulated frames and the analytic cases) and,
/// where the shared data is on this machine, its frames and splashsurf's examples, with
/// their known radii.
fn frames_with_radii() -> Vec<(PathBuf, f32)> {
    let mut frames: Vec<(PathBuf, f32)> = shipped_frames()
        .into_iter()
        .map(|(rel, r)| (dataset(&rel), r))
        .chain(
            ["sphere", "box", "droplets", "sheet"]
                .iter()
                .map(|c| (dataset(&format!("analytic/{c}.xyz")), 0.025)),
        )
        .collect();
    let shared = PathBuf::from("/work/shared/data");
    if shared.is_dir() {
        for (dir, r) in [("dambreak_small", 0.012), ("double_dambreak", 0.025)] {
            for entry in std::fs::read_dir(shared.join(dir)).unwrap() {
                let path = entry.unwrap().path();
                if path.extension().is_some_and(|e| e == "xyz") {
                    frames.push((path, r));
                }
            }
        }
        for name in [
            "bunny_frame_14_7705_particles.vtk",
            "dam_break_frame_23_24389_particles.bgeo",
            "double_dam_break_frame_26_4732_particles.vtk",
            "hilbert_46843_particles.bgeo",
            "sailors_knot_19539_particles.vtk",
        ] {
            frames.push((shared.join("splashsurf_examples").join(name), 0.025));
        }
    }
    frames
}

#[test]
fn the_estimate_is_within_ten_percent_on_every_shipped_frame() {
    let mut worst = 0f32;
    for (path, r) in frames_with_radii() {
        let e = estimate_radius_of_file(&path, None).unwrap();
        let ratio = e.radius / r;
        println!(
            "{}: {:.3} r (half the nearest distance {:.3} r)",
            path.display(),
            ratio,
            e.half_nearest / r
        );
        assert!((0.9..=1.1).contains(&ratio), "{}: {ratio}", path.display());
        worst = worst.max((ratio - 1.0).abs());
        // Streamed from the file and in memory: the same sample, the same estimate.
        let positions = read_particles(&path, None).unwrap().positions;
        assert_eq!(
            estimate_radius(&positions).unwrap(),
            e,
            "{}",
            path.display()
        );
    }
    println!("worst: {:.1} %", 100.0 * worst);
}

#[test]
fn the_estimate_scales_with_the_frame_and_needs_two_distinct_points() {
    let positions = read_particles(&dataset("double_dambreak/ParticleData_Fluid_9.vtk"), None)
        .unwrap()
        .positions;
    let e = estimate_radius(&positions).unwrap();
    let scaled: Vec<_> = positions
        .iter()
        .map(|p| *p * 1000.0 + glam::Vec3::splat(5.0))
        .collect();
    let big = estimate_radius(&scaled).unwrap();
    assert!(
        (big.radius / e.radius / 1000.0 - 1.0).abs() < 1e-3,
        "{big:?} {e:?}"
    );
    let same = vec![glam::Vec3::ONE; 10];
    let err = estimate_radius(&same).unwrap_err().to_string();
    assert!(
        err.contains("particle_radius") && err.contains("10 particles"),
        "{err}"
    );
    assert!(estimate_radius(&[]).is_err());
}

#[test]
fn a_given_radius_is_plausible_doubtful_or_implausible() {
    for (given, want) in [
        (1.0, RadiusCheck::Plausible),
        (0.25, RadiusCheck::Plausible),
        (4.0, RadiusCheck::Plausible),
        (0.2, RadiusCheck::Doubtful),
        (2.0 * 2.0 + 0.5, RadiusCheck::Doubtful),
        (0.05, RadiusCheck::Doubtful),
        (20.0, RadiusCheck::Doubtful),
        (0.04, RadiusCheck::Implausible),
        (100.0, RadiusCheck::Implausible),
    ] {
        assert_eq!(check_radius(given * 0.025, 0.025), want, "{given}");
    }
}

/// Without `-r` the CLI estimates r from the first frame, prints it, and runs with it: the
/// same mesh as `-r` with the printed value.
#[test]
fn without_r_the_cli_runs_with_the_estimate_it_prints() {
    let dir = tempfile::tempdir().unwrap();
    let input = dataset("double_dambreak/ParticleData_Fluid_9.vtk");
    let input = input.to_str().unwrap();
    let estimated = dir.path().join("e.ply");
    let (ok, err) = support::run(&["reconstruct", input, "-o", estimated.to_str().unwrap()]);
    assert!(ok, "{err}");
    let line = err
        .lines()
        .find(|l| l.starts_with("particle radius r = "))
        .unwrap_or_else(|| panic!("no estimate printed: {err}"));
    assert!(
        line.contains("ParticleData_Fluid_9.vtk") && line.contains("-r sets it"),
        "{line}"
    );
    let r = line["particle radius r = ".len()..]
        .split(' ')
        .next()
        .unwrap();
    let value: f32 = r.parse().unwrap();
    assert!((value / 0.025 - 1.0).abs() < 0.1, "{line}");
    let given = dir.path().join("g.ply");
    let (ok, err) = support::run(&[
        "reconstruct",
        input,
        "-r",
        r,
        "-q",
        "-o",
        given.to_str().unwrap(),
    ]);
    assert!(ok && err.is_empty(), "{err}");
    assert!(std::fs::read(&estimated).unwrap() == std::fs::read(&given).unwrap());
    // Quiet: nothing printed.
    let (ok, err) = support::run(&["reconstruct", input, "-q", "-o", given.to_str().unwrap()]);
    assert!(ok && err.is_empty(), "{err}");
}
