//! VTK XML particle files (`.vtu`, `.vtp`): every encoding VTK's own writers produce
//! (fixtures in `tests/data/vtk_xml/`, written by `make_fixtures.py` with VTK 9) read like
//! the legacy file they came from, whole and streamed; the writer round-trips; broken
//! files are errors naming the file and what is wrong.

mod support;

use glam::Vec3;
use meniscus::attributes::AttributeSelection;
use meniscus::io::particles::{
    read_particles, stream_positions, write_particles, Attribute, ParticleFormat, ParticleSource,
    Particles, SpooledParticles,
};
use meniscus::CancelToken;
use std::path::{Path, PathBuf};
use support::dataset;

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/vtk_xml")
        .join(name)
}

fn bits(p: &[Vec3]) -> Vec<[u32; 3]> {
    p.iter().map(|v| v.to_array().map(f32::to_bits)).collect()
}

fn float_bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// Positions and payload of a source, in order.
fn drain(source: &dyn ParticleSource) -> (Vec<Vec3>, Vec<f32>) {
    let (mut positions, mut payload) = (Vec::new(), Vec::new());
    source
        .visit_chunks(&mut |chunk| {
            positions.extend_from_slice(chunk.positions);
            payload.extend_from_slice(chunk.payload);
            Ok(())
        })
        .unwrap();
    (positions, payload)
}

#[test]
fn each_vtk_xml_encoding_reads_like_the_legacy_file() {
    let legacy =
        read_particles(&dataset("double_dambreak/ParticleData_Fluid_9.vtk"), None).unwrap();
    let n = 40;
    let velocity = &legacy.attributes[0];
    assert_eq!(velocity.name, "velocity");
    let files = support::vtk_xml_fixtures();
    // Every data mode × compressor VTK writes, both header sizes, both point types, both
    // dataset types, both byte orders.
    assert_eq!(files.len(), 13, "{files:?}");
    for kind in [
        "ascii_none",
        "binary_none",
        "binary_zlib",
        "binary_lz4",
        "appended_none",
        "appended_zlib",
        "appended_lz4",
        "appended64_none",
        "appended64_zlib",
        "appended64_lz4",
        "u32",
        "u64",
        "f32",
        "f64",
        "_be",
        ".vtu",
        ".vtp",
    ] {
        assert!(
            files.iter().any(|f| f.to_str().unwrap().contains(kind)),
            "no {kind} fixture"
        );
    }
    let temp = tempfile::tempdir().unwrap();
    for path in &files {
        let label = path.file_name().unwrap().to_str().unwrap();
        let p = read_particles(path, None).unwrap();
        assert_eq!(bits(&p.positions), bits(&legacy.positions[..n]), "{label}");
        let names: Vec<&str> = p.attributes.iter().map(|a| a.name.as_str()).collect();
        assert_eq!(names, ["velocity", "id", "density"], "{label}");
        assert_eq!(p.attributes[0].components, 3);
        assert_eq!(
            float_bits(&p.attributes[0].values),
            float_bits(&velocity.values[..3 * n]),
            "{label}"
        );
        let ids: Vec<f32> = (0..n).map(|i| i as f32).collect();
        assert_eq!(p.attributes[1].values, ids, "{label}");
        let density: Vec<f32> = (0..n).map(|i| (1000.0 + i as f64 / 8.0) as f32).collect();
        assert_eq!(p.attributes[2].values, density, "{label}");
        // Streamed: the positions alone, and spooled with every attribute.
        let mut streamed = Vec::new();
        let count = stream_positions(path, None, &mut |c| {
            streamed.extend_from_slice(c);
            Ok(())
        })
        .unwrap();
        assert_eq!(count, Some(n), "{label}");
        assert_eq!(bits(&streamed), bits(&p.positions), "{label}");
        let format = ParticleFormat::from_path(path).unwrap();
        for selection in [AttributeSelection::All, "density,velocity".parse().unwrap()] {
            let spooled = SpooledParticles::from_file(
                path,
                format,
                &selection,
                Some(temp.path()),
                &CancelToken::new(),
            )
            .unwrap()
            .unwrap_or_else(|| panic!("{label}: not streamed"));
            let parsed = p.clone().select(path, &selection).unwrap();
            assert_eq!(
                spooled.attribute_layout(),
                parsed.attribute_layout(),
                "{label}"
            );
            let (positions, payload) = drain(&spooled);
            let (want_positions, want_payload) = drain(&parsed);
            assert_eq!(bits(&positions), bits(&want_positions), "{label}");
            assert_eq!(float_bits(&payload), float_bits(&want_payload), "{label}");
        }
    }
}

