//! Particle readers: shipped files, cross-format agreement, round trips through the
//! writers, hand-made fixtures, and every kind of bad input.

mod support;

use glam::Vec3;
use meniscus::io::particles::{
    read_particles, stream_positions, write_particles, Attribute, ParticleFormat, Particles,
};
use meniscus::Error;
use std::path::{Path, PathBuf};
use support::{dataset as data, names_in, Rng};

/// splashsurf's example files live in the shared data folder beside the checkout.
fn shared(rel: &str) -> Option<PathBuf> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(rel);
    p.exists().then_some(p)
}

fn bits(p: &[Vec3]) -> Vec<[u32; 3]> {
    p.iter().map(|v| v.to_array().map(f32::to_bits)).collect()
}

#[test]
fn the_three_files_of_a_frame_agree_bit_for_bit() {
    let xyz = read_particles(&data("dambreak_small/ParticleData_Fluid_25.xyz"), None).unwrap();
    let vtk = read_particles(&data("dambreak_small/ParticleData_Fluid_25.vtk"), None).unwrap();
    let bgeo = read_particles(&data("dambreak_small/ParticleData_Fluid_25.bgeo"), None).unwrap();
    assert_eq!(xyz.positions.len(), 41_912);
    assert_eq!(bits(&xyz.positions), bits(&vtk.positions));
    assert_eq!(bits(&xyz.positions), bits(&bgeo.positions));
    let v_vtk = vtk
        .attributes
        .iter()
        .find(|a| a.name == "velocity")
        .expect("VTK velocity");
    let v_bgeo = bgeo
        .attributes
        .iter()
        .find(|a| a.name == "velocity")
        .expect("BGEO velocity");
    assert_eq!(v_vtk.components, 3);
    assert_eq!(v_vtk.values, v_bgeo.values);
    let ids = bgeo
        .attributes
        .iter()
        .find(|a| a.name == "id")
        .expect("BGEO id");
    assert_eq!(ids.values.len(), 41_912);
}

#[test]
fn shipped_and_example_files_have_their_stated_counts() {
    for (rel, n) in [
        ("analytic/sphere.vtk", 4224),
        ("analytic/box.xyz", 1920),
        ("analytic/droplets.vtk", 780),
        ("analytic/sheet.vtk", 800),
        ("double_dambreak/ParticleData_Fluid_9.vtk", 4732),
    ] {
        assert_eq!(
            read_particles(&data(rel), None).unwrap().positions.len(),
            n,
            "{rel}"
        );
    }
    for (rel, n) in [
        (
            "splashsurf_examples/dam_break_frame_23_24389_particles.bgeo",
            24_389,
        ),
        ("splashsurf_examples/hilbert_46843_particles.bgeo", 46_843),
        (
            "splashsurf_examples/double_dam_break_frame_26_4732_particles.vtk",
            4732,
        ),
        (
            "splashsurf_examples/sailors_knot_19539_particles.vtk",
            19_539,
        ),
        (
            "splashsurf_examples/free_particles_1000_particles.vtk",
            1000,
        ),
    ] {
        if let Some(path) = shared(rel) {
            assert_eq!(
                read_particles(&path, None).unwrap().positions.len(),
                n,
                "{rel}"
            );
        }
    }
}

fn sample() -> Particles {
    let positions: Vec<Vec3> = (0..50)
        .map(|i| {
            Vec3::new(
                i as f32 * 0.5 - 3.0,
                (i as f32).sin(),
                1.0 / (i as f32 + 1.0),
            )
        })
        .collect();
    Particles {
        attributes: vec![
            Attribute {
                name: "velocity".into(),
                components: 3,
                values: (0..150).map(|i| i as f32 * 0.25 - 7.0).collect(),
            },
            Attribute {
                name: "density".into(),
                components: 1,
                values: (0..50).map(|i| 1000.0 + i as f32).collect(),
            },
        ],
        positions,
    }
}

#[test]
fn writers_round_trip_through_the_readers() {
    let dir = tempfile::tempdir().unwrap();
    let original = sample();
    for (name, format) in [
        ("a.xyz", ParticleFormat::Xyz),
        ("a.vtk", ParticleFormat::Vtk),
        ("a.ply", ParticleFormat::Ply),
    ] {
        let path = dir.path().join(name);
        write_particles(&path, &original, format).unwrap();
        let back = read_particles(&path, None).unwrap();
        assert_eq!(bits(&back.positions), bits(&original.positions), "{name}");
        if format != ParticleFormat::Xyz {
            assert_eq!(back.attributes, original.attributes, "{name}");
        }
    }
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains(".tmp-"))
        .collect();
    assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

