//! Damage and interruptions in the `.mseq` archive: truncation and bit flips detected and
//! named by frame, a damaged record costing only its frame, appends that resume after an
//! interruption and refuse damage, and writers that fail, panic or are interrupted
//! partway leaving a consistent archive.

mod support;

use meniscus::archive::{ArchiveFrame, ArchiveOptions, ArchiveReader, ArchiveWriter};
use meniscus::isolated::icosphere;
use meniscus::mesh::{SphereInstances, Surface, TriMesh};
use meniscus::pipeline::ReconstructOptions;
use std::path::Path;
use support::archive::{
    archive_frame, decoded, frames, index_offset, small_mesh, write_archive, BOUND,
};

#[test]
fn truncation_and_bit_flips_are_detected() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mseq");
    let frames: Vec<(i64, Surface)> = frames().into_iter().take(3).collect();
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
            assert_eq!(report.good.len(), k);
            // The missing index is damage; a record cut in its payload names its frame.
            assert!(!report.is_clean(), "cut at {cut}");
            let cut_frame = report.damaged.iter().map(|d| d.0).collect::<Vec<_>>();
            if cut == offset as usize + 200 {
                assert_eq!(cut_frame, [frames[k].0], "cut at {cut}");
            } else {
                assert!(cut_frame.is_empty(), "cut at {cut}");
            }
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
    assert_eq!(r.frames().len(), 2);
    let report = r.verify();
    assert_eq!(report.damaged.len(), 1);
    assert_eq!(report.damaged[0].0, frames[2].0);
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
    w.append_frame(frames[2].0, &archive_frame(&frames[2].1))
        .unwrap();
    assert!(
        w.append_frame(frames[2].0, &archive_frame(&frames[2].1))
            .is_err(),
        "duplicate frame numbers are refused"
    );
    // Dropped without finish (the caller failed after the refusal): the writer writes
    // the index itself, of the frames before and the one appended.
    drop(w);
    let after = std::fs::read(&path).unwrap();
    assert_eq!(&after[..first_index], &before[..first_index]);
    let r = ArchiveReader::open(&path).unwrap();
    assert!(!r.recovered_by_scan() && r.verify().is_clean());
    assert_eq!(r.frames().len(), 3);
    // A crash mid-append (the process killed): no index, and a half-written record at
    // the end.
    let n = after.len();
    let index_offset = u64::from_le_bytes(after[n - 16..n - 8].try_into().unwrap()) as usize;
    let mut crashed = after[..index_offset].to_vec();
    crashed.extend_from_slice(&after[first_index..first_index + 100]);
    std::fs::write(&path, &crashed).unwrap();
    let r = ArchiveReader::open(&path).unwrap();
    assert!(r.recovered_by_scan());
    assert_eq!(r.frames().len(), 3);
    // The next run resumes: the incomplete record is cut, new frames follow.
    let mut w = ArchiveWriter::open_append(&path, &ArchiveOptions::new(BOUND)).unwrap();
    w.append_frame(frames[3].0, &archive_frame(&frames[3].1))
        .unwrap();
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

/// The frame as `archive extract` writes it.
fn extracted(r: &ArchiveReader, number: i64, dir: &Path) -> Vec<u8> {
    let path = dir.join(format!("x{number}.obj"));
    let surface = r.read_surface(number).unwrap();
    meniscus::io::mesh::write_surface(&path, &surface, &Default::default()).unwrap();
    std::fs::read(&path).unwrap()
}