#[test]
fn the_whole_frame_written_by_vtk_reads_like_the_legacy_file() {
    let legacy =
        read_particles(&dataset("double_dambreak/ParticleData_Fluid_9.vtk"), None).unwrap();
    let xml = read_particles(&fixture("frame9_appended_zlib.vtu"), None).unwrap();
    assert_eq!(xml.positions.len(), 4732);
    assert_eq!(bits(&xml.positions), bits(&legacy.positions));
    assert_eq!(xml.attributes, legacy.attributes);
}

/// A sample with attributes of 1 and 3 components.
fn sample(n: usize) -> Particles {
    let positions = (0..n)
        .map(|i| Vec3::new(i as f32 * 0.5, (i % 7) as f32 - 3.0, 1.0 / (1 + i) as f32))
        .collect();
    Particles {
        positions,
        attributes: vec![
            Attribute {
                name: "density & \"rho\"".into(),
                components: 1,
                values: (0..n).map(|i| 1000.0 + i as f32).collect(),
            },
            Attribute {
                name: "velocity".into(),
                components: 3,
                values: (0..3 * n).map(|i| i as f32 * -0.25).collect(),
            },
        ],
    }
}

#[test]
fn the_writer_round_trips_and_streams_past_one_chunk() {
    let dir = tempfile::tempdir().unwrap();
    for (name, format) in [
        ("a.vtu", ParticleFormat::Vtu),
        ("a.vtp", ParticleFormat::Vtp),
    ] {
        let path = dir.path().join(name);
        let p = sample(70_001);
        write_particles(&path, &p, format).unwrap();
        assert_eq!(read_particles(&path, None).unwrap(), p, "{name}");
        let spooled = SpooledParticles::from_file(
            &path,
            format,
            &AttributeSelection::All,
            Some(dir.path()),
            &CancelToken::new(),
        )
        .unwrap()
        .unwrap();
        let (positions, payload) = drain(&spooled);
        let (want_positions, want_payload) = drain(&p);
        assert_eq!(bits(&positions), bits(&want_positions));
        assert_eq!(float_bits(&payload), float_bits(&want_payload));
    }
}

#[test]
fn several_pieces_are_joined() {
    let dir = tempfile::tempdir().unwrap();
    let piece = |first: usize| {
        format!(
            "<Piece NumberOfPoints=\"2\"><PointData><DataArray type=\"Float32\" Name=\"m\" format=\"ascii\">{} {}</DataArray></PointData>\
             <Points><DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">{first} 0 0 {} 0 0</DataArray></Points></Piece>",
            first,
            first + 1,
            first + 1
        )
    };
    let text = format!(
        "<?xml version=\"1.0\"?>\n<!-- two pieces -->\n<VTKFile type=\"PolyData\" version=\"0.1\">\n<PolyData>{}{}</PolyData></VTKFile>\n",
        piece(0),
        piece(2)
    );
    let path = dir.path().join("pieces.vtp");
    std::fs::write(&path, text).unwrap();
    let p = read_particles(&path, None).unwrap();
    let x: Vec<f32> = p.positions.iter().map(|v| v.x).collect();
    assert_eq!(x, [0.0, 1.0, 2.0, 3.0]);
    assert_eq!(p.attributes[0].values, [0.0, 1.0, 2.0, 3.0]);
    // Several pieces do not stream; the job reads them whole.
    assert_eq!(
        stream_positions(&path, None, &mut |_| Ok(())).unwrap(),
        None
    );
}

/// The error of reading `bytes` as `name`, whole and streamed with every attribute (the
/// same kind of message both ways), checked to name the file.
#[track_caller]
fn error_of(dir: &Path, name: &str, bytes: &[u8]) -> String {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    let whole = read_particles(&path, None).unwrap_err().to_string();
    assert!(whole.contains(name), "{whole}");
    let format = ParticleFormat::from_path(&path).unwrap();
    let streamed = SpooledParticles::from_file(
        &path,
        format,
        &AttributeSelection::All,
        Some(dir),
        &CancelToken::new(),
    );
    if let Err(e) = streamed {
        assert!(e.to_string().contains(name), "{e}");
    }
    whole
}