#[test]
fn hand_made_ascii_and_double_fixtures() {
    let dir = tempfile::tempdir().unwrap();
    let vtk = write(dir.path(), "a.vtk", b"# vtk DataFile Version 3.0\ntitle\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 3 double\n0 0 0\n1.5 -2 3e-1\n7 8 9\nCELLS 3 6\n1 0\n1 1\n1 2\nCELL_TYPES 3\n1 1 1\nPOINT_DATA 3\nSCALARS pressure float 1\nLOOKUP_TABLE default\n1 2 3\nVECTORS velocity float\n1 0 0 0 1 0 0 0 1\n");
    let p = read_particles(&vtk, None).unwrap();
    assert_eq!(
        p.positions,
        vec![
            Vec3::ZERO,
            Vec3::new(1.5, -2.0, 0.3),
            Vec3::new(7.0, 8.0, 9.0)
        ]
    );
    assert_eq!(p.attributes[0].name, "pressure");
    assert_eq!(p.attributes[0].values, vec![1.0, 2.0, 3.0]);
    assert_eq!(p.attributes[1].values[4], 1.0);

    let ply = write(dir.path(), "a.ply", b"ply\nformat ascii 1.0\ncomment x\nelement vertex 2\nproperty double x\nproperty double y\nproperty double z\nproperty float vx\nproperty float vy\nproperty float vz\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n1 2 3 4 5 6\n-1 -2 -3 0 0 0\n3 0 1 1\n");
    let p = read_particles(&ply, None).unwrap();
    assert_eq!(
        p.positions,
        vec![Vec3::new(1.0, 2.0, 3.0), Vec3::new(-1.0, -2.0, -3.0)]
    );
    assert_eq!(p.attributes[0].name, "velocity");
    assert_eq!(p.attributes[0].values, vec![4.0, 5.0, 6.0, 0.0, 0.0, 0.0]);

    let mut be = b"ply\nformat binary_big_endian 1.0\nelement vertex 2\nproperty double x\nproperty double y\nproperty double z\nend_header\n".to_vec();
    for v in [1.0f64, 2.0, 3.0, 4.0, 5.0, 6.0] {
        be.extend_from_slice(&v.to_be_bytes());
    }
    let p = read_particles(&write(dir.path(), "be.ply", &be), None).unwrap();
    assert_eq!(p.positions[1], Vec3::new(4.0, 5.0, 6.0));
}

fn parse_error(path: &Path, format: Option<ParticleFormat>) -> String {
    match read_particles(path, format) {
        Err(e @ Error::Parse { .. }) => e.to_string(),
        other => panic!("{}: expected a parse error, got {other:?}", path.display()),
    }
}

#[test]
fn bad_inputs_are_rejected_with_their_location() {
    let dir = tempfile::tempdir().unwrap();
    // Empty files of every format.
    for name in ["e.xyz", "e.vtk", "e.ply", "e.bgeo"] {
        let p = write(dir.path(), name, b"");
        assert!(
            matches!(read_particles(&p, None), Err(Error::EmptyInput { .. })),
            "{name}"
        );
    }
    // Unknown extension.
    let p = write(dir.path(), "a.csv", b"1,2,3");
    assert!(matches!(
        read_particles(&p, None),
        Err(Error::UnsupportedFormat { .. })
    ));
    // Truncated .xyz.
    let p = write(dir.path(), "t.xyz", &[0u8; 30]);
    assert!(parse_error(&p, None).contains("multiple of 12"));
    // NaN and infinity.
    for (name, bad) in [("nan.xyz", f32::NAN), ("inf.xyz", f32::INFINITY)] {
        let mut bytes = Vec::new();
        for v in [0.0f32, 0.0, 0.0, 1.0, bad, 1.0] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        let msg = parse_error(&write(dir.path(), name, &bytes), None);
        assert!(
            msg.contains("particle 1") && msg.contains("non-finite"),
            "{msg}"
        );
    }
    // Truncated binary VTK at several offsets.
    let full = std::fs::read(data("double_dambreak/ParticleData_Fluid_9.vtk")).unwrap();
    for cut in [120, 1000, full.len() / 2, full.len() - 10] {
        let msg = parse_error(&write(dir.path(), "cut.vtk", &full[..cut]), None);
        assert!(
            msg.contains("byte offset") && (msg.contains("truncated") || msg.contains("expected")),
            "{cut}: {msg}"
        );
    }
    // Bad headers.
    let msg = parse_error(&write(dir.path(), "h.vtk", b"hello\n"), None);
    assert!(msg.contains("line 1"), "{msg}");
    let msg = parse_error(
        &write(
            dir.path(),
            "h.ply",
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1\n",
        ),
        None,
    );
    assert!(msg.contains("x, y, z"), "{msg}");
    // Truncated and corrupt BGEO.
    let bgeo = std::fs::read(data("dambreak_small/ParticleData_Fluid_25.bgeo")).unwrap();
    let mut plain = Vec::new();
    std::io::Read::read_to_end(&mut flate2::read::GzDecoder::new(&bgeo[..]), &mut plain).unwrap();
    let msg = parse_error(
        &write(dir.path(), "cut.bgeo", &plain[..plain.len() / 2]),
        None,
    );
    assert!(msg.contains("truncated"), "{msg}");
    let msg = parse_error(&write(dir.path(), "magic.bgeo", b"NotBgeo at all"), None);
    assert!(msg.contains("magic"), "{msg}");
    // The plain (uncompressed) BGEO reads like the gzip one.
    let p = read_particles(&write(dir.path(), "plain.bgeo", &plain), None).unwrap();
    assert_eq!(p.positions.len(), 41_912);
    // A format override reads a file with a foreign extension.
    let p = read_particles(
        &write(dir.path(), "frame.bin", &plain),
        Some(ParticleFormat::Bgeo),
    )
    .unwrap();
    assert_eq!(p.positions.len(), 41_912);
}

/// A classic BGEO (version 5) of `positions` with one vector attribute `v`, plain.
fn bgeo_bytes(positions: &[Vec3]) -> Vec<u8> {
    let mut b = b"BgeoV".to_vec();
    for v in [5, positions.len() as i32, 0, 0, 0, 1, 0, 0, 0] {
        b.extend_from_slice(&v.to_be_bytes());
    }
    b.extend_from_slice(&1u16.to_be_bytes());
    b.push(b'v');
    b.extend_from_slice(&3u16.to_be_bytes());
    b.extend_from_slice(&5i32.to_be_bytes());
    b.extend_from_slice(&[0u8; 12]);
    for (i, p) in positions.iter().enumerate() {
        for c in [p.x, p.y, p.z, 1.0, i as f32, -(i as f32), 0.5] {
            b.extend_from_slice(&c.to_be_bytes());
        }
    }
    b
}

