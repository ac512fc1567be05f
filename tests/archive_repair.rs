//! Archives that appending, finishing and `archive repair` must not make worse: a record
//! whose length field lies (its header re-checksummed), an archive holding every frame
//! but no index, and damaged or cut archives repaired with every readable frame kept
//! byte for byte.

mod support;

use meniscus::archive::{ArchiveOptions, ArchiveReader, ArchiveWriter};
use std::path::Path;
use support::archive::{
    assert_still_readable, index_offset, payload_len, readable, set_payload_len, small_mesh,
};

const BOUND: f64 = 1e-3;

/// A finished archive at `path` of frames `0..count` ([`small_mesh`]); its bytes and
/// its records' offsets.
fn small_archive(path: &Path, count: i64) -> (Vec<u8>, Vec<usize>) {
    let mut w = ArchiveWriter::create(path, &ArchiveOptions::new(BOUND)).unwrap();
    for k in 0..count {
        w.append(k, &small_mesh(k)).unwrap();
    }
    w.finish().unwrap();
    let offsets = ArchiveReader::open(path)
        .unwrap()
        .frames()
        .iter()
        .map(|f| f.offset as usize)
        .collect();
    (std::fs::read(path).unwrap(), offsets)
}

/// Appends frame 100 to the archive at `path` and finishes it.
fn append_one(path: &Path) -> meniscus::Result<()> {
    let mut w = ArchiveWriter::open_append(path, &ArchiveOptions::new(BOUND))?;
    w.append(100, &small_mesh(100))?;
    w.finish()
}

#[test]
fn an_append_after_a_record_whose_length_lies_keeps_every_readable_frame() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mseq");
    let (base, offsets) = small_archive(&path, 4);
    let records_end = index_offset(&base);
    for (k, &offset) in offsets.iter().enumerate() {
        let len = payload_len(&base, offset);
        for claimed in [len + 1, len - 1, len + 100, len + 60] {
            for with_index in [true, false] {
                let mut bytes = base.clone();
                set_payload_len(&mut bytes, offset, claimed);
                if !with_index {
                    bytes.truncate(records_end);
                }
                let what =
                    format!("record {k} claims {claimed} of {len} bytes, index {with_index}");
                std::fs::write(&path, &bytes).unwrap();
                let before = readable(&path);
                assert!(before.len() >= 3, "{what}: one frame lost at most");
                match append_one(&path) {
                    Err(e) => {
                        let e = e.to_string();
                        assert!(
                            e.contains("archive repair") && e.contains("run.mseq"),
                            "{what}: {e}"
                        );
                        assert_eq!(
                            std::fs::read(&path).unwrap(),
                            bytes,
                            "{what}: refused, unchanged"
                        );
                    }
                    Ok(()) => {
                        assert_still_readable(&path, &before, &what);
                        let r = ArchiveReader::open(&path).unwrap();
                        assert!(r.read_surface(100).is_ok(), "{what}: the appended frame");
                    }
                }
            }
        }
    }
    // The case the append used to get wrong: the last record claims one byte more, the
    // index is intact. Refused, through the library and the CLI, naming the repair.
    let mut bytes = base.clone();
    let last = *offsets.last().unwrap();
    set_payload_len(&mut bytes, last, payload_len(&base, last) + 1);
    std::fs::write(&path, &bytes).unwrap();
    let e = append_one(&path).unwrap_err().to_string();
    assert!(e.contains("frame 3") && e.contains("length field"), "{e}");
    let mesh = dir.path().join("m_5.obj");
    let surface = meniscus::mesh::Surface {
        fluid: small_mesh(5),
        spheres: Default::default(),
    };
    meniscus::io::mesh::write_surface(&mesh, &surface, &Default::default()).unwrap();
    let out = support::meniscus()
        .args(["archive", "pack", "--error-bound", "1e-3", "-o"])
        .arg(&path)
        .arg(dir.path().join("m_{}.obj"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(stderr.contains("meniscus archive repair"), "{stderr}");
    assert_eq!(std::fs::read(&path).unwrap(), bytes, "refused, unchanged");
}

/// The record of each frame of the archive `bytes` (at `path`): number and bytes.
fn records(path: &Path) -> Vec<(i64, Vec<u8>)> {
    let bytes = std::fs::read(path).unwrap();
    let r = ArchiveReader::open(path).unwrap();
    r.frames()
        .iter()
        .map(|f| {
            let start = f.offset as usize;
            (
                f.number,
                bytes[start..start + f.record_bytes() as usize].to_vec(),
            )
        })
        .collect()
}

#[test]
fn an_archive_with_every_frame_but_no_index_is_finished_by_a_skipping_run() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mseq");
    let (base, _) = small_archive(&path, 3);
    // What a run killed between its last record and its index leaves.
    std::fs::write(&path, &base[..index_offset(&base)]).unwrap();
    let verify = support::meniscus()
        .args(["archive", "verify"])
        .arg(&path)
        .output()
        .unwrap();
    assert!(!verify.status.success());
    let stderr = String::from_utf8_lossy(&verify.stderr);
    assert!(stderr.contains("meniscus archive repair"), "{stderr}");
    let merged = dir.path().join("all.mseq");
    let (ok, stderr) = support::run(&[
        "archive",
        "merge",
        path.to_str().unwrap(),
        "-o",
        merged.to_str().unwrap(),
    ]);
    assert!(
        !ok && stderr.contains("meniscus archive repair"),
        "{stderr}"
    );
    // The re-run with --skip-existing holds every frame: it writes the index.
    let sphere = support::dataset("analytic/sphere.xyz");
    for k in 0..3 {
        std::fs::copy(&sphere, dir.path().join(format!("f_{k}.xyz"))).unwrap();
    }
    let input = dir.path().join("f_{}.xyz");
    let (ok, stderr) = support::run(&[
        "reconstruct",
        input.to_str().unwrap(),
        "-o",
        path.to_str().unwrap(),
        "-r",
        "0.025",
        "--skip-existing",
        "-q",
    ]);
    assert!(ok, "{stderr}");
    assert_eq!(
        std::fs::read(&path).unwrap(),
        base,
        "the index a finished run writes"
    );
    // Through the library, the same; an archive with its index is left alone.
    std::fs::write(&path, &base[..index_offset(&base)]).unwrap();
    assert!(ArchiveWriter::finish_unindexed(&path).unwrap());
    assert_eq!(std::fs::read(&path).unwrap(), base);
    assert!(!ArchiveWriter::finish_unindexed(&path).unwrap());
    assert_eq!(std::fs::read(&path).unwrap(), base);
}

