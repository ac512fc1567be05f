//! The `.mseq` archive: round trips within the error bound with identical connectivity,
//! random access, truncation and bit flips detected, interrupted appends recovered.

use meniscus::archive::{ArchiveOptions, ArchiveReader, ArchiveWriter};
use meniscus::io::particles::read_particles;
use meniscus::mesh::TriMesh;
use meniscus::pipeline::{reconstruct, ReconstructOptions};
use std::path::{Path, PathBuf};

fn frames() -> Vec<(i64, TriMesh)> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("datasets");
    [1i64, 9, 17, 25, 31, 45]
        .iter()
        .map(|k| {
            let p = read_particles(
                &root.join(format!("dambreak_small/ParticleData_Fluid_{k}.xyz")),
                None,
            )
            .unwrap();
            let (s, _) = reconstruct(&p.positions, &ReconstructOptions::new(0.012)).unwrap();
            (*k, s.fluid)
        })
        .collect()
}

/// The triangles as a sorted list of lattice-coordinate triples (each in its smallest
/// rotation): equal lists mean equal connectivity up to the permutations the
/// archive allows.
fn canonical(mesh: &TriMesh, step: f64) -> Vec<[[i64; 3]; 3]> {
    let q = |v: u32| {
        mesh.positions[v as usize]
            .to_array()
            .map(|c| (c as f64 / step).round() as i64)
    };
    let mut list: Vec<[[i64; 3]; 3]> = mesh
        .triangles
        .iter()
        .map(|t| {
            let c = t.map(q);
            // The smallest rotation as a whole (two corners may share a lattice point).
            (0..3)
                .map(|r| [c[r], c[(r + 1) % 3], c[(r + 2) % 3]])
                .min()
                .unwrap()
        })
        .collect();
    list.sort_unstable();
    list
}

const BOUND: f64 = 0.01 * 0.012;

fn write_archive(path: &Path, frames: &[(i64, TriMesh)]) {
    let mut w = ArchiveWriter::create(path, &ArchiveOptions::new(BOUND)).unwrap();
    for (n, m) in frames {
        w.append(*n, m).unwrap();
    }
    w.finish().unwrap();
}

#[test]
fn every_frame_round_trips_within_the_bound() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mseq");
    let frames = frames();
    write_archive(&path, &frames);
    let reader = ArchiveReader::open(&path).unwrap();
    assert!(!reader.recovered_by_scan());
    assert_eq!(
        reader.frames().iter().map(|f| f.number).collect::<Vec<_>>(),
        [1, 9, 17, 25, 31, 45]
    );
    let mut stored = 0u64;
    let mut triangles = 0u64;
    let step = 2.0 * BOUND;
    for (n, original) in &frames {
        let back = reader.read_frame(*n).unwrap();
        assert_eq!(
            back.triangle_count(),
            original.triangle_count(),
            "frame {n}"
        );
        assert_eq!(
            canonical(&back, step),
            canonical(original, step),
            "frame {n}: connectivity"
        );
        // Every decoded vertex lies within the bound of an original vertex on its lattice
        // point (plus the f32 rounding of the stored coordinate).
        let mut by_cell: hashbrown::HashMap<[i64; 3], Vec<glam::Vec3>> = hashbrown::HashMap::new();
        for p in &original.positions {
            by_cell
                .entry(p.to_array().map(|c| (c as f64 / step).round() as i64))
                .or_default()
                .push(*p);
        }
        for p in &back.positions {
            let cell = p.to_array().map(|c| (c as f64 / step).round() as i64);
            let err = by_cell[&cell]
                .iter()
                .map(|o| (*o - *p).abs().max_element() as f64)
                .fold(f64::MAX, f64::min);
            assert!(
                err <= BOUND * 1.001 + 1e-7,
                "frame {n}: error {err} > {BOUND}"
            );
        }
        assert_eq!(back.normals.len(), back.positions.len());
        stored += reader
            .frames()
            .iter()
            .find(|f| f.number == *n)
            .unwrap()
            .payload_bytes
            + 48;
        triangles += original.triangle_count() as u64;
    }
    println!("{:.3} bytes per triangle", stored as f64 / triangles as f64);
    // Random access equals sequential decoding.
    let sequential: Vec<TriMesh> = [1i64, 9, 17, 25, 31, 45]
        .iter()
        .map(|n| reader.read_frame(*n).unwrap())
        .collect();
    assert_eq!(reader.read_frame(31).unwrap(), sequential[4]);
    assert!(reader.read_frame(2).is_err());
    assert!(reader.verify().damaged.is_empty());
}