#[test]
fn bgeo_streams_in_chunks_like_it_reads_whole() {
    let dir = tempfile::tempdir().unwrap();
    // 150 000 particles: three chunks of the streaming reader.
    let positions: Vec<Vec3> = (0..150_000)
        .map(|i| Vec3::new(i as f32 * 0.001, (i % 7) as f32, -(i as f32).sqrt()))
        .collect();
    let plain = bgeo_bytes(&positions);
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    std::io::Write::write_all(&mut gz, &plain).unwrap();
    let gz = gz.finish().unwrap();
    for (name, bytes) in [("big.bgeo", &plain), ("big.bgeo.gz", &gz)] {
        let path = write(dir.path(), name, bytes);
        let mut streamed = Vec::new();
        let mut chunks = 0;
        let count = stream_positions(&path, None, &mut |chunk| {
            chunks += 1;
            streamed.extend_from_slice(chunk);
            Ok(())
        })
        .unwrap();
        assert_eq!(count, Some(positions.len()));
        assert_eq!(chunks, 3, "{name}");
        assert_eq!(bits(&streamed), bits(&positions), "{name}");
        let whole = read_particles(&path, None).unwrap();
        assert_eq!(bits(&whole.positions), bits(&positions), "{name}");
        let v = &whole.attributes[0];
        assert_eq!((v.name.as_str(), v.components), ("v", 3));
        assert_eq!(&v.values[3..6], &[1.0, -1.0, 0.5]);
    }
    // The shipped frame streams to the positions the whole-file reader gives.
    let shipped = data("dambreak_small/ParticleData_Fluid_25.bgeo");
    let mut streamed = Vec::new();
    stream_positions(&shipped, None, &mut |chunk| {
        streamed.extend_from_slice(chunk);
        Ok(())
    })
    .unwrap();
    assert_eq!(
        bits(&streamed),
        bits(&read_particles(&shipped, None).unwrap().positions)
    );
    // Cut in the particle data: a clear error naming the stream position.
    let cut = write(dir.path(), "cut.bgeo.gz", &gz[..gz.len() / 2]);
    let err = stream_positions(&cut, None, &mut |_| Ok(()))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("cut.bgeo.gz") && err.contains("decompressed"),
        "{err}"
    );
}

/// The streaming reader's count and positions, gathered from its chunks.
fn streamed(path: &Path) -> (Option<usize>, Vec<Vec3>) {
    let mut out = Vec::new();
    let n = stream_positions(path, None, &mut |chunk| {
        out.extend_from_slice(chunk);
        Ok(())
    })
    .unwrap();
    (n, out)
}

/// The checks both streaming readers share: a big file (`bytes`, holding `positions`)
/// streams and reads whole to those positions, its first half is a clear "truncated"
/// error; an ASCII file (`ascii`, its last record on line `last_record_line`) streams like
/// it reads whole, and a cut or a bad number in it is an error naming the line.
fn check_big_cut_and_ascii(
    dir: &Path,
    ext: &str,
    bytes: &[u8],
    positions: &[Vec3],
    ascii: &str,
    last_record_line: usize,
) {
    let big = write(dir, &format!("big.{ext}"), bytes);
    let (n, got) = streamed(&big);
    assert_eq!(n, Some(positions.len()));
    assert_eq!(bits(&got), bits(positions));
    assert_eq!(
        bits(&read_particles(&big, None).unwrap().positions),
        bits(positions)
    );
    let cut = write(dir, &format!("cut.{ext}"), &bytes[..bytes.len() / 2]);
    let err = stream_positions(&cut, None, &mut |_| Ok(()))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains(&format!("cut.{ext}")) && err.contains("truncated"),
        "{err}"
    );

    let text = write(dir, &format!("a.{ext}"), ascii.as_bytes());
    let whole = read_particles(&text, None).unwrap().positions;
    assert!(whole.len() > 2);
    let (n, got) = streamed(&text);
    assert_eq!(n, Some(whole.len()));
    assert_eq!(bits(&got), bits(&whole));
    let lines = last_record_line;
    let before_last: usize = ascii.lines().take(lines - 1).map(|l| l.len() + 1).sum();
    let cut = write(
        dir,
        &format!("acut.{ext}"),
        &ascii.as_bytes()[..before_last],
    );
    let err = stream_positions(&cut, None, &mut |_| Ok(()))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("truncated") && err.contains(&format!("line {lines}")),
        "{err}"
    );
    let mut bad = ascii.as_bytes()[..before_last].to_vec();
    bad.extend_from_slice(b"1 2 oops 4 5 6\n");
    let bad = write(dir, &format!("abad.{ext}"), &bad);
    let err = stream_positions(&bad, None, &mut |_| Ok(()))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("\"oops\"") && err.contains(&format!("line {lines}")),
        "{err}"
    );
}

