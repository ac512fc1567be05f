//! The USD stage writer's behaviour that needs no USD reader: atomic writes, the checks
//! before a frame is written, options and paths. The stages' content is checked with
//! Pixar's reader by `tests/usd/check_stages.py` (see `tests/usd/run.sh`).

use glam::Vec3;
use meniscus::io::usd::{UsdDroplets, UsdFormat, UsdOptions, UsdStageWriter};
use meniscus::isolated::icosphere;
use meniscus::mesh::{Attribute, SphereInstances, Surface};
use meniscus::Error;
use std::path::Path;

fn attribute(name: &str, components: usize, items: usize) -> Attribute {
    Attribute {
        name: name.into(),
        components,
        values: (0..components * items).map(|i| i as f32 * 0.5).collect(),
    }
}

/// A frame with a velocity and a density on the fluid and two spheres.
fn surface(level: u32) -> Surface {
    let mut fluid = icosphere(level, 1.0);
    let n = fluid.positions.len();
    fluid.attributes = vec![attribute("velocity", 3, n), attribute("density", 1, n)];
    Surface {
        fluid,
        spheres: SphereInstances {
            template: icosphere(1, 0.05),
            scales: Vec::new(),
            centers: vec![Vec3::new(3.0, 0.0, 0.0), Vec3::new(-3.0, 1.0, 0.5)],
            attributes: vec![attribute("velocity", 3, 2)],
        },
    }
}

/// Files in `dir`, sorted.
fn files(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn a_writer_can_move_between_threads() {
    fn send<T: Send>() {}
    send::<UsdStageWriter>();
}

#[test]
fn both_formats_are_written_by_finish_only() {
    let dir = tempfile::tempdir().unwrap();
    for (name, head) in [
        ("s.usdc", &b"PXR-USDC"[..]),
        ("s.usd", b"PXR-USDC"),
        ("s.usda", b"#usda 1.0"),
    ] {
        let path = dir.path().join(name);
        let mut stage = UsdStageWriter::create(&path, &UsdOptions::default()).unwrap();
        stage.append_frame(3, &surface(1)).unwrap();
        stage.append_frame(1, &surface(2)).unwrap();
        assert!(!path.exists(), "{name} before finish");
        assert_eq!(stage.frames(), 2);
        let stats = stage.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert!(bytes.starts_with(head), "{name}");
        assert_eq!(stats.bytes, bytes.len() as u64, "{name}");
        assert_eq!(stats.frames, 2);
        // The droplets are points by default: no sphere triangles.
        assert_eq!(stats.triangles, 80 + 320, "{name}");
        assert_eq!(stats.droplets, 2 * 2, "{name}");
        let instanced = UsdOptions {
            droplets: UsdDroplets::Instancer,
            ..UsdOptions::default()
        };
        let mut stage = UsdStageWriter::create(&path, &instanced).unwrap();
        stage.append_frame(3, &surface(1)).unwrap();
        let stats = stage.finish().unwrap();
        // Two spheres of 80 triangles.
        assert_eq!(stats.triangles, 80 + 2 * 80, "{name}");
        assert_eq!(stats.droplets, 2, "{name}");
    }
    assert_eq!(
        files(dir.path()),
        ["s.usd", "s.usda", "s.usdc"],
        "no temporary file left"
    );
}

#[test]
fn a_stage_dropped_unfinished_leaves_the_target_as_it_was() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("shot.usdc");
    std::fs::write(&path, b"earlier").unwrap();
    for ext in ["usdc", "usda"] {
        let path = path.with_extension(ext);
        let mut stage = UsdStageWriter::create(&path, &UsdOptions::default()).unwrap();
        stage.append_frame(1, &surface(1)).unwrap();
        drop(stage);
    }
    assert_eq!(files(dir.path()), ["shot.usdc"]);
    assert_eq!(std::fs::read(&path).unwrap(), b"earlier");
}

#[test]
fn a_frame_number_twice_is_refused_and_the_stage_stays_usable() {
    let dir = tempfile::tempdir().unwrap();
    let mut stage =
        UsdStageWriter::create(&dir.path().join("s.usdc"), &UsdOptions::default()).unwrap();
    stage.append_frame(7, &surface(1)).unwrap();
    let err = stage.append_frame(7, &surface(1)).unwrap_err();
    assert!(
        matches!(&err, Error::FramesExist { frames, .. } if frames == &[7]),
        "{err}"
    );
    stage.append_frame(8, &surface(1)).unwrap();
    assert_eq!(stage.finish().unwrap().frames, 2);
}