#[test]
fn a_damaged_record_header_costs_only_its_frame_and_appends_lose_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mseq");
    let frames = frames();
    write_archive(&path, &frames[..5]);
    let r = ArchiveReader::open(&path).unwrap();
    let before: Vec<Vec<u8>> = frames[..5]
        .iter()
        .map(|(n, _)| extracted(&r, *n, dir.path()))
        .collect();
    let third = r.frames()[2].clone();
    let mut bytes = std::fs::read(&path).unwrap();
    bytes[third.offset as usize + 17] ^= 0x08; // the triangle count
    std::fs::write(&path, &bytes).unwrap();
    let check = |expect_new: bool| {
        let r = ArchiveReader::open(&path).unwrap();
        for (k, (n, _)) in frames[..5].iter().enumerate() {
            if k == 2 {
                let err = r.read_frame(*n).unwrap_err().to_string();
                assert!(
                    err.contains(&format!("frame {n}")) && err.contains("header"),
                    "{err}"
                );
            } else {
                assert_eq!(extracted(&r, *n, dir.path()), before[k], "frame {n}");
            }
        }
        let report = r.verify();
        assert!(!report.is_clean());
        assert_eq!(report.damaged.len(), 1, "{report:?}");
        assert_eq!(report.damaged[0].0, third.number);
        assert_eq!(report.good.len(), if expect_new { 5 } else { 4 });
        r
    };
    check(false);
    // Appending goes after the last record and keeps the damaged one where it is.
    let mut w = ArchiveWriter::open_append(&path, &ArchiveOptions::new(BOUND)).unwrap();
    w.append_frame(frames[5].0, &archive_frame(&frames[5].1))
        .unwrap();
    w.finish().unwrap();
    let r = check(true);
    let mut alone = dir.path().join("alone.mseq");
    write_archive(&alone, &frames[5..]);
    let a = ArchiveReader::open(&alone).unwrap();
    assert_eq!(
        extracted(&r, frames[5].0, dir.path()),
        extracted(&a, frames[5].0, dir.path())
    );
    // Without the index the scan finds the records after the damaged one.
    let mut cut = std::fs::read(&path).unwrap();
    cut.truncate(
        r.frames()
            .last()
            .map(|f| f.offset + 48 + f.payload_bytes)
            .unwrap() as usize,
    );
    alone.set_file_name("noindex.mseq");
    std::fs::write(&alone, &cut).unwrap();
    let s = ArchiveReader::open(&alone).unwrap();
    assert!(s.recovered_by_scan());
    assert_eq!(s.frames().len(), 5);
    let report = s.verify();
    assert_eq!(report.good.len(), 5);
    assert!(
        report.damage.iter().any(|d| d.contains("damaged record")),
        "{report:?}"
    );
    // The CLI exits non-zero.
    let out = support::meniscus()
        .args(["archive", "verify"])
        .arg(&path)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stdout).contains(&format!("frame {}: DAMAGED", third.number))
    );
}

#[test]
fn truncation_anywhere_is_damage_and_appends_keep_every_complete_frame() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mseq");
    let frames = frames();
    write_archive(&path, &frames[..4]);
    let bytes = std::fs::read(&path).unwrap();
    let r = ArchiveReader::open(&path).unwrap();
    let infos = r.frames().to_vec();
    let before: Vec<Vec<u8>> = infos
        .iter()
        .map(|f| extracted(&r, f.number, dir.path()))
        .collect();
    let cut_path = dir.path().join("cut.mseq");
    for sixteenth in 1..16 {
        let cut = bytes.len() * sixteenth / 16;
        std::fs::write(&cut_path, &bytes[..cut]).unwrap();
        let r = ArchiveReader::open(&cut_path).unwrap();
        assert!(!r.verify().is_clean(), "cut at {cut}");
        let complete: Vec<usize> = (0..infos.len())
            .filter(|&k| (infos[k].offset + 48 + infos[k].payload_bytes) as usize <= cut)
            .collect();
        let out = support::meniscus()
            .args(["archive", "verify"])
            .arg(&cut_path)
            .output()
            .unwrap();
        assert!(!out.status.success(), "cut at {cut}");
        let mut w = ArchiveWriter::open_append(&cut_path, &ArchiveOptions::new(BOUND)).unwrap();
        w.append_frame(frames[5].0, &archive_frame(&frames[5].1))
            .unwrap();
        w.finish().unwrap();
        let r = ArchiveReader::open(&cut_path).unwrap();
        let report = r.verify();
        assert!(report.is_clean(), "cut at {cut}: {report:?}");
        assert_eq!(report.good.len(), complete.len() + 1, "cut at {cut}");
        for &k in &complete {
            assert_eq!(extracted(&r, infos[k].number, dir.path()), before[k]);
        }
    }
}

#[test]
fn appending_with_another_error_bound_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mseq");
    let mut w = ArchiveWriter::create(&path, &ArchiveOptions::new(1e-3)).unwrap();
    w.append(0, &icosphere(1, 1.0)).unwrap();
    w.finish().unwrap();
    let before = std::fs::read(&path).unwrap();
    let err = ArchiveWriter::open_append(&path, &ArchiveOptions::new(2e-3))
        .err()
        .expect("refused")
        .to_string();
    assert!(
        err.contains("0.002") && err.contains("0.001") && err.contains("run.mseq"),
        "{err}"
    );
    assert!(!err.contains("--"), "names no flag: {err}");
    assert_eq!(std::fs::read(&path).unwrap(), before);
    let mut w = ArchiveWriter::open_append(&path, &ArchiveOptions::new(1e-3)).unwrap();
    w.append(1, &icosphere(1, 1.0)).unwrap();
    w.finish().unwrap();
    assert_eq!(ArchiveReader::open(&path).unwrap().verify().good, [0, 1]);
    // The same bound in world units computed another way (0.04 × an f32 radius, as
    // reconstruct's default is) appends, and the new frame keeps the archive's step.
    let computed = 0.04 * 0.025f32 as f64;
    assert_ne!(computed, 1e-3);
    let mut w = ArchiveWriter::open_append(&path, &ArchiveOptions::new(computed)).unwrap();
    w.append(2, &icosphere(1, 1.0)).unwrap();
    w.finish().unwrap();
    let r = ArchiveReader::open(&path).unwrap();
    assert!(r.frames().iter().all(|f| f.step == 2e-3), "one step");
    assert_eq!(r.verify().good, [0, 1, 2]);
}