#[test]
fn vtk_streams_its_points_like_it_reads_whole() {
    // Shipped frames (SPlisHSPlasH layout, float points) and the written sample (with
    // point data after the points).
    let dir = tempfile::tempdir().unwrap();
    let written = dir.path().join("sample.vtk");
    write_particles(&written, &sample(), ParticleFormat::Vtk).unwrap();
    for path in [
        data("dambreak_small/ParticleData_Fluid_25.vtk"),
        data("double_dambreak/ParticleData_Fluid_9.vtk"),
        data("analytic/droplets.vtk"),
        written,
    ] {
        let (n, got) = streamed(&path);
        let whole = read_particles(&path, None).unwrap().positions;
        assert_eq!(n, Some(whole.len()), "{}", path.display());
        assert_eq!(bits(&got), bits(&whole), "{}", path.display());
    }
    // More than one chunk, double precision.
    let positions: Vec<Vec3> = (0..100_000)
        .map(|i| Vec3::new(i as f32 * 0.01, -(i as f32), (i % 13) as f32 * 0.1))
        .collect();
    let mut doubles = b"# vtk DataFile Version 3.0\nbig\nBINARY\nDATASET POLYDATA\n".to_vec();
    doubles.extend_from_slice(format!("POINTS {} double\n", positions.len()).as_bytes());
    for p in &positions {
        for c in p.to_array() {
            doubles.extend_from_slice(&(c as f64).to_be_bytes());
        }
    }
    check_big_cut_and_ascii(
        dir.path(),
        "vtk",
        &doubles,
        &positions,
        // Records spanning lines, several on one line, and a section after the points.
        "# vtk DataFile Version 3.0\na\nASCII\nDATASET POLYDATA\nPOINTS 4 float\n1 2.5\n-3 4e-3 5 6\n7 8 9\n0.1 0.2 0.3\nVERTICES 0 0\n",
        9,
    );
}

#[test]
fn ply_streams_its_vertices_like_it_reads_whole() {
    let dir = tempfile::tempdir().unwrap();
    // The written sample (velocity and density interleaved with the positions).
    let written = dir.path().join("sample.ply");
    write_particles(&written, &sample(), ParticleFormat::Ply).unwrap();
    let (n, got) = streamed(&written);
    assert_eq!(n, Some(50));
    assert_eq!(bits(&got), bits(&sample().positions));
    // Big-endian doubles behind another property, over two chunks, a face element after.
    let positions: Vec<Vec3> = (0..70_000)
        .map(|i| Vec3::new(i as f32 * 0.5, (i % 11) as f32, -(i as f32) * 0.01))
        .collect();
    let mut bytes = format!(
        "ply\nformat binary_big_endian 1.0\ncomment test\nelement vertex {}\nproperty uchar tag\nproperty double x\nproperty double y\nproperty double z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n",
        positions.len()
    )
    .into_bytes();
    for p in &positions {
        bytes.push(7);
        for c in p.to_array() {
            bytes.extend_from_slice(&(c as f64).to_be_bytes());
        }
    }
    bytes.push(3);
    for i in [0i32, 1, 2] {
        bytes.extend_from_slice(&i.to_be_bytes());
    }
    check_big_cut_and_ascii(
        dir.path(),
        "ply",
        &bytes,
        &positions,
        // Positions behind another property, a face element after the vertices.
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty uchar tag\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n7 1 2 3\n8 -4.5 5e2 6\n9 0.7 0.8 0.9\n3 0 1 2\n",
        13,
    );
}

// ---------------------------------------------------------------------------------------
// Streaming with payload: `SpooledParticles` against `read_particles` + `Particles::select`.

use meniscus::attributes::{AttributeLayout, AttributeSelection};
use meniscus::io::particles::{ParticleSource, SpooledParticles};
use meniscus::CancelToken;

fn names(list: &[&str]) -> AttributeSelection {
    AttributeSelection::Names(list.iter().map(|n| n.to_string()).collect())
}

/// `count` particles with a 3-component velocity, a scalar density and a 2-component
/// `uv`, all distinct per particle.
fn payload_sample(count: usize) -> Particles {
    let f = |i: usize, k: u32| ((i as f32) * 0.37 + k as f32).sin() * (1.0 + k as f32);
    Particles {
        positions: (0..count)
            .map(|i| Vec3::new(f(i, 0), f(i, 1) * 2.0, i as f32 * 1e-3))
            .collect(),
        attributes: vec![
            Attribute {
                name: "velocity".into(),
                components: 3,
                values: (0..3 * count)
                    .map(|j| f(j / 3, 3 + (j % 3) as u32))
                    .collect(),
            },
            Attribute {
                name: "density".into(),
                components: 1,
                values: (0..count).map(|i| 1000.0 + f(i, 7)).collect(),
            },
            Attribute {
                name: "uv".into(),
                components: 2,
                values: (0..2 * count)
                    .map(|j| f(j / 2, 9 + (j % 2) as u32))
                    .collect(),
            },
        ],
    }
}

/// The sample as ASCII PLY: x y z vx vy vz density uv_0 uv_1, with a second element after
/// the vertices (skipped by both readers).
fn ascii_ply(p: &Particles) -> String {
    let n = p.positions.len();
    let mut s = format!(
        "ply\nformat ascii 1.0\nelement vertex {n}\nproperty float x\nproperty float y\nproperty float z\nproperty float vx\nproperty float vy\nproperty float vz\nproperty double density\nproperty float uv_0\nproperty float uv_1\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
    );
    for i in 0..n {
        let x = p.positions[i];
        let row: Vec<String> = [x.x, x.y, x.z]
            .iter()
            .chain(p.attributes[0].item(i))
            .chain(p.attributes[1].item(i))
            .chain(p.attributes[2].item(i))
            .map(|v| format!("{v:e}"))
            .collect();
        s += &row.join(" ");
        s += "\n";
    }
    s + "3 0 1 2\n"
}