#[test]
fn attributes_that_do_not_fit_are_refused_before_anything_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let mut stage =
        UsdStageWriter::create(&dir.path().join("s.usdc"), &UsdOptions::default()).unwrap();
    stage.append_frame(1, &surface(1)).unwrap();
    // The density had 1 component in frame 1.
    let mut changed = surface(1);
    changed.fluid.attributes[1] = attribute("density", 2, changed.fluid.vertex_count());
    let err = stage.append_frame(2, &changed).unwrap_err();
    assert!(
        matches!(&err, Error::Attribute { attribute, .. } if attribute == "primvars:density"),
        "{err}"
    );
    // Two names that become the same USD identifier.
    let mut clash = surface(1);
    let n = clash.fluid.vertex_count();
    clash.fluid.attributes.push(attribute("tex-coord", 2, n));
    clash.fluid.attributes.push(attribute("tex coord", 2, n));
    let err = stage.append_frame(3, &clash).unwrap_err();
    assert!(
        matches!(&err, Error::Attribute { attribute, .. } if attribute == "tex coord"),
        "{err}"
    );
    // A value count that is not one item per vertex.
    let mut short = surface(1);
    short.fluid.attributes[1].values.pop();
    assert!(matches!(
        stage.append_frame(4, &short),
        Err(Error::Attribute { .. })
    ));
    // None of them took a frame number.
    stage.append_frame(2, &surface(2)).unwrap();
    assert_eq!(stage.finish().unwrap().frames, 2);
}

#[test]
fn options_and_paths_are_checked_at_create() {
    let dir = tempfile::tempdir().unwrap();
    let bad_fps = UsdOptions {
        fps: 0.0,
        ..UsdOptions::default()
    };
    let err = UsdStageWriter::create(&dir.path().join("s.usdc"), &bad_fps)
        .err()
        .unwrap();
    assert!(
        matches!(err, Error::InvalidOption { option: "fps", .. }),
        "{err}"
    );
    let bad_scale = UsdOptions {
        meters_per_unit: f64::NAN,
        ..UsdOptions::default()
    };
    let err = UsdStageWriter::create(&dir.path().join("s.usdc"), &bad_scale)
        .err()
        .unwrap();
    assert!(
        matches!(
            err,
            Error::InvalidOption {
                option: "meters_per_unit",
                ..
            }
        ),
        "{err}"
    );
    let err = UsdStageWriter::create(&dir.path().join("s.abc"), &UsdOptions::default())
        .err()
        .unwrap();
    assert!(matches!(err, Error::UnsupportedFormat { .. }), "{err}");
    let missing = dir.path().join("no/such/dir/s.usdc");
    let err = UsdStageWriter::create(&missing, &UsdOptions::default())
        .err()
        .unwrap();
    assert!(
        matches!(&err, Error::Io { path, .. } if path == &missing),
        "{err}"
    );
    let err = UsdStageWriter::create(dir.path(), &UsdOptions::default())
        .err()
        .unwrap();
    assert!(
        matches!(err, Error::UnsupportedFormat { .. } | Error::Io { .. }),
        "{err}"
    );
    let forced = UsdOptions {
        format: Some(UsdFormat::Usda),
        ..UsdOptions::default()
    };
    let path = dir.path().join("stage.txt");
    UsdStageWriter::create(&path, &forced)
        .unwrap()
        .finish()
        .unwrap();
    assert!(std::fs::read_to_string(&path)
        .unwrap()
        .starts_with("#usda 1.0"));
    assert_eq!(
        UsdFormat::from_path(Path::new("a.USD")).unwrap(),
        UsdFormat::Usdc
    );
}

#[test]
fn droplets_are_points_with_widths_or_an_instancer_by_option() {
    let dir = tempfile::tempdir().unwrap();
    let mut s = surface(1);
    s.spheres.scales = vec![1.0, 2.0];
    let write = |name: &str, droplets| {
        let path = dir.path().join(name);
        let options = UsdOptions {
            droplets,
            ..UsdOptions::default()
        };
        let mut stage = UsdStageWriter::create(&path, &options).unwrap();
        stage.append_frame(1, &s).unwrap();
        stage.finish().unwrap();
        std::fs::read_to_string(path).unwrap()
    };
    let points = write("points.usda", UsdDroplets::default());
    assert!(points.contains("def Points \"Droplets\""), "{points}");
    assert!(!points.contains("PointInstancer"));
    // widths = 2 r_i: the template's radius is 0.05, the scales 1 and 2.
    let widths = &points[points.find("float[] widths.timeSamples").unwrap()..];
    let widths = &widths[widths.find("1: [").unwrap() + 4..];
    let widths: Vec<f32> = widths[..widths.find(']').unwrap()]
        .split(", ")
        .map(|w| w.parse().unwrap())
        .collect();
    assert_eq!(widths.len(), 2);
    for (w, want) in widths.iter().zip([0.1, 0.2]) {
        assert!((w - want).abs() < 1e-6, "{widths:?}");
    }
    let droplets = &points[points.find("def Points").unwrap()..];
    assert!(droplets.contains("vector3f[] velocities.timeSamples"));
    assert!(droplets.contains("interpolation = \"vertex\""));
    let instanced = write("instanced.usda", UsdDroplets::Instancer);
    assert!(instanced.contains("def PointInstancer \"Spheres\""));
    assert!(!instanced.contains("def Points"));
    assert_eq!("instancer".parse(), Ok(UsdDroplets::Instancer));
    assert!("spheres".parse::<UsdDroplets>().is_err());
}