#[test]
fn truncation_and_bit_flips_are_detected() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mseq");
    let frames: Vec<(i64, TriMesh)> = frames().into_iter().take(3).collect();
    write_archive(&path, &frames);
    let bytes = std::fs::read(&path).unwrap();
    let reader = ArchiveReader::open(&path).unwrap();
    let offsets: Vec<u64> = reader.frames().iter().map(|f| f.offset).collect();
    // Truncation at every frame boundary and in the middle of every frame: the complete
    // frames before the cut remain readable, nothing after it is claimed.
    let cut_path = dir.path().join("cut.mseq");
    for (k, &offset) in offsets.iter().enumerate() {
        for cut in [offset as usize, offset as usize + 30, offset as usize + 200] {
            std::fs::write(&cut_path, &bytes[..cut]).unwrap();
            let r = ArchiveReader::open(&cut_path).unwrap();
            assert!(r.recovered_by_scan());
            assert_eq!(r.frames().len(), k, "cut at {cut}");
            let report = r.verify();
            assert!(report.damaged.is_empty() && report.good.len() == k);
        }
    }
    // A bit flip in each frame's payload: that frame is reported by number, the others
    // still decode.
    let flip_path = dir.path().join("flip.mseq");
    for (k, f) in reader.frames().iter().enumerate() {
        let mut damaged = bytes.clone();
        let at = f.offset as usize + 48 + (f.payload_bytes as usize) / 2;
        damaged[at] ^= 0x10;
        std::fs::write(&flip_path, &damaged).unwrap();
        let r = ArchiveReader::open(&flip_path).unwrap();
        let report = r.verify();
        assert_eq!(report.damaged.len(), 1, "flip in frame {k}");
        assert_eq!(report.damaged[0].0, f.number);
        assert!(
            report.damaged[0].1.contains("checksum"),
            "{}",
            report.damaged[0].1
        );
        assert_eq!(report.good.len(), frames.len() - 1);
        let msg = r.read_frame(f.number).unwrap_err().to_string();
        assert!(msg.contains(&format!("frame {}", f.number)), "{msg}");
    }
    // A flip in a record header: the frames before it remain (by scan if need be).
    let mut damaged = bytes.clone();
    damaged[offsets[2] as usize + 5] ^= 1;
    std::fs::write(&flip_path, &damaged).unwrap();
    let r = ArchiveReader::open(&flip_path).unwrap();
    assert!(r.frames().len() >= 2);
    // Not an archive at all.
    std::fs::write(&flip_path, b"hello").unwrap();
    assert!(ArchiveReader::open(&flip_path).is_err());
}

#[test]
fn appends_resume_after_interruption_and_refuse_damage() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mseq");
    let frames = frames();
    write_archive(&path, &frames[..2]);
    // A normal append keeps the earlier frames byte for byte.
    let before = std::fs::read(&path).unwrap();
    let first_index = ArchiveReader::open(&path).unwrap().frames()[1].offset as usize;
    let mut w = ArchiveWriter::open_append(&path, &ArchiveOptions::new(BOUND)).unwrap();
    assert_eq!(w.frame_numbers(), [1, 9]);
    w.append(frames[2].0, &frames[2].1).unwrap();
    assert!(
        w.append(frames[2].0, &frames[2].1).is_err(),
        "duplicate frame numbers are refused"
    );
    // Interrupted: dropped without finish, so there is no index.
    drop(w);
    let after = std::fs::read(&path).unwrap();
    assert_eq!(&after[..first_index], &before[..first_index]);
    // A half-written record at the end, as a crash mid-append leaves it.
    let mut crashed = after.clone();
    crashed.extend_from_slice(&after[first_index..first_index + 100]);
    std::fs::write(&path, &crashed).unwrap();
    let r = ArchiveReader::open(&path).unwrap();
    assert!(r.recovered_by_scan());
    assert_eq!(r.frames().len(), 3);
    // The next run resumes: the incomplete record is cut, new frames follow.
    let mut w = ArchiveWriter::open_append(&path, &ArchiveOptions::new(BOUND)).unwrap();
    w.append(frames[3].0, &frames[3].1).unwrap();
    w.finish().unwrap();
    let r = ArchiveReader::open(&path).unwrap();
    assert!(!r.recovered_by_scan());
    assert_eq!(
        r.frames().iter().map(|f| f.number).collect::<Vec<_>>(),
        [1, 9, 17, 25]
    );
    assert!(r.verify().damaged.is_empty());
    // A damaged frame makes appending refuse instead of losing anything.
    let mut bytes = std::fs::read(&path).unwrap();
    let f = &r.frames()[1];
    bytes[f.offset as usize + 60] ^= 0xff;
    std::fs::write(&path, &bytes).unwrap();
    let err = ArchiveWriter::open_append(&path, &ArchiveOptions::new(BOUND))
        .err()
        .expect("refused");
    assert!(err.to_string().contains("damaged"), "{err}");
    assert_eq!(
        std::fs::read(&path).unwrap(),
        bytes,
        "a refused append changes nothing"
    );
}
