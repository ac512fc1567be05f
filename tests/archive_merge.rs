//! `archive merge`: archives joined into one byte-identical to one writer's, conflicts
//! and damage refused without leaving an output.

mod support;

use meniscus::archive::{ArchiveOptions, ArchiveReader, ArchiveWriter};
use meniscus::mesh::TriMesh;
use std::path::{Path, PathBuf};
use support::archive::{bumpy, with_attributes};
use support::names_in;

/// An archive of small synthetic meshes as frames `numbers`, with error bound `bound`.
fn small_archive(path: &Path, numbers: &[i64], bound: f64) {
    let mut w = ArchiveWriter::create(path, &ArchiveOptions::new(bound)).unwrap();
    for &n in numbers {
        w.append(n, &bumpy(2, 0.3 + 0.01 * n as f32)).unwrap();
    }
    w.finish().unwrap();
}

#[test]
fn merging_interleaves_frames_and_equals_one_writer() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n);
    small_archive(&p("even.mseq"), &[0, 2, 4], 1e-4);
    small_archive(&p("odd.mseq"), &[1, 3], 1e-4);
    small_archive(&p("one.mseq"), &[0, 1, 2, 3, 4], 1e-4);
    let stats =
        meniscus::archive::merge(&[p("odd.mseq"), p("even.mseq")], &p("all/merged.mseq")).unwrap();
    assert_eq!((stats.inputs, stats.frames), (2, 5));
    let merged = std::fs::read(p("all/merged.mseq")).unwrap();
    assert_eq!(stats.bytes, merged.len() as u64);
    assert!(
        merged == std::fs::read(p("one.mseq")).unwrap(),
        "byte-identical to one writer's archive"
    );
    let r = ArchiveReader::open(&p("all/merged.mseq")).unwrap();
    assert!(r.verify().is_clean());
    // One input: the same archive again.
    meniscus::archive::merge(&[p("one.mseq")], &p("copy.mseq")).unwrap();
    assert_eq!(std::fs::read(p("copy.mseq")).unwrap(), merged);
    // Into one of its inputs: replaced whole.
    small_archive(&p("later.mseq"), &[7], 1e-4);
    meniscus::archive::merge(&[p("copy.mseq"), p("later.mseq")], &p("copy.mseq")).unwrap();
    let numbers: Vec<i64> = ArchiveReader::open(&p("copy.mseq"))
        .unwrap()
        .frames()
        .iter()
        .map(|f| f.number)
        .collect();
    assert_eq!(numbers, [0, 1, 2, 3, 4, 7]);
}

#[test]
fn merging_refuses_conflicts_and_damage_and_leaves_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n);
    small_archive(&p("a.mseq"), &[0, 1], 1e-4);
    small_archive(&p("b.mseq"), &[1, 2], 1e-4);
    small_archive(&p("coarse.mseq"), &[5], 2e-4);
    let out = p("out.mseq");
    let refused = |inputs: &[&str]| -> String {
        let inputs: Vec<PathBuf> = inputs.iter().map(|n| p(n)).collect();
        let e = meniscus::archive::merge(&inputs, &out)
            .unwrap_err()
            .to_string();
        assert!(!out.exists(), "no output on error: {e}");
        e
    };
    let e = refused(&["a.mseq", "b.mseq"]);
    assert!(
        e.contains("b.mseq: frame 1: also in") && e.contains("a.mseq"),
        "{e}"
    );
    let e = refused(&["a.mseq", "coarse.mseq"]);
    assert!(
        e.contains("error bound 0.0002 differs from the error bound 0.0001")
            && e.contains("a.mseq")
            && e.contains("coarse.mseq"),
        "{e}"
    );
    let e = refused(&["a.mseq", "a.mseq"]);
    assert!(e.contains("a.mseq: frame 0: given twice"), "{e}");
    // A flipped payload byte: refused, naming the frame.
    let mut bytes = std::fs::read(p("b.mseq")).unwrap();
    let r = ArchiveReader::open(&p("b.mseq")).unwrap();
    let f = &r.frames()[1];
    bytes[(f.offset + 48 + f.payload_bytes / 2) as usize] ^= 0x10;
    std::fs::write(p("bad.mseq"), &bytes).unwrap();
    // (opening finds no damage in the headers: the payload checksum is checked on copy)
    let e = refused(&["bad.mseq"]);
    assert!(
        e.contains("bad.mseq") && e.contains("frame 2") && e.contains("checksum"),
        "{e}"
    );
    // An unfinished archive (no index, a record cut off): refused.
    let a = ArchiveReader::open(&p("a.mseq")).unwrap();
    let cut = &std::fs::read(p("a.mseq")).unwrap()[..(a.frames()[1].offset as usize + 10)];
    std::fs::write(p("cut.mseq"), cut).unwrap();
    let e = refused(&["cut.mseq"]);
    assert!(e.contains("cut.mseq") && e.contains("unfinished"), "{e}");
    // An existing output that is no input is not overwritten.
    std::fs::write(&out, b"keep").unwrap();
    let e = meniscus::archive::merge(&[p("a.mseq")], &out)
        .unwrap_err()
        .to_string();
    assert!(e.contains("exists"), "{e}");
    assert_eq!(std::fs::read(&out).unwrap(), b"keep");
    std::fs::remove_file(&out).unwrap();
    // No temporary file is left behind.
    assert!(
        names_in(dir.path()).iter().all(|n| !n.contains("merging")),
        "{:?}",
        names_in(dir.path())
    );
}

#[test]
fn merging_a_version_4_input_gives_what_one_writer_gives() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n);
    let plain = bumpy(2, 0.3);
    let carried = with_attributes(bumpy(2, 0.4));
    let write = |path: &Path, frames: &[(i64, &TriMesh)]| {
        let mut w = ArchiveWriter::create(path, &ArchiveOptions::new(1e-4)).unwrap();
        for (n, mesh) in frames {
            w.append(*n, mesh).unwrap();
        }
        w.finish().unwrap();
    };
    write(&p("plain.mseq"), &[(0, &plain), (2, &plain)]);
    write(&p("attrs.mseq"), &[(1, &carried)]);
    // One writer: version 3 until frame 1 makes it version 4.
    write(&p("one.mseq"), &[(0, &plain), (1, &carried), (2, &plain)]);
    assert_eq!(ArchiveReader::open(&p("plain.mseq")).unwrap().version(), 3);
    meniscus::archive::merge(&[p("plain.mseq"), p("attrs.mseq")], &p("merged.mseq")).unwrap();
    let merged = ArchiveReader::open(&p("merged.mseq")).unwrap();
    assert_eq!(merged.version(), 4);
    assert!(merged.verify().is_clean());
    assert!(std::fs::read(p("merged.mseq")).unwrap() == std::fs::read(p("one.mseq")).unwrap());
}
