//! The streaming reader of positions (`stream_positions`, what a run and the radius
//! estimate read) and the whole-file reader (`read_particles`) on mutated files of every
//! streaming format (issue 38): the stream never rejects what the whole reader accepts,
//! and when both accept they give the same particles in the same order. The stream may
//! accept a file whose damage lies after the points (another array, a later section): it
//! does not read that part, by design (documented on `stream_positions`).

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
            _ => {}
        }
    }
    // The mutations must exercise both outcomes.
    assert!(
        both > 100 && neither > 100,
        "both {both}, neither {neither}"
    );
}