/// The bytes of fixture `name` with `from` replaced by `to` (once).
fn edited(name: &str, from: &str, to: &str) -> Vec<u8> {
    let bytes = std::fs::read(fixture(name)).unwrap();
    let at = bytes
        .windows(from.len())
        .position(|w| w == from.as_bytes())
        .unwrap_or_else(|| panic!("{from:?} in {name}"));
    let mut out = bytes[..at].to_vec();
    out.extend_from_slice(to.as_bytes());
    out.extend_from_slice(&bytes[at + from.len()..]);
    out
}

/// The offset of the first byte of the appended data (after `<AppendedData ...>` and `_`).
fn appended_start(bytes: &[u8]) -> usize {
    let tag = bytes
        .windows(13)
        .position(|w| w == b"<AppendedData")
        .expect("appended data");
    tag + bytes[tag..].iter().position(|&b| b == b'_').unwrap() + 1
}

#[test]
fn broken_files_are_errors_naming_the_file_and_the_fault() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let raw = "dd9_appended_none_u64_f32.vtu";
    let bytes = std::fs::read(fixture(raw)).unwrap();
    // Appended data cut inside the first point-data array (the cells are not read).
    let e = error_of(d, "cut.vtu", &bytes[..appended_start(&bytes) + 300]);
    assert!(e.contains("truncated"), "{e}");
    // Bad base64, inline and appended.
    let b64 = std::fs::read_to_string(fixture("dd9_binary_none_u32_f64.vtu")).unwrap();
    let at = b64.find("format=\"binary\"").unwrap();
    let at = at + b64[at..].find('>').unwrap() + 20;
    let mut bad = b64.into_bytes();
    bad[at] = b'#';
    let e = error_of(d, "b64.vtu", &bad);
    assert!(e.contains("bad base64 character '#'"), "{e}");
    // A compressed block that does not inflate: the zlib stream's bytes changed.
    let zlib = std::fs::read(fixture("dd9_appended_zlib_u32_f64.vtp")).unwrap();
    let data = appended_start(&zlib);
    let mut bad = zlib.clone();
    for b in &mut bad[data + 100..data + 120] {
        *b ^= 0x5a;
    }
    let e = error_of(d, "inflate.vtp", &bad);
    assert!(
        e.contains("does not inflate") || e.contains("inflates to"),
        "{e}"
    );
    // LZ4 has no checksum: the first block's token and length bytes changed (its header is
    // 3 + 8 UInt64 words, 88 bytes), so that its literal run outgrows the block.
    let lz4 = std::fs::read(fixture("dd9_appended_lz4_u64_f64.vtu")).unwrap();
    let data = appended_start(&lz4);
    let mut bad = lz4.clone();
    for b in &mut bad[data + 88..data + 92] {
        *b = 0xff;
    }
    let e = error_of(d, "inflate.vtu", &bad);
    assert!(
        e.contains("does not inflate") || e.contains("inflates to"),
        "{e}"
    );
    // A header size the file does not use: UInt32 words read as UInt64 take the data's
    // first bytes into the size. (The other way round goes unnoticed in uncompressed data
    // when the high words are zero, as the offsets leave room for them.)
    let e = error_of(
        d,
        "header.vtp",
        &edited(
            "dd9_appended64_none_u32_f32.vtp",
            "header_type=\"UInt32\"",
            "header_type=\"UInt64\"",
        ),
    );
    assert!(e.contains("header_type of UInt64"), "{e}");
    // A NumberOfPoints the data contradicts, fewer and (far) more.
    let e = error_of(
        d,
        "fewer.vtu",
        &edited(raw, "NumberOfPoints=\"40\"", "NumberOfPoints=\"39\""),
    );
    assert!(
        e.contains("39") && e.contains("NumberOfPoints the data contradicts"),
        "{e}"
    );
    let e = error_of(
        d,
        "lying.vtu",
        &edited(
            raw,
            "NumberOfPoints=\"40\"",
            "NumberOfPoints=\"4000000000000\"",
        ),
    );
    assert!(e.contains("NumberOfPoints the data contradicts"), "{e}");
    let e = error_of(
        d,
        "ascii.vtp",
        &edited(
            "dd9_ascii_none_u32_f32.vtp",
            "NumberOfPoints=\"40\"",
            "NumberOfPoints=\"90000000000\"",
        ),
    );
    assert!(e.contains("cannot fit"), "{e}");
    // Not VTK XML, another dataset type, an unknown compressor.
    let e = error_of(d, "text.vtu", b"hello\n");
    assert!(e.contains("no <VTKFile>"), "{e}");
    let e = error_of(d, "empty.vtu", b"");
    assert!(e.contains("holds no particles"), "{e}");
    let e = error_of(
        d,
        "image.vtu",
        b"<VTKFile type=\"ImageData\"><ImageData/></VTKFile>",
    );
    assert!(e.contains("\"ImageData\" holds no particle points"), "{e}");
    let e = error_of(
        d,
        "lzma.vtu",
        &edited(
            "dd9_appended_lz4_u64_f64.vtu",
            "vtkLZ4DataCompressor",
            "vtkLZMADataCompressor",
        ),
    );
    assert!(
        e.contains("vtkLZMADataCompressor\" is not supported"),
        "{e}"
    );
}

