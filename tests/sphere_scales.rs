//! Isolated spheres of different sizes (per-instance scales, issue 37) in every output:
//! each format is written and read back, and every sphere must have its own radius
//! (template radius × scale) about its own centre.

use glam::Vec3;
use meniscus::archive::{ArchiveFrame, ArchiveOptions, ArchiveReader, ArchiveWriter};
use meniscus::io::mesh::{read_mesh, write_surface, MeshWriteOptions};
use meniscus::io::usd::{UsdOptions, UsdStageWriter};
use meniscus::isolated::icosphere;
use meniscus::mesh::{Attribute, SphereInstances, Surface, TriMesh};
use std::path::Path;

/// Radius of the sphere template.
const RADIUS: f32 = 0.1;
const SCALES: [f32; 3] = [1.0, 2.0, 0.5];

/// A small fluid and three spheres of scales 1, 2 and 0.5.
fn scaled() -> Surface {
    let mut fluid = icosphere(2, 1.0);
    for p in &mut fluid.positions {
        *p += Vec3::new(0.1, -0.2, 0.3);
    }
    Surface {
        fluid,
        spheres: SphereInstances {
            template: icosphere(1, RADIUS),
            centers: vec![
                Vec3::new(3.0, 0.0, 0.0),
                Vec3::new(-3.0, 1.0, 0.5),
                Vec3::new(0.5, 2.5, -1.0),
            ],
            scales: SCALES.to_vec(),
            attributes: Vec::new(),
        },
    }
}