/// Repairs `damaged` (written to `dir/damaged.mseq`) and checks what every repair
/// promises: every frame readable before is kept, its record byte for byte (or, for
/// `relengthed` frames, its payload with the length corrected), the result verifies
/// clean through its index; returns the frames kept.
fn repair_keeps_every_readable_frame(
    dir: &Path,
    damaged: &[u8],
    original: &[(i64, Vec<u8>)],
    what: &str,
) -> Vec<i64> {
    let path = dir.join("damaged.mseq");
    let out = dir.join("repaired.mseq");
    let _ = std::fs::remove_file(&out);
    std::fs::write(&path, damaged).unwrap();
    let before = readable(&path);
    let report = meniscus::archive::repair(&path, &out).unwrap_or_else(|e| panic!("{what}: {e}"));
    assert_eq!(
        std::fs::read(&path).unwrap(),
        damaged,
        "{what}: input unchanged"
    );
    let r = ArchiveReader::open(&out).unwrap();
    let v = r.verify();
    assert!(v.is_clean() && !r.recovered_by_scan(), "{what}: {v:?}");
    assert_eq!(v.good, report.kept, "{what}");
    assert_still_readable(&out, &before, what);
    for (n, record) in records(&out) {
        let (_, original) = original.iter().find(|(m, _)| *m == n).unwrap();
        if report.relengthed.contains(&n) {
            assert_eq!(record[48..], original[48..], "{what}: frame {n}'s payload");
        } else {
            assert_eq!(record, *original, "{what}: frame {n}'s record");
        }
    }
    report.kept
}