/// The sample as ASCII VTK: points, vertices, then POINT_DATA with a SCALARS, a VECTORS
/// and a FIELD of two arrays (one a cell-count array the readers ignore).
fn ascii_vtk(p: &Particles) -> String {
    let n = p.positions.len();
    let join = |v: &mut dyn Iterator<Item = f32>| -> String {
        let words: Vec<String> = v.map(|x| format!("{x:e}")).collect();
        words
            .chunks(7)
            .map(|c| c.join(" "))
            .collect::<Vec<_>>()
            .join("\n")
    };
    let mut s = format!(
        "# vtk DataFile Version 3.0\nascii sample\nASCII\nDATASET POLYDATA\nPOINTS {n} float\n"
    );
    s += &join(&mut p.positions.iter().flat_map(|x| x.to_array()));
    s += &format!("\nVERTICES {n} {}\n", 2 * n);
    for i in 0..n {
        s += &format!("1 {i}\n");
    }
    s += &format!("POINT_DATA {n}\nSCALARS density double 1\nLOOKUP_TABLE default\n");
    s += &join(&mut p.attributes[1].values.iter().copied());
    s += "\nVECTORS velocity float\n";
    s += &join(&mut p.attributes[0].values.iter().copied());
    s += "\nFIELD FieldData 2\nother 1 3 int\n1 2 3\nuv 2 ";
    s += &format!("{n} float\n");
    s += &join(&mut p.attributes[2].values.iter().copied());
    s + "\n"
}

/// The name of the sample's `uv` (or of its second component) in `format`: PLY holds
/// one scalar per component.
fn uv(format: ParticleFormat) -> &'static str {
    if format == ParticleFormat::Ply {
        "uv_1"
    } else {
        "uv"
    }
}

/// Positions and payload rows of a source, and its layout.
fn drain(source: &dyn ParticleSource) -> (Vec<Vec3>, Vec<f32>, Vec<AttributeLayout>) {
    let (mut positions, mut payload) = (Vec::new(), Vec::new());
    let mut next = 0;
    source
        .visit_chunks(&mut |chunk| {
            assert_eq!(chunk.first, next);
            next += chunk.positions.len();
            positions.extend_from_slice(chunk.positions);
            payload.extend_from_slice(chunk.payload);
            Ok(())
        })
        .unwrap();
    assert_eq!(next, source.particle_count());
    (positions, payload, source.attribute_layout())
}

/// Streams `path` with `selection` into `temp` and checks it gives, bit for bit, the
/// positions, payload rows and layout of the parsed file with the same selection; the
/// temporary files exist while the source lives and are gone after.
fn check_streamed(
    path: &Path,
    format: ParticleFormat,
    selection: &AttributeSelection,
    temp: &Path,
) {
    let label = format!("{} {selection:?}", path.display());
    let parsed = read_particles(path, Some(format))
        .unwrap()
        .select(path, selection)
        .unwrap();
    let spooled =
        SpooledParticles::from_file(path, format, selection, Some(temp), &CancelToken::new())
            .unwrap()
            .unwrap_or_else(|| panic!("{label}: not streamed"));
    let files = names_in(temp);
    let expect_files = if parsed.attributes.is_empty() { 1 } else { 2 };
    assert_eq!(files.len(), expect_files, "{label}: {files:?}");
    let (positions, payload, layout) = drain(&spooled);
    let (want_positions, want_payload, want_layout) = drain(&parsed);
    assert!(
        !want_layout.is_empty()
            || matches!(
                selection,
                AttributeSelection::None | AttributeSelection::Velocity
            ),
        "{label}"
    );
    assert_eq!(layout, want_layout, "{label}");
    assert_eq!(bits(&positions), bits(&want_positions), "{label}");
    assert_eq!(payload.len(), want_payload.len(), "{label}");
    let differ = payload
        .iter()
        .zip(&want_payload)
        .position(|(a, b)| a.to_bits() != b.to_bits());
    assert_eq!(differ, None, "{label}: payload differs");
    drop(spooled);
    assert!(
        names_in(temp).is_empty(),
        "{label}: left {:?}",
        names_in(temp)
    );
}

#[test]
fn streamed_payload_matches_the_parsed_file_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let temp = dir.path().join("temp");
    std::fs::create_dir(&temp).unwrap();
    let bgeo = data("dambreak_small/ParticleData_Fluid_25.bgeo");
    let vtk = data("dambreak_small/ParticleData_Fluid_25.vtk");
    for selection in [
        AttributeSelection::Velocity,
        AttributeSelection::All,
        names(&["id", "VELOCITY"]),
        names(&["id"]),
        AttributeSelection::None,
    ] {
        check_streamed(&bgeo, ParticleFormat::Bgeo, &selection, &temp);
    }
    for selection in [AttributeSelection::Velocity, AttributeSelection::All] {
        check_streamed(&vtk, ParticleFormat::Vtk, &selection, &temp);
    }
    // Written files: binary PLY and VTK past one streaming chunk (65 536) and one visited
    // window (2^20), ASCII PLY and VTK past one streaming chunk.
    let big = payload_sample((1 << 20) + 4321);
    let small = payload_sample(70_001);
    let files = [
        (dir.path().join("big.ply"), ParticleFormat::Ply),
        (dir.path().join("big.vtk"), ParticleFormat::Vtk),
    ];
    for (path, format) in &files {
        write_particles(path, &big, *format).unwrap();
    }
    let ascii_ply_path = write(dir.path(), "ascii.ply", ascii_ply(&small).as_bytes());
    let ascii_vtk_path = write(dir.path(), "ascii.vtk", ascii_vtk(&small).as_bytes());
    let all = [
        files[0].clone(),
        files[1].clone(),
        (ascii_ply_path, ParticleFormat::Ply),
        (ascii_vtk_path, ParticleFormat::Vtk),
    ];
    for (path, format) in &all {
        for selection in [
            AttributeSelection::All,
            AttributeSelection::Velocity,
            names(&[uv(*format), "density", "velocity"]),
            names(&["DENSITY"]),
        ] {
            check_streamed(path, *format, &selection, &temp);
        }
    }
    // The ASCII files really hold the attributes (the comparison above is not vacuous).
    let parsed = read_particles(&all[3].0, None).unwrap();
    let got: Vec<&str> = parsed.attributes.iter().map(|a| a.name.as_str()).collect();
    assert_eq!(got, ["density", "velocity", "uv"]);
}