/// Checks that the vertices of `mesh` after its first `fluid` ones are the spheres of
/// `s`, instance after instance: every vertex at the instance's radius from its centre
/// (within `tolerance`), and the sphere's extent that of its radius.
fn assert_spheres(mesh: &TriMesh, fluid: usize, s: &SphereInstances, tolerance: f32, what: &str) {
    let n = s.template.vertex_count();
    assert_eq!(mesh.vertex_count(), fluid + n * s.centers.len(), "{what}");
    for (k, c) in s.centers.iter().enumerate() {
        let radius = RADIUS * s.scales[k];
        let block = &mesh.positions[fluid + k * n..fluid + (k + 1) * n];
        for p in block {
            let d = (*p - *c).length();
            assert!(
                (d - radius).abs() <= tolerance,
                "{what}: sphere {k}: a vertex at {d} from its centre, radius {radius}"
            );
        }
        let (lo, hi) = block.iter().fold(
            (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        );
        let extent = hi - lo;
        assert!(
            (extent - Vec3::splat(2.0 * radius)).abs().max_element() <= 2.0 * tolerance,
            "{what}: sphere {k}: extent {extent}, radius {radius}"
        );
    }
}

#[test]
fn merged_scales_each_sphere_about_its_centre_and_keeps_the_normals() {
    let s = scaled();
    let merged = s.spheres.merged();
    assert_spheres(&merged, 0, &s.spheres, 1e-6, "merged");
    let n = s.spheres.template.vertex_count();
    assert_eq!(merged.normals[n..2 * n], s.spheres.template.normals[..]);
    // Scale 1 everywhere is the unscaled merge, bit for bit.
    let mut ones = s.spheres.clone();
    ones.scales = vec![1.0; 3];
    let mut none = s.spheres.clone();
    none.scales.clear();
    assert_eq!(ones.merged(), none.merged());
}

#[test]
fn every_mesh_format_reads_back_spheres_of_their_own_size() {
    let dir = tempfile::tempdir().unwrap();
    let s = scaled();
    let fluid = s.fluid.vertex_count();
    for ext in ["glb", "gltf", "ply", "obj", "vtk"] {
        let path = dir.path().join(format!("s.{ext}"));
        write_surface(&path, &s, &MeshWriteOptions::default()).unwrap();
        let back = read_mesh(&path).unwrap();
        assert_spheres(&back, fluid, &s.spheres, 1e-6, ext);
        if ext != "glb" && ext != "gltf" {
            // One vertex table: the spheres exactly as merged.
            assert_eq!(back.positions, s.merged().positions, "{ext}");
        }
    }
    // glTF instances: one node per sphere, its scale the instance's on all three axes.
    let json = gltf_json(&std::fs::read(dir.path().join("s.glb")).unwrap());
    let nodes = json["nodes"].as_array().unwrap();
    let scales: Vec<Vec<f64>> = nodes
        .iter()
        .filter(|n| n.get("translation").is_some())
        .map(|n| serde_json::from_value(n["scale"].clone()).unwrap())
        .collect();
    let expected: Vec<Vec<f64>> = SCALES.iter().map(|&s| vec![s as f64; 3]).collect();
    assert_eq!(scales, expected);
}

/// The JSON chunk of a `.glb`.
fn gltf_json(bytes: &[u8]) -> serde_json::Value {
    let len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    serde_json::from_slice(&bytes[20..20 + len]).unwrap()
}

#[test]
fn gltf_spheres_with_attributes_are_merged_at_their_size() {
    let dir = tempfile::tempdir().unwrap();
    let mut s = scaled();
    s.spheres.attributes = vec![Attribute {
        name: "density".into(),
        components: 1,
        values: vec![1000.0, 1001.0, 1002.0],
    }];
    s.fluid.attributes = vec![Attribute {
        name: "density".into(),
        components: 1,
        values: vec![999.0; s.fluid.vertex_count()],
    }];
    for ext in ["glb", "gltf", "ply", "vtk"] {
        let path = dir.path().join(format!("a.{ext}"));
        write_surface(&path, &s, &MeshWriteOptions::default()).unwrap();
        let back = read_mesh(&path).unwrap();
        assert_spheres(&back, s.fluid.vertex_count(), &s.spheres, 1e-6, ext);
        let density = &back.attributes[0];
        let n = s.spheres.template.vertex_count();
        assert_eq!(density.item(s.fluid.vertex_count() + n), [1001.0], "{ext}");
    }
}

#[test]
fn scales_that_do_not_fit_the_centres_are_refused_before_anything_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let usd = dir.path().join("s.usda");
    for (scales, says) in [
        (vec![1.0, 2.0], "2 scales for 3 centres"),
        (vec![1.0, 0.0, 1.0], "sphere instance 1 has the scale 0"),
        (
            vec![1.0, 1.0, f32::NAN],
            "sphere instance 2 has the scale NaN",
        ),
    ] {
        let mut s = scaled();
        s.spheres.scales = scales;
        for ext in ["glb", "ply", "obj", "vtk"] {
            let path = dir.path().join(format!("bad.{ext}"));
            let e = write_surface(&path, &s, &MeshWriteOptions::default()).unwrap_err();
            assert!(e.to_string().contains(says), "{ext}: {e}");
            assert!(!path.exists(), "{ext}");
        }
        let mut stage = UsdStageWriter::create(&usd, &UsdOptions::default()).unwrap();
        let e = stage.append_frame(1, &s).unwrap_err();
        assert!(e.to_string().contains(says), "usd: {e}");
        assert_eq!(stage.frames(), 0);
        let mseq = dir.path().join("bad.mseq");
        let mut w = ArchiveWriter::create(&mseq, &ArchiveOptions::new(1e-4)).unwrap();
        let e = w.append_frame(3, &frame(&s)).unwrap_err().to_string();
        assert!(e.contains(says) && e.contains("frame 3"), "mseq: {e}");
        drop(w);
        assert!(!mseq.exists());
    }
}

/// The text of a `.usda` property's samples: the line holding `name`, then up to the
/// closing brace.
fn usda_property<'a>(text: &'a str, name: &str) -> &'a str {
    let start = text.find(name).unwrap_or_else(|| panic!("no {name}"));
    let end = start + text[start..].find('}').unwrap();
    &text[start..end]
}