#[test]
fn a_new_archive_is_written_only_when_its_first_frame_is() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mseq");
    let w = ArchiveWriter::create(&path, &ArchiveOptions::new(1e-3)).unwrap();
    drop(w);
    assert!(!path.exists());
    // finish makes an archive without frames.
    ArchiveWriter::create(&path, &ArchiveOptions::new(1e-3))
        .unwrap()
        .finish()
        .unwrap();
    let r = ArchiveReader::open(&path).unwrap();
    assert!(r.frames().is_empty() && r.verify().is_clean());
}

// ---------------------------------------------------------------------------------------
// Failures partway through appending: the archive stays consistent.

/// The archive verifies clean through its index and holds exactly `numbers`.
fn assert_clean(path: &Path, numbers: &[i64]) {
    let r = ArchiveReader::open(path).unwrap();
    let v = r.verify();
    assert!(v.is_clean(), "{v:?}");
    assert!(!r.recovered_by_scan(), "the index was written");
    assert_eq!(v.good, numbers);
}

static NO_SPHERES: std::sync::LazyLock<SphereInstances> =
    std::sync::LazyLock::new(SphereInstances::default);

fn refused_frame(mesh: &TriMesh) -> ArchiveFrame<'_> {
    // More Loop steps than an archive stores: refused before anything is written.
    ArchiveFrame {
        fluid: mesh,
        subdivision_levels: 5,
        spheres: &NO_SPHERES,
    }
}

#[test]
fn a_writer_dropped_after_an_error_keeps_every_complete_frame() {
    let dir = tempfile::tempdir().unwrap();
    let options = ArchiveOptions::new(1e-3);
    // What finish writes for frames 0 and 1.
    let reference = dir.path().join("reference.mseq");
    let mut w = ArchiveWriter::create(&reference, &options).unwrap();
    for k in [0, 1] {
        w.append(k, &small_mesh(k)).unwrap();
    }
    w.finish().unwrap();

    // A new archive: frames 0 and 1, then a duplicate number refused, the caller gives
    // up (as `archive pack` returns its error) and drops the writer.
    let path = dir.path().join("run.mseq");
    let mut w = ArchiveWriter::create(&path, &options).unwrap();
    for k in [0, 1] {
        w.append(k, &small_mesh(k)).unwrap();
    }
    assert!(w.append(1, &small_mesh(1)).is_err(), "duplicate refused");
    drop(w);
    assert_clean(&path, &[0, 1]);
    assert_eq!(
        std::fs::read(&path).unwrap(),
        std::fs::read(&reference).unwrap(),
        "the same archive finish writes"
    );
    let before = std::fs::read(&path).unwrap();
    let frames_before = decoded(&path);

    // Opened for appending and dropped without writing: nothing changes.
    drop(ArchiveWriter::open_append(&path, &options).unwrap());
    assert_eq!(std::fs::read(&path).unwrap(), before, "untouched");

    // An existing archive: a frame appended, one refused, the writer goes on after the
    // refusal, then another refusal and the writer is dropped.
    let mut w = ArchiveWriter::open_append(&path, &options).unwrap();
    w.append(2, &small_mesh(2)).unwrap();
    let mesh = small_mesh(3);
    assert!(w.append_frame(3, &refused_frame(&mesh)).is_err());
    w.append(4, &small_mesh(4)).unwrap();
    assert!(w.append(0, &small_mesh(0)).is_err(), "duplicate refused");
    drop(w);
    assert_clean(&path, &[0, 1, 2, 4]);
    let after = std::fs::read(&path).unwrap();
    let old_index = index_offset(&before);
    assert_eq!(&after[..old_index], &before[..old_index], "earlier records");
    let frames_after = decoded(&path);
    assert_eq!(
        &frames_after[..2],
        &frames_before[..],
        "earlier frames decode the same"
    );
    // The frames appended before the failure are complete: they decode to what a
    // finished archive of the same meshes holds.
    let full = dir.path().join("full.mseq");
    let mut w = ArchiveWriter::create(&full, &options).unwrap();
    for k in [0, 1, 2, 4] {
        w.append(k, &small_mesh(k)).unwrap();
    }
    w.finish().unwrap();
    assert_eq!(frames_after, decoded(&full));
    assert_eq!(after, std::fs::read(&full).unwrap());
}

