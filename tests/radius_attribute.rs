//! Each particle's radius from a point attribute (issue 37): which attribute is taken,
//! the checks of its values, and the run's radius from it.

mod support;

use meniscus::io::particles::{write_particles, Attribute, ParticleFormat, Particles};
use meniscus::radius::{radii_of, read_radii, RadiusAttribute};
use meniscus::Error;
use std::path::{Path, PathBuf};
use support::{dataset, meniscus, positions};

/// The analytic sphere (r = 0.025) with the attributes `columns` (name, one value per
/// particle from its index), written to `dir/name`.
fn sphere_with(dir: &Path, name: &str, columns: &[(&str, &dyn Fn(usize) -> f32)]) -> PathBuf {
    let positions = positions("analytic/sphere.xyz");
    let attributes = columns
        .iter()
        .map(|(n, f)| Attribute {
            name: n.to_string(),
            components: 1,
            values: (0..positions.len()).map(f).collect(),
        })
        .collect();
    let path = dir.join(name);
    let format = ParticleFormat::from_path(&path).unwrap();
    write_particles(
        &path,
        &Particles {
            positions,
            attributes,
        },
        format,
    )
    .unwrap();
    path
}

/// A radius that differs from particle to particle (0.02 to 0.03).
fn varying(i: usize) -> f32 {
    0.02 + 0.01 * (i % 11) as f32 / 10.0
}

#[test]
fn the_radius_attribute_is_pscale_by_default_or_the_one_named() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["s.vtk", "s.ply", "s.vtu", "s.vtp"] {
        let path = sphere_with(
            dir.path(),
            name,
            &[("radius", &|_| 0.025), ("pscale", &varying)],
        );
        let count = positions("analytic/sphere.xyz").len();
        let pscale = read_radii(&path, None, &RadiusAttribute::default())
            .unwrap()
            .expect("pscale taken by default");
        assert_eq!(pscale.attribute, "pscale", "{name}");
        assert_eq!(pscale.values.len(), count);
        assert!(pscale
            .values
            .iter()
            .enumerate()
            .all(|(i, &v)| v == varying(i)));
        assert_eq!(pscale.range(), (0.02, 0.03), "{name}");
        assert!(!pscale.is_uniform());
        let named = read_radii(&path, None, &"RADIUS".parse().unwrap())
            .unwrap()
            .expect("named, matched ignoring case");
        assert_eq!(named.attribute, "radius");
        assert!(named.is_uniform());
        assert_eq!(named.median(), 0.025);
        assert_eq!(
            read_radii(&path, None, &RadiusAttribute::None).unwrap(),
            None
        );
    }
    // Without pscale the default takes nothing (a `radius` only when named).
    let path = sphere_with(dir.path(), "r.ply", &[("radius", &varying)]);
    assert_eq!(
        read_radii(&path, None, &RadiusAttribute::default()).unwrap(),
        None
    );
    // Raw positions hold no attributes: nothing by default, an error when named.
    let xyz = dataset("analytic/sphere.xyz");
    assert_eq!(
        read_radii(&xyz, None, &RadiusAttribute::default()).unwrap(),
        None
    );
    let err = read_radii(&xyz, None, &"radius".parse().unwrap()).unwrap_err();
    assert!(
        err.to_string().contains("holds no point attributes"),
        "{err}"
    );
    let err = read_radii(&path, None, &"size".parse().unwrap()).unwrap_err();
    assert!(err.to_string().contains("which has: radius"), "{err}");
}

#[test]
fn the_median_is_a_radius_of_the_input() {
    let path = Path::new("particles in memory");
    let radii = |values: Vec<f32>| {
        let count = values.len();
        let a = Attribute {
            name: "radius".into(),
            components: 1,
            values,
        };
        radii_of(path, &[a], count, &"radius".parse().unwrap())
            .unwrap()
            .unwrap()
    };
    assert_eq!(radii(vec![3.0, 1.0, 2.0]).median(), 2.0);
    assert_eq!(radii(vec![4.0, 1.0, 2.0, 3.0]).median(), 2.0);
    assert_eq!(radii(vec![0.5]).median(), 0.5);
}

#[test]
fn a_bad_radius_is_an_error_naming_file_attribute_and_particle() {
    let dir = tempfile::tempdir().unwrap();
    for (bad, shown) in [(f32::NAN, "NaN"), (0.0, "0.0"), (-0.025, "-0.025")] {
        for name in ["b.vtk", "b.ply", "b.vtu"] {
            let value = move |i: usize| if i == 37 { bad } else { 0.025 };
            let path = sphere_with(dir.path(), name, &[("pscale", &value)]);
            let err = read_radii(&path, None, &RadiusAttribute::default()).unwrap_err();
            match &err {
                Error::InvalidRadius {
                    path: p,
                    attribute,
                    particle,
                    ..
                } => {
                    assert_eq!(p, &path);
                    assert_eq!(attribute, "pscale");
                    assert_eq!(*particle, Some(37), "{name}: {err}");
                }
                e => panic!("{name}: {e}"),
            }
            let text = err.to_string();
            assert!(text.contains(&format!("radius {shown}")), "{text}");
            assert!(text.contains("particle 37"), "{text}");
        }
    }
    // In memory: the wrong length and a vector are refused as a whole.
    let path = Path::new("particles in memory");
    let column = |components: usize, len: usize| Attribute {
        name: "r".into(),
        components,
        values: vec![0.01; len],
    };
    for (a, wanted) in [
        (column(1, 9), "holds 9 values for 10 particles"),
        (column(3, 30), "3 components per particle"),
    ] {
        let err = radii_of(path, &[a], 10, &"r".parse().unwrap()).unwrap_err();
        assert!(
            matches!(err, Error::InvalidRadius { particle: None, .. }),
            "{err}"
        );
        assert!(err.to_string().contains(wanted), "{err}");
    }
}