#[test]
fn a_usd_instancer_gets_scales_and_a_scaled_extent_only_for_frames_with_them() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.usda");
    let s = scaled();
    let mut plain = scaled();
    plain.spheres.scales.clear();
    let options = UsdOptions {
        droplets: meniscus::io::usd::UsdDroplets::Instancer,
        ..UsdOptions::default()
    };
    let mut stage = UsdStageWriter::create(&path, &options).unwrap();
    stage.append_frame(1, &s).unwrap();
    stage.append_frame(2, &plain).unwrap();
    stage.finish().unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    let scales = usda_property(&text, "float3[] scales.timeSamples");
    assert!(
        scales.contains("1: [(1.0, 1.0, 1.0), (2.0, 2.0, 2.0), (0.5, 0.5, 0.5)]"),
        "{scales}"
    );
    // Frame 2 has no scales: an empty array, every instance at the prototype's size.
    assert!(scales.contains("2: []"), "{scales}");
    // The instancer's extent holds every sphere at its size: the big one (scale 2,
    // radius 0.2) sets x min, the small one (0.5) z min.
    let instancer = &text[text.find("PointInstancer").unwrap()..];
    let extent = usda_property(instancer, "float3[] extent.timeSamples");
    let frame1 = extent.lines().find(|l| l.trim().starts_with("1:")).unwrap();
    let (lo, hi) = s.spheres.centers.iter().zip(&SCALES).fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(lo, hi), (c, &k)| {
            (
                lo.min(*c - Vec3::splat(RADIUS) * k),
                hi.max(*c + Vec3::splat(RADIUS) * k),
            )
        },
    );
    let numbers: Vec<f32> = frame1
        .split(|c: char| !(c.is_ascii_digit() || c == '-' || c == '.' || c == 'e'))
        .filter(|t| t.contains('.'))
        .map(|t| t.parse().unwrap())
        .collect();
    let want = [lo.to_array(), hi.to_array()].concat();
    assert_eq!(numbers.len(), 6, "{frame1}");
    for (a, b) in numbers.iter().zip(&want) {
        assert!((a - b).abs() < 1e-6, "{frame1} vs {want:?}");
    }
}

/// A frame of `s` stored as it is (no Loop steps).
fn frame(s: &Surface) -> ArchiveFrame<'_> {
    ArchiveFrame {
        fluid: &s.fluid,
        subdivision_levels: 0,
        spheres: &s.spheres,
    }
}