#[test]
fn a_bad_selection_fails_before_any_temporary_file_and_like_the_parser() {
    let dir = tempfile::tempdir().unwrap();
    let temp = dir.path().join("temp");
    std::fs::create_dir(&temp).unwrap();
    let ply = dir.path().join("p.ply");
    write_particles(&ply, &payload_sample(1000), ParticleFormat::Ply).unwrap();
    let vtk_ascii = write(
        dir.path(),
        "a.vtk",
        ascii_vtk(&payload_sample(100)).as_bytes(),
    );
    for (path, format) in [
        (
            data("dambreak_small/ParticleData_Fluid_25.bgeo"),
            ParticleFormat::Bgeo,
        ),
        (
            data("dambreak_small/ParticleData_Fluid_25.vtk"),
            ParticleFormat::Vtk,
        ),
        (ply, ParticleFormat::Ply),
        (vtk_ascii, ParticleFormat::Vtk),
    ] {
        for selection in [
            names(&["velocity", "nope"]),
            names(&["velocity", "Velocity"]),
        ] {
            let parsed = read_particles(&path, Some(format))
                .unwrap()
                .select(&path, &selection)
                .unwrap_err();
            let streamed = SpooledParticles::from_file(
                &path,
                format,
                &selection,
                Some(&temp),
                &CancelToken::new(),
            )
            .err()
            .unwrap_or_else(|| panic!("{}: {selection:?} accepted", path.display()));
            assert!(matches!(streamed, Error::Attribute { .. }), "{streamed}");
            assert_eq!(streamed.to_string(), parsed.to_string());
            assert!(names_in(&temp).is_empty(), "left {:?}", names_in(&temp));
        }
    }
    // The listing names what the input has.
    let err = SpooledParticles::from_file(
        &data("dambreak_small/ParticleData_Fluid_25.bgeo"),
        ParticleFormat::Bgeo,
        &names(&["nope"]),
        Some(&temp),
        &CancelToken::new(),
    )
    .err()
    .unwrap()
    .to_string();
    assert!(
        err.contains("nope") && err.contains("velocity") && err.contains("id"),
        "{err}"
    );
}

#[test]
fn a_non_finite_attribute_value_is_a_clear_error_and_leaves_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let temp = dir.path().join("temp");
    std::fs::create_dir(&temp).unwrap();
    let mut bad = payload_sample(80_000);
    // Past the first streaming chunk, in the second component of the velocity, and an
    // infinity in uv later.
    bad.attributes[0].values[3 * 70_123 + 1] = f32::NAN;
    bad.attributes[2].values[2 * 75_000 + 1] = f32::INFINITY;
    let ply = dir.path().join("bad.ply");
    let vtk = dir.path().join("bad.vtk");
    write_particles(&ply, &bad, ParticleFormat::Ply).unwrap();
    write_particles(&vtk, &bad, ParticleFormat::Vtk).unwrap();
    let ascii = write(dir.path(), "bad_ascii.vtk", ascii_vtk(&bad).as_bytes());
    for (path, format) in [
        (&ply, ParticleFormat::Ply),
        (&vtk, ParticleFormat::Vtk),
        (&ascii, ParticleFormat::Vtk),
    ] {
        for (selection, attribute, particle) in [
            (AttributeSelection::Velocity, "velocity", 70_123),
            (names(&[uv(format)]), uv(format), 75_000),
            (names(&[uv(format), "velocity"]), "velocity", 70_123),
        ] {
            let err = SpooledParticles::from_file(
                path,
                format,
                &selection,
                Some(&temp),
                &CancelToken::new(),
            )
            .err()
            .unwrap_or_else(|| panic!("{}: accepted", path.display()));
            let parsed = read_particles(path, Some(format))
                .unwrap()
                .select(path, &selection)
                .unwrap_err();
            match &err {
                Error::Attribute {
                    path: p,
                    attribute: a,
                    message,
                } => {
                    assert_eq!(p, path);
                    assert_eq!(a, attribute);
                    assert!(
                        message.contains(&format!("particle {particle} ")),
                        "{message}"
                    );
                }
                other => panic!("{other}"),
            }
            // One attribute: the very error of the parser (with more, the first bad value
            // met in the file's order is reported; the parser checks in selection order).
            if attribute != "velocity" || selection == AttributeSelection::Velocity {
                assert_eq!(err.to_string(), parsed.to_string());
            }
            assert!(names_in(&temp).is_empty(), "left {:?}", names_in(&temp));
        }
        // Positions only: the attributes are not read, so not checked.
        let fine = SpooledParticles::from_file(
            path,
            format,
            &AttributeSelection::None,
            Some(&temp),
            &CancelToken::new(),
        )
        .unwrap()
        .unwrap();
        assert_eq!(fine.particle_count(), 80_000);
        assert!(fine.attribute_layout().is_empty());
        drop(fine);
        assert!(names_in(&temp).is_empty());
    }
}