#[test]
fn repair_keeps_every_readable_frame_of_cut_and_damaged_archives() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mseq");
    let (base, offsets) = small_archive(&path, 5);
    let original = records(&path);
    let all: Vec<i64> = (0..5).collect();
    let end_of = |k: usize| offsets[k] + original[k].1.len();
    // Cut at every sixteenth: the frames complete before the cut.
    for sixteenth in 1..16 {
        let cut = base.len() * sixteenth / 16;
        let complete: Vec<i64> = (0..5).filter(|&k| end_of(k as usize) <= cut).collect();
        let what = format!("cut at {cut}");
        let kept = repair_keeps_every_readable_frame(dir.path(), &base[..cut], &original, &what);
        assert_eq!(kept, complete, "{what}");
    }
    let records_end = index_offset(&base);
    for (k, &offset) in offsets.iter().enumerate() {
        let others: Vec<i64> = all.iter().copied().filter(|&n| n != k as i64).collect();
        // A flipped bit in the payload, in the header (checksum mismatch): that frame.
        for (at, field) in [(offset + 60, "payload"), (offset + 17, "header")] {
            let mut b = base.clone();
            b[at] ^= 0x08;
            let what = format!("frame {k}: bit flip in its {field}");
            let kept = repair_keeps_every_readable_frame(dir.path(), &b, &original, &what);
            assert_eq!(kept, others, "{what}");
        }
        // A length field that lies, with or without the index: every frame, this one
        // with its length corrected.
        for delta in [1i64, -1, 37] {
            for with_index in [true, false] {
                let mut b = base.clone();
                let len = payload_len(&b, offset) as i64;
                set_payload_len(&mut b, offset, (len + delta) as u64);
                if !with_index {
                    b.truncate(records_end);
                }
                let what = format!("frame {k}: length {delta:+}, index {with_index}");
                let kept = repair_keeps_every_readable_frame(dir.path(), &b, &original, &what);
                assert_eq!(kept, all, "{what}");
            }
        }
        // The record written twice: kept once.
        let mut b = base[..records_end].to_vec();
        b.extend_from_slice(&original[k].1);
        let what = format!("frame {k} twice");
        let kept = repair_keeps_every_readable_frame(dir.path(), &b, &original, &what);
        assert_eq!(kept, all, "{what}");
        // Garbage before the record: skipped.
        let mut b = base.clone();
        b.splice(offset..offset, b"GARBAGE!".iter().copied());
        let what = format!("garbage before frame {k}");
        let kept = repair_keeps_every_readable_frame(dir.path(), &b, &original, &what);
        assert_eq!(kept, all, "{what}");
    }
    // Records swapped (the index now wrong): every frame, in file order.
    let mut b = base[..offsets[1]].to_vec();
    b.extend_from_slice(&original[2].1);
    b.extend_from_slice(&original[1].1);
    b.extend_from_slice(&base[offsets[3]..]);
    let kept = repair_keeps_every_readable_frame(dir.path(), &b, &original, "swapped");
    assert_eq!(kept, [0, 2, 1, 3, 4]);
    // No index, a damaged index, an index pointing elsewhere: every frame, and the
    // repaired archive is the original byte for byte.
    let mut damaged_index = base.clone();
    damaged_index[records_end + 20] ^= 1;
    let mut elsewhere = base.clone();
    let n = elsewhere.len();
    elsewhere[n - 16..n - 8].copy_from_slice(&(offsets[2] as u64).to_le_bytes());
    for (b, what) in [
        (&base[..records_end], "no index"),
        (&damaged_index[..], "damaged index"),
        (&elsewhere[..], "index pointing elsewhere"),
        (&base[..], "intact"),
    ] {
        let kept = repair_keeps_every_readable_frame(dir.path(), b, &original, what);
        assert_eq!(kept, all, "{what}");
        let repaired = std::fs::read(dir.path().join("repaired.mseq")).unwrap();
        assert!(repaired == base, "{what}: the original archive");
    }
}