/// `meniscus reconstruct` of the VTK-written `.vtu` and of the legacy `.vtk` it came from
/// give the same bytes: in memory, and tiled (the `.vtu` streamed from disk), with the
/// velocity transferred.
#[test]
fn a_reconstruction_from_the_vtu_equals_the_legacy_files() {
    let dir = tempfile::tempdir().unwrap();
    let legacy = dataset("double_dambreak/ParticleData_Fluid_9.vtk");
    let xml = fixture("frame9_appended_zlib.vtu");
    let tiled = ["--tile-size", "32", "--attributes", "all"];
    for (k, flags) in [&[][..], &tiled[..]].into_iter().enumerate() {
        let mut outputs = Vec::new();
        for input in [&legacy, &xml] {
            let out = dir.path().join(format!("{k}_{}.ply", outputs.len()));
            let mut args = vec![
                "reconstruct",
                input.to_str().unwrap(),
                "-r",
                "0.025",
                "-q",
                "-o",
                out.to_str().unwrap(),
            ];
            args.extend_from_slice(flags);
            let (ok, err) = support::run(&args);
            assert!(ok, "{args:?}: {err}");
            outputs.push(std::fs::read(&out).unwrap());
        }
        assert!(outputs[0].len() > 10_000, "{flags:?}");
        assert!(outputs[0] == outputs[1], "{flags:?}: the outputs differ");
    }
}

/// Mutated VTK-written files (flipped bits, truncations, bytes replaced, counts and
/// offsets made huge) are read or rejected with an error naming the file, whole and
/// streamed; never a panic (the fuzz target `particles_vtk_xml` goes further).
#[test]
fn mutated_vtk_xml_files_are_read_or_rejected_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let bases: Vec<(String, Vec<u8>)> = support::vtk_xml_fixtures()
        .iter()
        .map(|p| {
            let ext = p.extension().unwrap().to_str().unwrap();
            (format!("m.{ext}"), std::fs::read(p).unwrap())
        })
        .collect();
    let huge = [
        "18446744073709551615",
        "4294967295",
        "999999999999",
        "2147483647",
    ];
    let mut rng = support::Rng(0x2545_f491_4f6c_dd1d);
    for round in 0..2000 {
        let (name, base) = &bases[round % bases.len()];
        let bytes = support::mutate(&mut rng, base, &huge, |_, _| {});
        let path = dir.path().join(name);
        std::fs::write(&path, &bytes).unwrap();
        let result = support::without_panic(round, name, &bytes, || {
            let whole = read_particles(&path, None).map(|_| ());
            let format = ParticleFormat::from_path(&path).unwrap();
            let streamed = SpooledParticles::from_file(
                &path,
                format,
                &AttributeSelection::All,
                Some(dir.path()),
                &CancelToken::new(),
            )
            .map(|_| ());
            whole.and(streamed)
        });
        if let Err(e) = result {
            assert!(e.to_string().contains(name.as_str()), "{name}: {e}");
        }
    }
}