#[test]
fn a_cancelled_stream_removes_its_files() {
    let dir = tempfile::tempdir().unwrap();
    let temp = dir.path().join("temp");
    std::fs::create_dir(&temp).unwrap();
    let cancel = CancelToken::new();
    cancel.cancel();
    for (path, format) in [
        (
            data("dambreak_small/ParticleData_Fluid_25.bgeo"),
            ParticleFormat::Bgeo,
        ),
        (
            data("dambreak_small/ParticleData_Fluid_25.vtk"),
            ParticleFormat::Vtk,
        ),
    ] {
        let err = SpooledParticles::from_file(
            &path,
            format,
            &AttributeSelection::All,
            Some(&temp),
            &cancel,
        )
        .err()
        .unwrap();
        assert!(matches!(err, Error::Interrupted), "{err}");
        assert!(names_in(&temp).is_empty(), "left {:?}", names_in(&temp));
    }
}

// ---- Hostile inputs: counts from a header are bounded by the bytes that follow. ----

/// The error of reading `bytes` as `name`: must be an error (not a panic, not an abort
/// from a huge reservation) that names the file.
fn hostile(name: &str, bytes: &[u8]) -> String {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), name, bytes);
    let e = read_particles(&path, None).expect_err(name).to_string();
    assert!(e.contains(name), "{e}");
    e
}

fn ply_with(head: &str, data: &[u8]) -> Vec<u8> {
    let mut b = format!("ply\nformat binary_little_endian 1.0\n{head}end_header\n").into_bytes();
    b.extend_from_slice(data);
    b
}

#[test]
fn ply_counts_beyond_the_file_are_errors() {
    let props = "property float x\nproperty float y\nproperty float z\n";
    // 4·10^11 vertices in a tiny file (used to reserve 4 TB).
    let e = hostile(
        "big.ply",
        &ply_with(&format!("element vertex 400000000000\n{props}"), &[0; 24]),
    );
    assert!(e.contains("only 24 bytes follow the header"), "{e}");
    // 2^64 − 1 (used to panic on capacity overflow).
    let e = hostile(
        "max.ply",
        &ply_with(
            &format!("element vertex 18446744073709551615\n{props}"),
            &[0; 24],
        ),
    );
    assert!(e.contains("\"vertex\""), "{e}");
    // An element without properties and a huge count (used to loop forever).
    let e = hostile(
        "empty.ply",
        &ply_with(
            &format!("element junk 18446744073709551615\nelement vertex 1\n{props}"),
            &[0; 12],
        ),
    );
    assert!(e.contains("\"junk\""), "{e}");
    // ASCII: at least one byte per value.
    let e = hostile(
        "ascii.ply",
        format!("ply\nformat ascii 1.0\nelement vertex 100000000000\n{props}end_header\n1 2 3\n")
            .as_bytes(),
    );
    assert!(e.contains("100000000000 rows"), "{e}");
    // Two elements that each fit but together do not.
    hostile(
        "sum.ply",
        &ply_with(
            &format!("element vertex 2\n{props}element vertex2 2\n{props}"),
            &[0; 36],
        ),
    );
}

/// A BGEO header with one point per `npoints` and `nattr` float attributes of 65 535
/// components each: records of 262 KB.
fn bgeo_wide(npoints: i32, nattr: i32) -> Vec<u8> {
    let mut b = b"BgeoV".to_vec();
    for v in [5, npoints, 0, 0, 0, nattr, 0, 0, 0] {
        b.extend_from_slice(&v.to_be_bytes());
    }
    for k in 0..nattr {
        b.extend_from_slice(&1u16.to_be_bytes());
        b.push(b'a' + k as u8);
        b.extend_from_slice(&u16::MAX.to_be_bytes());
        b.extend_from_slice(&0i32.to_be_bytes());
        b.extend_from_slice(&vec![0u8; 4 * u16::MAX as usize]);
    }
    b
}

#[test]
fn bgeo_reserves_nothing_from_its_header_count() {
    use std::io::Write;
    // 2^31 − 1 points of 2 MB records in a 2 KB gzip file (used to ask for 137 GB).
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
    gz.write_all(&bgeo_wide(i32::MAX, 8)).unwrap();
    let gz = gz.finish().unwrap();
    assert!(gz.len() < 8192, "{}", gz.len());
    let e = hostile("wide.bgeo.gz", &gz);
    assert!(e.contains("truncated while reading points 0.."), "{e}");
    // Plain file, one wide attribute.
    let e = hostile("wide.bgeo", &bgeo_wide(i32::MAX, 1));
    assert!(e.contains("truncated while reading points"), "{e}");
}

#[test]
fn vtk_point_counts_that_overflow_or_exceed_the_file_are_errors() {
    let head = "# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\n";
    // 3·n overflows usize (used to be read as 1 particle).
    let e = hostile(
        "over.vtk",
        format!("{head}POINTS 6148914691236517206 float\n1 2 3\n").as_bytes(),
    );
    assert!(e.contains("overflows"), "{e}");
    // A count beyond the bytes left (ASCII and binary).
    hostile(
        "big.vtk",
        format!("{head}POINTS 100000000000 float\n1 2 3\n").as_bytes(),
    );
    hostile(
        "bin.vtk",
        b"# vtk DataFile Version 3.0\nx\nBINARY\nDATASET POLYDATA\nPOINTS 100000000000 float\n\0\0\0\0\0\0\0\0\0\0\0\0",
    );
}