#[test]
fn a_panic_while_appending_leaves_a_clean_archive() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mseq");
    let options = ArchiveOptions::new(1e-3);
    let mut w = ArchiveWriter::create(&path, &options).unwrap();
    w.append(0, &small_mesh(0)).unwrap();
    w.finish().unwrap();
    let before = decoded(&path);
    let unwound = std::panic::catch_unwind(|| {
        let mut w = ArchiveWriter::open_append(&path, &options).unwrap();
        w.append(1, &small_mesh(1)).unwrap();
        panic!("the caller fails after frame 1");
    });
    assert!(unwound.is_err());
    assert_clean(&path, &[0, 1]);
    assert_eq!(&decoded(&path)[..1], &before[..]);
}

#[test]
fn a_new_archive_whose_first_frame_fails_does_not_exist() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mseq");
    let mut w = ArchiveWriter::create(&path, &ArchiveOptions::new(1e-3)).unwrap();
    let mesh = small_mesh(0);
    assert!(w.append_frame(0, &refused_frame(&mesh)).is_err());
    assert!(!path.exists());
    drop(w);
    assert!(!path.exists(), "no archive without a frame");
    // Nor after a panic before the first frame.
    let unwound = std::panic::catch_unwind(|| {
        let _w = ArchiveWriter::create(&path, &ArchiveOptions::new(1e-3)).unwrap();
        panic!("before the first frame");
    });
    assert!(unwound.is_err());
    assert!(!path.exists());
}

/// `reconstruct … -o run.mseq` through the library, interrupted (its cancel token set,
/// as Ctrl-C does) when frame `cancel_at` starts.
fn run_into_archive(
    input: &str,
    archive: &Path,
    cancel_at: Option<i64>,
) -> meniscus::Result<Vec<meniscus::job::FrameReport>> {
    use meniscus::job::{plan_frames, run_frames, JobOptions};
    let cancel = meniscus::CancelToken::new();
    let job = JobOptions {
        input_format: None,
        write: Default::default(),
        skip_existing: true,
        archive_error_bound: 0.00025,
        archive_attribute_error_bound: 1e-3,
        fps: 24.0,
        up_axis: Default::default(),
        meters_per_unit: 1.0,
        usd_droplets: Default::default(),
        attributes: Default::default(),
        radius_attribute: Default::default(),
        keep_going: false,
        cancel: cancel.clone(),
    };
    let plan = plan_frames(input, archive.to_str().unwrap(), &Default::default())?;
    run_frames(
        &plan,
        &ReconstructOptions::new(0.025),
        &job,
        &mut |_, frame| {
            if Some(frame.number) == cancel_at {
                cancel.cancel();
            }
        },
        &mut |_| {},
        &mut |_| {},
    )
}

#[test]
fn an_interrupted_run_leaves_a_clean_archive() {
    let dir = tempfile::tempdir().unwrap();
    let sphere = support::dataset("analytic/sphere.xyz");
    for k in 1..=4 {
        std::fs::copy(&sphere, dir.path().join(format!("f_{k}.xyz"))).unwrap();
    }
    let input = format!("{}/f_{{}}.xyz", dir.path().display());
    let archive = dir.path().join("run.mseq");
    // A new archive, interrupted at frame 3.
    let err = run_into_archive(&input, &archive, Some(3)).unwrap_err();
    assert!(matches!(err, meniscus::Error::Interrupted), "{err}");
    assert_clean(&archive, &[1, 2]);
    let before = decoded(&archive);
    // The re-run skips them, appends frame 3 and is interrupted at frame 4.
    let err = run_into_archive(&input, &archive, Some(4)).unwrap_err();
    assert!(matches!(err, meniscus::Error::Interrupted), "{err}");
    assert_clean(&archive, &[1, 2, 3]);
    assert_eq!(&decoded(&archive)[..2], &before[..]);
    // A new archive interrupted at its first frame is not left behind.
    let fresh = dir.path().join("fresh.mseq");
    assert!(run_into_archive(&input, &fresh, Some(1)).is_err());
    assert!(!fresh.exists());
    // The last run completes it.
    let reports = run_into_archive(&input, &archive, None).unwrap();
    assert_eq!(reports.iter().filter(|r| r.skipped).count(), 3);
    assert_clean(&archive, &[1, 2, 3, 4]);
}