#[test]
fn archive_repair_on_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mseq");
    let (base, offsets) = small_archive(&path, 4);
    let mut b = base.clone();
    b[offsets[1] + 60] ^= 1;
    b.truncate(offsets[3] + 100);
    std::fs::write(&path, &b).unwrap();
    let fixed = dir.path().join("fixed.mseq");
    let (ok, stderr) = support::run(&[
        "archive",
        "repair",
        path.to_str().unwrap(),
        "-o",
        fixed.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    assert!(
        stderr.contains("dropped frame 1") && stderr.contains("dropped frame 3"),
        "{stderr}"
    );
    assert!(stderr.contains("2 frame(s) kept"), "{stderr}");
    assert_eq!(ArchiveReader::open(&fixed).unwrap().verify().good, [0, 2]);
    // An existing output that is not the archive is refused; without -o, in place.
    let (ok, stderr) = support::run(&[
        "archive",
        "repair",
        path.to_str().unwrap(),
        "-o",
        fixed.to_str().unwrap(),
    ]);
    assert!(!ok && stderr.contains("exists"), "{stderr}");
    let (ok, stderr) = support::run(&["archive", "repair", path.to_str().unwrap()]);
    assert!(ok, "{stderr}");
    assert_eq!(
        std::fs::read(&path).unwrap(),
        std::fs::read(&fixed).unwrap()
    );
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains("tmp"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

/// A structure-aware mutation of the finished archive `base` (records at `offsets`, each
/// `lens[k]` bytes): header fields changed and re-checksummed (a lying length, frame
/// number or count), records swapped, duplicated or cut short, the index removed or
/// pointed elsewhere; sometimes two of them. Returns the bytes and what was done.
fn mutate_structure(
    rng: &mut support::Rng,
    base: &[u8],
    offsets: &[usize],
    lens: &[usize],
) -> (Vec<u8>, String) {
    let records_end = index_offset(base);
    let record = |k: usize| &base[offsets[k]..offsets[k] + lens[k]];
    let k = rng.below(offsets.len());
    let j = rng.below(offsets.len());
    // Two different records, in file order.
    let (lo, hi) = match (k.min(j), k.max(j)) {
        (a, b) if a == b && b + 1 < offsets.len() => (a, b + 1),
        (a, b) if a == b => (a - 1, b),
        pair => pair,
    };
    let mut b = base.to_vec();
    let what = match rng.below(7) {
        0 => {
            let len = payload_len(&b, offsets[k]) as i64;
            let delta = rng.below(129) as i64 - 64;
            set_payload_len(&mut b, offsets[k], (len + delta).max(0) as u64);
            format!("record {k} length {delta:+}")
        }
        1 => {
            // The frame number, the vertex or the triangle count.
            let field = [4usize, 12, 16][rng.below(3)];
            b[offsets[k] + field] = b[offsets[j] + field].wrapping_add(rng.below(2) as u8);
            support::archive::reseal_header(&mut b, offsets[k]);
            format!("record {k} field {field} from record {j}")
        }
        2 => {
            let mut swapped = base[..offsets[lo]].to_vec();
            swapped.extend_from_slice(record(hi));
            swapped.extend_from_slice(&base[offsets[lo] + lens[lo]..offsets[hi]]);
            swapped.extend_from_slice(record(lo));
            swapped.extend_from_slice(&base[offsets[hi] + lens[hi]..]);
            b = swapped;
            format!("records {lo} and {hi} swapped")
        }
        3 => {
            let at = offsets[j];
            b.splice(at..at, record(k).iter().copied());
            format!("record {k} copied before record {j}")
        }
        4 => {
            let cut = offsets[k] + 1 + rng.below(lens[k] - 1);
            b.drain(cut..offsets[k] + lens[k]);
            format!("record {k} cut at {cut}")
        }
        5 => {
            b.truncate(records_end);
            "index removed".to_string()
        }
        _ => {
            let n = b.len();
            let to = offsets[k] as u64 + rng.below(64) as u64;
            b[n - 16..n - 8].copy_from_slice(&to.to_le_bytes());
            format!("index pointed at {to}")
        }
    };
    if rng.below(4) == 0 && b.len() > records_end && b.ends_with(b"MSEQEND!") {
        let n = b.len();
        let index = u64::from_le_bytes(b[n - 16..n - 8].try_into().unwrap()) as usize;
        b.truncate(index.min(n));
        return (b, format!("{what}, then the index removed"));
    }
    (b, what)
}

#[test]
fn structure_aware_mutations_never_make_a_readable_frame_unreadable() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.mseq");
    let repaired = dir.path().join("repaired.mseq");
    let merged = dir.path().join("merged.mseq");
    let (base, offsets) = small_archive(&path, 4);
    let lens: Vec<usize> = records(&path).iter().map(|r| r.1.len()).collect();
    let mut rng = support::Rng(0x243f_6a88_85a3_08d3);
    for round in 0..400 {
        let (b, what) = mutate_structure(&mut rng, &base, &offsets, &lens);
        let what = format!("round {round}: {what}");
        std::fs::write(&path, &b).unwrap();
        let before = readable(&path);
        // Repair: every readable frame kept, the result clean.
        let _ = std::fs::remove_file(&repaired);
        match meniscus::archive::repair(&path, &repaired) {
            Ok(report) => {
                assert_still_readable(&repaired, &before, &what);
                let v = ArchiveReader::open(&repaired).unwrap().verify();
                assert!(v.is_clean() && v.good == report.kept, "{what}: {v:?}");
            }
            Err(e) => panic!("{what}: repair failed: {e}"),
        }
        // Merge: refused, or every readable frame in the output.
        let _ = std::fs::remove_file(&merged);
        if meniscus::archive::merge(std::slice::from_ref(&path), &merged).is_ok() {
            assert_still_readable(&merged, &before, &format!("{what}, merged"));
        }
        // Append: refused with the file unchanged, or every readable frame still read.
        match append_one(&path) {
            Ok(()) => assert_still_readable(&path, &before, &format!("{what}, appended")),
            Err(_) => assert_eq!(
                std::fs::read(&path).unwrap(),
                b,
                "{what}: refused, unchanged"
            ),
        }
    }
}