#[test]
fn text_renamed_xyz_is_an_error() {
    let text = "1.5 2.25 -3e-2\n".repeat(12); // 180 bytes: a multiple of 12
    assert_eq!(text.len() % 12, 0);
    let e = hostile("text.xyz", text.as_bytes());
    assert!(e.contains("looks like text"), "{e}");
    // Real floats still read, even ones whose bytes are partly ASCII.
    let dir = tempfile::tempdir().unwrap();
    let mut bytes = Vec::new();
    for v in [1.0f32, 2.0, 3.0, f32::from_le_bytes(*b"1234"), 0.5, -0.25] {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    let p = read_particles(&write(dir.path(), "ok.xyz", &bytes), None).unwrap();
    assert_eq!(p.positions.len(), 2);
}

/// A mutated copy of `base`: flipped bytes, a truncation, or a number in the text
/// replaced by a huge one.
fn mutate(rng: &mut Rng, base: &[u8]) -> Vec<u8> {
    let huge = [
        "18446744073709551615",
        "4294967295",
        "999999999999",
        "6148914691236517206",
        "2147483647",
    ];
    support::mutate(rng, base, &huge, |rng, b| {
        if b.len() >= 8 {
            // Binary header fields: a big-endian i32 of 2^31 − 1.
            let i = rng.below(b.len() - 4);
            b[i..i + 4].copy_from_slice(&i32::MAX.to_be_bytes());
        }
    })
}

#[test]
fn mutated_particle_files_are_read_or_rejected_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let mut small = sample();
    small.positions.truncate(6);
    for a in &mut small.attributes {
        a.values.truncate(6 * a.components);
    }
    let mut bases: Vec<(&str, Vec<u8>)> = Vec::new();
    for (name, format) in [
        ("b.ply", ParticleFormat::Ply),
        ("b.vtk", ParticleFormat::Vtk),
        ("b.xyz", ParticleFormat::Xyz),
    ] {
        let p = dir.path().join(name);
        write_particles(&p, &small, format).unwrap();
        bases.push((name, std::fs::read(&p).unwrap()));
    }
    bases.push((
        "a.ply",
        b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty float density\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0 1\n1 0 0 2\n0 1 0 3\n3 0 1 2\n".to_vec(),
    ));
    bases.push((
        "a.vtk",
        b"# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\nPOINTS 3 float\n0 0 0 1 0 0 0 1 0\nVERTICES 3 6\n1 0\n1 1\n1 2\nPOINT_DATA 3\nSCALARS density float 1\nLOOKUP_TABLE default\n1 2 3\nFIELD f 1\nv 3 3 float\n1 2 3 4 5 6 7 8 9\n".to_vec(),
    ));
    let positions: Vec<Vec3> = small.positions.clone();
    let plain = bgeo_bytes(&positions);
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    std::io::Write::write_all(&mut gz, &plain).unwrap();
    bases.push(("b.bgeo", plain));
    bases.push(("g.bgeo", gz.finish().unwrap()));
    for (name, base) in &bases {
        let path = dir.path().join(name);
        std::fs::write(&path, base).unwrap();
        read_particles(&path, None).unwrap_or_else(|e| panic!("{name}: {e}"));
    }
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    for round in 0..3000 {
        let (name, base) = &bases[round % bases.len()];
        let bytes = mutate(&mut rng, base);
        let path = dir.path().join(name);
        std::fs::write(&path, &bytes).unwrap();
        let result = support::without_panic(round, name, &bytes, || read_particles(&path, None));
        if let Err(e) = result {
            assert!(e.to_string().contains(name), "{name}: {e}");
        }
    }
}

#[test]
fn a_gzip_bgeo_holding_more_points_than_its_header_announces_fails_fast() {
    // The header says 10 points; the data holds a million (about 28 MB decompressed).
    let positions: Vec<Vec3> = (0..1_000_000)
        .map(|i| Vec3::new(i as f32 * 1e-3, 0.0, 0.0))
        .collect();
    let mut plain = bgeo_bytes(&positions);
    plain[9..13].copy_from_slice(&10i32.to_be_bytes());
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    std::io::Write::write_all(&mut gz, &plain).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "liar.bgeo", &gz.finish().unwrap());
    let temp = tempfile::tempdir().unwrap();
    let clock = std::time::Instant::now();
    let check = |e: meniscus::Error| {
        let e = e.to_string();
        assert!(
            e.contains("liar.bgeo") && e.contains("past the 10 points the header announces"),
            "{e}"
        );
    };
    check(read_particles(&path, None).expect_err("undercounting header"));
    check(stream_positions(&path, None, &mut |_| Ok(())).expect_err("undercounting header"));
    for selection in [AttributeSelection::None, AttributeSelection::All] {
        let spooled = SpooledParticles::from_file(
            &path,
            ParticleFormat::Bgeo,
            &selection,
            Some(temp.path()),
            &CancelToken::new(),
        );
        check(spooled.err().expect("undercounting header"));
    }
    // Nothing but the announced points and one MiB past them is decompressed.
    assert!(clock.elapsed().as_secs_f64() < 5.0, "{:?}", clock.elapsed());
    // The spool files are removed with the error.
    assert_eq!(std::fs::read_dir(temp.path()).unwrap().count(), 0);
}