#[test]
fn an_archive_stores_the_scales_and_every_sphere_within_the_bound() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.mseq");
    let bound = 1e-3;
    let s = scaled();
    let mut plain = scaled();
    plain.spheres.scales.clear();
    let mut w = ArchiveWriter::create(&path, &ArchiveOptions::new(bound)).unwrap();
    w.append_frame(1, &frame(&plain)).unwrap();
    w.finish().unwrap();
    assert_eq!(ArchiveReader::open(&path).unwrap().version(), 3);
    // Appending a frame with scales makes the archive version 5.
    let mut w = ArchiveWriter::open_append(&path, &ArchiveOptions::new(bound)).unwrap();
    w.append_frame(2, &frame(&s)).unwrap();
    w.finish().unwrap();
    let reader = ArchiveReader::open(&path).unwrap();
    assert_eq!(reader.version(), 5);
    assert!(reader.verify().is_clean());
    assert!(reader.read_surface(1).unwrap().spheres.scales.is_empty());
    let back = reader.read_surface(2).unwrap();
    assert_eq!(back.spheres.scales, SCALES);
    // Every sphere vertex (scaled template plus centre) within the bound per coordinate
    // of an original one (the template's vertices are renumbered).
    let (want, got) = (s.spheres.merged(), back.spheres.merged());
    for b in &got.positions {
        let error = want
            .positions
            .iter()
            .map(|a| (*a - *b).abs().max_element() as f64)
            .fold(f64::MAX, f64::min);
        assert!(error <= bound * 1.0001, "{error} > {bound}");
    }
    assert_spheres(
        &reader.read_frame(2).unwrap(),
        s.fluid.vertex_count(),
        &s.spheres,
        2e-3,
        "mseq",
    );
    // Extracted to other formats, the spheres keep their sizes.
    let cancel = meniscus::CancelToken::new();
    let out = dir.path().join("f_{}.ply");
    let files = reader
        .extract(
            Some(&[2]),
            out.to_str().unwrap(),
            &MeshWriteOptions::default(),
            &cancel,
        )
        .unwrap();
    let ply = read_mesh(&files[0]).unwrap();
    assert_eq!(ply.positions, back.merged().positions);
    let stage = dir.path().join("f.usda");
    reader
        .extract_stage(
            Some(&[2]),
            stage.to_str().unwrap(),
            &UsdOptions::default(),
            &cancel,
        )
        .unwrap();
    let text = std::fs::read_to_string(&stage).unwrap();
    // The droplets' widths are their diameters, 2 r_i (the template's radius within the
    // archive's bound, scaled).
    let widths = usda_property(&text, "float[] widths.timeSamples");
    let widths = &widths[widths.find("2: [").unwrap() + 4..];
    let widths: Vec<f32> = widths[..widths.find(']').unwrap()]
        .split(", ")
        .map(|w| w.parse().unwrap())
        .collect();
    assert_eq!(widths.len(), SCALES.len());
    for (w, k) in widths.iter().zip(SCALES) {
        assert!(
            (w - 2.0 * RADIUS * k).abs() <= 2.0 * bound as f32 * k,
            "{widths:?}"
        );
    }
}

#[test]
fn a_version_1_archive_stores_scaled_spheres_merged() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("v1.mseq");
    // A version-1 archive: the header's version field set to 1 before any frame.
    let w = ArchiveWriter::create(&path, &ArchiveOptions::new(1e-3)).unwrap();
    w.finish().unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    bytes[8..12].copy_from_slice(&1u32.to_le_bytes());
    std::fs::write(&path, &bytes).unwrap();
    let s = scaled();
    let mut w = ArchiveWriter::open_append(&path, &ArchiveOptions::new(1e-3)).unwrap();
    w.append_frame(4, &frame(&s)).unwrap();
    w.finish().unwrap();
    let reader = ArchiveReader::open(&path).unwrap();
    assert_eq!(reader.version(), 1);
    let mesh = reader.read_frame(4).unwrap();
    // Fluid and spheres in one plain mesh: the spheres' area is that of their radii.
    let spheres = mesh.area() - s.fluid.area();
    let unit = s.spheres.template.area() / (RADIUS as f64).powi(2);
    let expected: f64 = SCALES
        .iter()
        .map(|&k| unit * ((RADIUS * k) as f64).powi(2))
        .sum();
    assert!(
        (spheres - expected).abs() < 1e-2 * expected,
        "{spheres} vs {expected}"
    );
}

#[test]
fn an_archive_written_before_scales_reads_with_empty_scales() {
    // `reconstruct datasets/analytic/droplets.xyz --particle-radius 0.025 -o x.mseq`
    // by the build before sphere scales (b2d40e0): version 3, 500 isolated spheres.
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/archive/droplets-v3.mseq");
    let reader = ArchiveReader::open(&path).unwrap();
    assert_eq!(reader.version(), 3);
    assert!(reader.verify().is_clean());
    let surface = reader.read_surface(0).unwrap();
    assert_eq!(surface.spheres.centers.len(), 500);
    assert!(surface.spheres.scales.is_empty());
    // Its spheres write as before: glTF nodes without a scale.
    let dir = tempfile::tempdir().unwrap();
    let glb = dir.path().join("d.glb");
    write_surface(&glb, &surface, &MeshWriteOptions::default()).unwrap();
    let json = gltf_json(&std::fs::read(&glb).unwrap());
    assert!(json["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .all(|n| n.get("scale").is_none()));
}
