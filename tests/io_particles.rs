//! Particle readers: shipped files, cross-format agreement, round trips through the
//! writers, hand-made fixtures, and every kind of bad input.

use glam::Vec3;
use meniscus::io::particles::{
    read_particles, stream_bgeo_positions, stream_ply_positions, stream_vtk_positions,
    write_particles, Attribute, ParticleFormat, Particles,
};
use meniscus::Error;
use std::path::{Path, PathBuf};

fn data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("datasets")
        .join(rel)
}

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
        let count = stream_bgeo_positions(&path, &mut |chunk| {
            chunks += 1;
            streamed.extend_from_slice(chunk);
            Ok(())
        })
        .unwrap();
        assert_eq!(count, positions.len());
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
    stream_bgeo_positions(&shipped, &mut |chunk| {
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
    let err = stream_bgeo_positions(&cut, &mut |_| Ok(()))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("cut.bgeo.gz") && err.contains("decompressed"),
        "{err}"
    );
}

/// A streaming reader's count and positions, gathered from its chunks.
type StreamFn =
    fn(&Path, &mut dyn FnMut(&[Vec3]) -> meniscus::Result<()>) -> meniscus::Result<Option<usize>>;

fn streamed(stream: StreamFn, path: &Path) -> (Option<usize>, Vec<Vec3>) {
    let mut out = Vec::new();
    let n = stream(path, &mut |chunk| {
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
    stream: StreamFn,
    dir: &Path,
    ext: &str,
    bytes: &[u8],
    positions: &[Vec3],
    ascii: &str,
    last_record_line: usize,
) {
    let big = write(dir, &format!("big.{ext}"), bytes);
    let (n, got) = streamed(stream, &big);
    assert_eq!(n, Some(positions.len()));
    assert_eq!(bits(&got), bits(positions));
    assert_eq!(
        bits(&read_particles(&big, None).unwrap().positions),
        bits(positions)
    );
    let cut = write(dir, &format!("cut.{ext}"), &bytes[..bytes.len() / 2]);
    let err = stream(&cut, &mut |_| Ok(())).unwrap_err().to_string();
    assert!(
        err.contains(&format!("cut.{ext}")) && err.contains("truncated"),
        "{err}"
    );

    let text = write(dir, &format!("a.{ext}"), ascii.as_bytes());
    let whole = read_particles(&text, None).unwrap().positions;
    assert!(whole.len() > 2);
    let (n, got) = streamed(stream, &text);
    assert_eq!(n, Some(whole.len()));
    assert_eq!(bits(&got), bits(&whole));
    let lines = last_record_line;
    let before_last: usize = ascii.lines().take(lines - 1).map(|l| l.len() + 1).sum();
    let cut = write(
        dir,
        &format!("acut.{ext}"),
        &ascii.as_bytes()[..before_last],
    );
    let err = stream(&cut, &mut |_| Ok(())).unwrap_err().to_string();
    assert!(
        err.contains("truncated") && err.contains(&format!("line {lines}")),
        "{err}"
    );
    let mut bad = ascii.as_bytes()[..before_last].to_vec();
    bad.extend_from_slice(b"1 2 oops 4 5 6\n");
    let bad = write(dir, &format!("abad.{ext}"), &bad);
    let err = stream(&bad, &mut |_| Ok(())).unwrap_err().to_string();
    assert!(
        err.contains("\"oops\"") && err.contains(&format!("line {lines}")),
        "{err}"
    );
}

#[test]
fn vtk_streams_its_points_like_it_reads_whole() {
    let collect = |path: &Path| streamed(stream_vtk_positions, path);
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
        let (n, streamed) = collect(&path);
        let whole = read_particles(&path, None).unwrap().positions;
        assert_eq!(n, Some(whole.len()), "{}", path.display());
        assert_eq!(bits(&streamed), bits(&whole), "{}", path.display());
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
        stream_vtk_positions,
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
    let collect = |path: &Path| streamed(stream_ply_positions, path);
    let dir = tempfile::tempdir().unwrap();
    // The written sample (velocity and density interleaved with the positions).
    let written = dir.path().join("sample.ply");
    write_particles(&written, &sample(), ParticleFormat::Ply).unwrap();
    let (n, streamed) = collect(&written);
    assert_eq!(n, Some(50));
    assert_eq!(bits(&streamed), bits(&sample().positions));
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
        stream_ply_positions,
        dir.path(),
        "ply",
        &bytes,
        &positions,
        // Positions behind another property, a face element after the vertices.
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty uchar tag\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n7 1 2 3\n8 -4.5 5e2 6\n9 0.7 0.8 0.9\n3 0 1 2\n",
        13,
    );
}