/// Runs `meniscus reconstruct INPUT -o OUTPUT ARGS`: exit code and stderr.
fn reconstruct(input: &Path, output: &Path, args: &[&str]) -> (Option<i32>, String) {
    let out = meniscus()
        .arg("reconstruct")
        .arg(input)
        .arg("-o")
        .arg(output)
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn a_uniform_radius_attribute_gives_the_plain_runs_output_byte_for_byte() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let input = sphere_with(d, "u.vtk", &[("pscale", &|_| 0.025), ("size", &|_| 0.025)]);
    let plain = d.join("plain.ply");
    let (code, err) = reconstruct(
        &input,
        &plain,
        &["-r", "0.025", "--radius-attribute", "none"],
    );
    assert_eq!(code, Some(0), "{err}");
    // pscale by default, said on stderr; r is its median.
    let by_default = d.join("pscale.ply");
    let (code, err) = reconstruct(&input, &by_default, &[]);
    assert_eq!(code, Some(0), "{err}");
    assert!(
        err.contains("particle radii from Houdini's attribute \"pscale\""),
        "{err}"
    );
    assert!(
        err.contains("particle radius r = 0.025 (the median of"),
        "{err}"
    );
    assert!(!err.contains("warning"), "{err}");
    // Named, tiled.
    let named = d.join("named.ply");
    let (code, err) = reconstruct(
        &input,
        &named,
        &["--radius-attribute", "size", "--tile-size", "16", "-q"],
    );
    assert_eq!(code, Some(0), "{err}");
    assert!(err.is_empty(), "{err}");
    let untiled_plain = std::fs::read(&plain).unwrap();
    assert_eq!(untiled_plain, std::fs::read(&by_default).unwrap());
    let tiled_plain = d.join("tiled.ply");
    let (code, err) = reconstruct(
        &input,
        &tiled_plain,
        &[
            "-r",
            "0.025",
            "--radius-attribute",
            "none",
            "--tile-size",
            "16",
        ],
    );
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(
        std::fs::read(&tiled_plain).unwrap(),
        std::fs::read(&named).unwrap()
    );
}

#[test]
fn the_cli_reports_bad_and_differing_radii() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("out.ply");
    let nan = sphere_with(
        d,
        "nan.ply",
        &[("pscale", &|i| if i == 5 { f32::NAN } else { 0.025 })],
    );
    let uniform = sphere_with(d, "uniform.ply", &[("pscale", &|_| 0.025)]);
    let differing = sphere_with(d, "differing.ply", &[("pscale", &varying)]);
    // A sequence whose second frame has a negative radius.
    let seq = d.join("seq");
    std::fs::create_dir(&seq).unwrap();
    std::fs::copy(&uniform, seq.join("f_1.ply")).unwrap();
    let bad = sphere_with(
        d,
        "neg.ply",
        &[("pscale", &|i| if i == 9 { -1.0 } else { 0.025 })],
    );
    std::fs::copy(&bad, seq.join("f_2.ply")).unwrap();
    let pattern = seq.join("f_{}.ply");
    let seq_out = d.join("o_{}.ply");
    type Case<'a> = (&'a Path, &'a Path, Vec<&'a str>, i32, Vec<&'a str>);
    let cases: Vec<Case> = vec![
        (
            &nan,
            &out,
            vec![],
            1,
            vec!["nan.ply: radius attribute \"pscale\", particle 5: radius NaN"],
        ),
        (
            &nan,
            &out,
            vec!["-r", "0.025"],
            1,
            vec!["nan.ply: radius attribute \"pscale\", particle 5"],
        ),
        (
            &pattern,
            &seq_out,
            vec!["-q"],
            1,
            vec!["f_2.ply: radius attribute \"pscale\", particle 9: radius -1.0"],
        ),
        // -r far from the median radius: refused before any work, as against the spacing.
        (
            &uniform,
            &out,
            vec!["-r", "2.5"],
            2,
            vec![
                "uniform.ply: a particle radius of 2.5 is refused: it is 100.000 × the 0.025 median of the particles' radius attribute \"pscale\"",
                "one blob",
                "give about 0.025, or --no-radius-check to run with 2.5 anyway",
            ],
        ),
        (
            &uniform,
            &out,
            vec!["-r", "0.06", "-q"],
            0,
            vec![
                "warning: ",
                "a particle radius of 0.06 is 2.40 × the 0.025 median of the particles' radius attribute \"pscale\"",
                "(--no-radius-check silences this)",
            ],
        ),
        (
            &differing,
            &out,
            vec![],
            0,
            vec![
                "particle radii of attribute \"pscale\"",
                "from 0.02 to 0.03: each particle meshed with its own",
                "multiples of r = 0.02",
            ],
        ),
        (
            &uniform,
            &out,
            vec!["--radius-attribute", ""],
            2,
            vec!["an empty attribute name"],
        ),
    ];
    for (input, output, args, code, wanted) in cases {
        let (got, err) = reconstruct(input, output, &args);
        assert_eq!(got, Some(code), "{input:?} {args:?}: {err}");
        for w in wanted {
            assert!(err.contains(w), "{input:?} {args:?}: wanted {w:?} in {err}");
        }
        if code != 0 {
            assert!(!out.exists(), "{args:?}: no output on failure");
            assert!(!d.join("o_2.ply").exists(), "no output of the bad frame");
        }
        let _ = std::fs::remove_file(&out);
    }
}
