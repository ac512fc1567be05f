//! The streaming reader of positions (`stream_positions`, what a run and the radius
//! estimate read) and the whole-file reader (`read_particles`) on mutated files of every
//! streaming format (issue 38): one set of checks. The stream takes a file (`Ok(Some)`)
//! only when the whole reader takes it, and then gives the same particles in the same
//! order; it never rejects what the whole reader takes; a layout it does not follow is
//! `Ok(None)`, left to the whole reader. Damage after the points (an array the run does
//! not use, a later section or element) is refused by both.

mod support;

use meniscus::io::particles::{read_particles, stream_positions, write_particles, ParticleFormat};
use std::path::PathBuf;

#[test]
fn the_stream_of_positions_agrees_with_the_whole_reader_on_mutated_files() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let frame = root.join("datasets/dambreak_small/ParticleData_Fluid_25.bgeo");
    let mut small = read_particles(&frame, None).unwrap();
    small.positions.truncate(300);
    for a in &mut small.attributes {
        a.values.truncate(300 * a.components);
    }
    let mut bases: Vec<(String, Vec<u8>)> = vec![("m.bgeo".into(), std::fs::read(&frame).unwrap())];
    for (ext, format) in [("ply", ParticleFormat::Ply), ("vtk", ParticleFormat::Vtk)] {
        let path = dir.path().join(format!("s.{ext}"));
        write_particles(&path, &small, format).unwrap();
        bases.push((format!("m.{ext}"), std::fs::read(&path).unwrap()));
    }
    // A PLY with a face element after the vertices (the stream walks its rows too).
    let mut faced = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
    for v in [0f32, 0., 0., 1., 0., 0., 0., 1., 0.] {
        faced.extend_from_slice(&v.to_le_bytes());
    }
    for face in [[0i32, 1, 2], [2, 1, 0]] {
        faced.push(3);
        for i in face {
            faced.extend_from_slice(&i.to_le_bytes());
        }
    }
    bases.push(("f.ply".into(), faced));
    bases.push((
        "fa.ply".into(),
        b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 2 1 0\n".to_vec(),
    ));
    for p in support::vtk_xml_fixtures() {
        let ext = p.extension().unwrap().to_str().unwrap();
        bases.push((format!("m.{ext}"), std::fs::read(&p).unwrap()));
    }
    let huge = [
        "18446744073709551615",
        "4294967295",
        "999999999999",
        "0",
        "1",
    ];
    let mut rng = support::Rng(0x1234_5678_9abc_def1);
    let (mut both, mut neither) = (0, 0);
    for round in 0..1500 {
        let (name, base) = &bases[round % bases.len()];
        let bytes = support::mutate(&mut rng, base, &huge, |_, _| {});
        let path = dir.path().join(name);
        std::fs::write(&path, &bytes).unwrap();
        let whole = read_particles(&path, None);
        let mut streamed = Vec::new();
        let stream = stream_positions(&path, None, &mut |chunk| {
            streamed.extend_from_slice(chunk);
            Ok(())
        });
        match (whole, stream) {
            (Ok(whole), Ok(Some(count))) => {
                both += 1;
                assert_eq!(count, whole.positions.len(), "round {round}, {name}");
                assert!(
                    whole.positions == streamed,
                    "round {round}, {name}: positions differ"
                );
            }
            (Ok(_), Err(e)) => {
                panic!("round {round}, {name}: the stream rejects what the whole reader reads: {e}")
            }
            (Err(_), Err(_)) => neither += 1,
            (Err(e), Ok(Some(_))) => {
                panic!("round {round}, {name}: the stream takes what the whole reader refuses: {e}")
            }
            _ => {}
        }
    }
    // The mutations must exercise both outcomes.
    assert!(
        both > 100 && neither > 100,
        "both {both}, neither {neither}"
    );
}

/// Files damaged only after the points, one per streaming layout: the whole reader refuses
/// each, so the stream must not take it; the same files undamaged are taken by both.
#[test]
fn damage_after_the_points_is_refused_by_the_stream_too() {
    let dir = tempfile::tempdir().unwrap();
    let vtk = |density: &str| {
        format!(
            "# vtk DataFile Version 3.0\nt\nASCII\nDATASET POLYDATA\nPOINTS 2 float\n0 0 0 1 1 1\n\
             POINT_DATA 2\nSCALARS density float 1\nLOOKUP_TABLE default\n{density}\n"
        )
    };
    let vtu = |density: &str| {
        format!(
            "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"0.1\" byte_order=\"LittleEndian\">\n\
             <UnstructuredGrid><Piece NumberOfPoints=\"2\" NumberOfCells=\"0\">\n\
             <Points><DataArray type=\"Float32\" NumberOfComponents=\"3\" format=\"ascii\">0 0 0 1 1 1</DataArray></Points>\n\
             <PointData><DataArray type=\"Float32\" Name=\"density\" format=\"ascii\">{density}</DataArray></PointData>\n\
             </Piece></UnstructuredGrid></VTKFile>\n"
        )
    };
    let ply = |face: &str| {
        format!(
            "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n\
             element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 1 1\n{face}\n"
        )
    };
    let binary_ply = |cut: usize| {
        let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
        for v in [0f32, 0., 0., 1., 1., 1.] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.push(3);
        for i in [0i32, 1, 0] {
            b.extend_from_slice(&i.to_le_bytes());
        }
        b.truncate(b.len() - cut);
        b
    };
    let cases = [
        ("b.ply", binary_ply(0), binary_ply(4)),
        (
            "a.vtk",
            vtk("1000 1000").into_bytes(),
            vtk("1000 x1000").into_bytes(),
        ),
        (
            "a.vtu",
            vtu("1000 1000").into_bytes(),
            vtu("1000 oops").into_bytes(),
        ),
        (
            "a.ply",
            ply("3 0 1 0").into_bytes(),
            ply("3 0 1").into_bytes(),
        ),
    ];
    for (name, good, bad) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, good).unwrap();
        let whole = read_particles(&path, None).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(whole.positions.len(), 2, "{name}");
        let mut streamed = Vec::new();
        let stream = stream_positions(&path, None, &mut |chunk| {
            streamed.extend_from_slice(chunk);
            Ok(())
        });
        if let Ok(Some(n)) = stream {
            assert_eq!((n, &streamed), (2, &whole.positions), "{name}");
        } else {
            assert!(
                matches!(stream, Ok(None)),
                "{name}: the stream refuses a good file"
            );
        }
        std::fs::write(&path, bad).unwrap();
        assert!(
            read_particles(&path, None).is_err(),
            "{name}: the damage is not damage"
        );
        let stream = stream_positions(&path, None, &mut |_| Ok(()));
        assert!(
            !matches!(stream, Ok(Some(_))),
            "{name}: the stream takes a file the whole reader refuses"
        );
    }
}
