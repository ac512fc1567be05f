//! Hostile `.mseq` archives: crafted record headers and payloads, record lengths that
//! wrap, huge indexes and random mutations are read or refused as damage, never a
//! panic, a loop, an allocation of what a header claims or quadratic time.

mod support;

use meniscus::archive::{ArchiveFrame, ArchiveOptions, ArchiveReader, ArchiveWriter, VerifyReport};
use meniscus::isolated::icosphere;
use meniscus::mesh::SphereInstances;
use std::path::{Path, PathBuf};
use support::archive::{
    bumpy, index_offset, payload_len, small_mesh, spheres_with_attributes, with_attributes, BOUND,
};
use support::Rng;

#[test]
fn a_record_length_that_wraps_the_scan_position_does_not_loop() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tiny.mseq");
    let mut bytes = file_header();
    // 16 + 48 + this = 16 modulo 2^64: the next record would start where this one does.
    bytes.extend(record_header(0, 0, 0, 1e-3, u64::MAX - 47, 0));
    assert_eq!(bytes.len(), 64);
    std::fs::write(&path, &bytes).unwrap();
    let r = ArchiveReader::open(&path).unwrap();
    assert!(r.frames().is_empty());
    let report = r.verify();
    assert!(!report.is_clean());
    assert_eq!(report.damaged.len(), 1, "{report:?}");
    assert!(ArchiveWriter::open_append(&path, &ArchiveOptions::new(BOUND)).is_ok());
}

/// The file header of a version-3 archive.
fn file_header() -> Vec<u8> {
    let mut bytes = Vec::with_capacity(16);
    bytes.extend_from_slice(b"MNSCMSEQ");
    bytes.extend_from_slice(&3u32.to_le_bytes());
    bytes.extend_from_slice(&0u32.to_le_bytes());
    bytes
}

/// A record header with these fields (flags 0) and its checksum.
fn record_header(
    number: i64,
    vertices: u32,
    triangles: u32,
    step: f64,
    payload_len: u64,
    payload_crc: u32,
) -> Vec<u8> {
    let mut h = Vec::with_capacity(48);
    h.extend_from_slice(b"FRAM");
    h.extend_from_slice(&number.to_le_bytes());
    h.extend_from_slice(&vertices.to_le_bytes());
    h.extend_from_slice(&triangles.to_le_bytes());
    h.extend_from_slice(&step.to_le_bytes());
    h.extend_from_slice(&payload_len.to_le_bytes());
    h.extend_from_slice(&payload_crc.to_le_bytes());
    h.extend_from_slice(&0u32.to_le_bytes());
    h.extend_from_slice(&crc32fast::hash(&h).to_le_bytes());
    h
}

/// An archive of one record (no index) with a hand-made payload and header fields.
fn hostile_archive(
    dir: &Path,
    payload: &[u8],
    vertices: u32,
    triangles: u32,
    step: f64,
) -> PathBuf {
    let mut bytes = file_header();
    bytes.extend(record_header(
        0,
        vertices,
        triangles,
        step,
        payload.len() as u64,
        crc32fast::hash(payload),
    ));
    bytes.extend_from_slice(payload);
    let path = dir.join("hostile.mseq");
    std::fs::write(&path, &bytes).unwrap();
    path
}

fn varints(values: &[u64]) -> Vec<u8> {
    let mut out = Vec::new();
    for &v in values {
        let mut v = v;
        while v >= 0x80 {
            out.push((v as u8) | 0x80);
            v >>= 7;
        }
        out.push(v as u8);
    }
    out
}

/// The frame is refused as damaged, by `read_frame` and `verify`, with `what` in the
/// message.
fn assert_refused(path: &Path, what: &str) {
    let r = ArchiveReader::open(path).unwrap();
    let err = r.read_frame(0).unwrap_err().to_string();
    assert!(err.contains("frame 0") && err.contains(what), "{err}");
    let report = r.verify();
    assert_eq!(report.damaged.len(), 1, "{report:?}");
    assert!(report.good.is_empty());
}

#[test]
fn hostile_record_headers_are_errors_before_any_allocation() {
    let dir = tempfile::tempdir().unwrap();
    // A real frame with its step replaced: NaN, 1e300, negative, zero.
    let path = dir.path().join("real.mseq");
    let mut w = ArchiveWriter::create(&path, &ArchiveOptions::new(1e-3)).unwrap();
    w.append(0, &icosphere(1, 1.0)).unwrap();
    w.finish().unwrap();
    let good = std::fs::read(&path).unwrap();
    for step in [f64::NAN, 1e300, -2e-3, 0.0, f64::INFINITY] {
        let mut bytes = good.clone();
        bytes[16 + 20..16 + 28].copy_from_slice(&step.to_le_bytes());
        let crc = crc32fast::hash(&bytes[16..16 + 44]);
        bytes[16 + 44..16 + 48].copy_from_slice(&crc.to_le_bytes());
        std::fs::write(&path, &bytes).unwrap();
        assert_refused(&path, "quantization step");
    }
    // Counts far beyond what the payload holds, with and without a zstd content size.
    let raw = varints(&[0, 0, 4_000_000_000, 4_000_000_000, 0, 0, 0, 0]);
    let stated = zstd::bulk::compress(&raw, 3).unwrap();
    let path = hostile_archive(dir.path(), &stated, u32::MAX, u32::MAX, 2e-3);
    assert_refused(&path, "cannot fit");
    let unstated = zstd::stream::encode_all(&raw[..], 3).unwrap();
    assert!(zstd::zstd_safe::get_frame_content_size(&unstated)
        .unwrap()
        .is_none());
    let path = hostile_archive(dir.path(), &unstated, u32::MAX, u32::MAX, 2e-3);
    assert_refused(&path, "cannot fit");
    // A plain mesh (version-1 layout inside) asking for five Loop steps.
    let raw = varints(&[5, 0, 3, 1, 0, 0, 0, 0]);
    let path = hostile_archive(
        dir.path(),
        &zstd::bulk::compress(&raw, 3).unwrap(),
        3 * 4u32.pow(5),
        4u32.pow(5),
        2e-3,
    );
    assert_refused(&path, "subdivision levels");
    // The writer refuses such a frame instead of storing it.
    let mut w =
        ArchiveWriter::create(&dir.path().join("w.mseq"), &ArchiveOptions::new(1e-3)).unwrap();
    let mesh = icosphere(0, 1.0);
    let frame = ArchiveFrame {
        fluid: &mesh,
        subdivision_levels: 5,
        spheres: &SphereInstances::default(),
    };
    let err = w.append_frame(0, &frame).unwrap_err().to_string();
    assert!(
        err.contains("frame 0") && err.contains("subdivision levels"),
        "{err}"
    );
    // An error bound whose step a coordinate cannot be decoded with.
    assert!(
        ArchiveWriter::create(&dir.path().join("x.mseq"), &ArchiveOptions::new(1e300)).is_err()
    );
}

/// Recomputes the checksums of the records that follow each other from the file header
/// on and of an index that ends at the trailer, so that a mutation reaches the frame
/// decoders instead of stopping at a CRC mismatch.
fn reseal(b: &mut [u8]) {
    let u64_at = |b: &[u8], at: usize| u64::from_le_bytes(b[at..at + 8].try_into().unwrap());
    let mut pos = 16;
    while pos + 48 <= b.len() && &b[pos..pos + 4] == b"FRAM" {
        let Some(end) = usize::try_from(u64_at(b, pos + 28))
            .ok()
            .and_then(|len| (pos + 48).checked_add(len))
            .filter(|&end| end <= b.len())
        else {
            break;
        };
        let crc = crc32fast::hash(&b[pos + 48..end]);
        b[pos + 36..pos + 40].copy_from_slice(&crc.to_le_bytes());
        let crc = crc32fast::hash(&b[pos..pos + 44]);
        b[pos + 44..pos + 48].copy_from_slice(&crc.to_le_bytes());
        pos = end;
    }
    let len = b.len();
    if len >= 48 && &b[len - 8..] == b"MSEQEND!" {
        let index = usize::try_from(u64_at(b, len - 16)).unwrap_or(usize::MAX);
        if index >= 16 && index.checked_add(16).is_some_and(|e| e <= len - 16) {
            let crc = crc32fast::hash(&b[index..len - 20]);
            b[len - 20..len - 16].copy_from_slice(&crc.to_le_bytes());
        }
    }
}

/// Opens `path` and decodes everything in it; every error names the file.
fn read_everything(path: &Path, name: &str) {
    let r = match ArchiveReader::open(path) {
        Ok(r) => r,
        Err(e) => return assert!(e.to_string().contains(name), "{e}"),
    };
    let numbers: Vec<i64> = r.frames().iter().map(|f| f.number).collect();
    let report = r.verify();
    assert_every_frame_reported(&r, &report);
    for n in numbers {
        match r.read_surface(n) {
            Ok(s) => {
                let v = s.fluid.positions.len() as u32;
                assert!(s.fluid.triangles.iter().flatten().all(|&i| i < v));
            }
            Err(e) => assert!(e.to_string().contains(name), "{e}"),
        }
    }
}

#[test]
fn mutated_archives_are_read_or_rejected_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.mseq");
    // A frame with attributes, a Loop step and spheres, and a plain mesh: version 4.
    let fluid = with_attributes(bumpy(1, 1.0));
    let spheres = spheres_with_attributes(3);
    let mut w = ArchiveWriter::create(&path, &ArchiveOptions::new(1e-3)).unwrap();
    w.append_frame(
        7,
        &ArchiveFrame {
            fluid: &fluid,
            subdivision_levels: 1,
            spheres: &spheres,
        },
    )
    .unwrap();
    w.append(8, &icosphere(0, 0.5)).unwrap();
    w.finish().unwrap();
    let base = std::fs::read(&path).unwrap();
    assert!(base.len() < 8192, "{}", base.len());
    assert_eq!(ArchiveReader::open(&path).unwrap().verify().good, [7, 8]);
    let mut rng = Rng(0x6a09_e667_f3bc_c909);
    for round in 0..5000 {
        let mut b = base.clone();
        match rng.below(4) {
            0 => {
                for _ in 0..1 + rng.below(4) {
                    let i = rng.below(b.len());
                    b[i] ^= 1 << rng.below(8);
                }
            }
            1 => b.truncate(rng.below(b.len())),
            2 => {
                let i = rng.below(b.len() + 1);
                let n = 1 + rng.below(8);
                let bytes: Vec<u8> = (0..n).map(|_| rng.next() as u8).collect();
                b.splice(i..i, bytes);
            }
            _ => {
                // A header field or count: a little-endian u32 or u64 of extreme value.
                let i = rng.below(b.len() - 8);
                match rng.below(3) {
                    0 => b[i..i + 4].copy_from_slice(&u32::MAX.to_le_bytes()),
                    1 => b[i..i + 8]
                        .copy_from_slice(&(u64::MAX - rng.below(64) as u64).to_le_bytes()),
                    _ => b[i] = 0xff,
                }
            }
        }
        // Half the cases with their checksums recomputed, to reach the decoders.
        if round % 2 == 1 {
            reseal(&mut b);
        }
        std::fs::write(&path, &b).unwrap();
        support::without_panic(round, "m.mseq", &b, || read_everything(&path, "m.mseq"));
    }
}

#[test]
fn an_index_of_many_entries_over_many_records_opens_in_linear_time() {
    // 400 000 empty records and an index listing each: matching every entry against
    // every record (as the reader used to) is 8·10^10 comparisons.
    let n = 400_000usize;
    let mut bytes = Vec::with_capacity(16 + n * 64 + 36);
    bytes.extend(file_header());
    let mut index = Vec::with_capacity(12 + 16 * n);
    index.extend_from_slice(b"INDX");
    index.extend_from_slice(&(n as u64).to_le_bytes());
    for k in 0..n {
        index.extend_from_slice(&(k as i64).to_le_bytes());
        index.extend_from_slice(&(bytes.len() as u64).to_le_bytes());
        bytes.extend(record_header(k as i64, 0, 0, 1e-3, 0, crc32fast::hash(&[])));
    }
    let index_offset = bytes.len() as u64;
    let crc = crc32fast::hash(&index);
    bytes.extend_from_slice(&index);
    bytes.extend_from_slice(&crc.to_le_bytes());
    bytes.extend_from_slice(&index_offset.to_le_bytes());
    bytes.extend_from_slice(b"MSEQEND!");
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("many.mseq");
    std::fs::write(&path, &bytes).unwrap();
    let start = std::time::Instant::now();
    let r = ArchiveReader::open(&path).unwrap();
    let took = start.elapsed();
    assert!(!r.recovered_by_scan());
    assert_eq!(r.frames().len(), n);
    // Linear: well under a second; quadratic: minutes.
    assert!(took.as_secs() < 30, "opening took {took:?}");
}

/// The first record's decompressed payload (`raw` of src/archive/frame.rs) and its
/// header's vertex and triangle counts.
fn first_raw(path: &Path) -> (Vec<u8>, u32, u32) {
    let b = std::fs::read(path).unwrap();
    let u32_at = |at: usize| u32::from_le_bytes(b[at..at + 4].try_into().unwrap());
    let len = u64::from_le_bytes(b[16 + 28..16 + 36].try_into().unwrap()) as usize;
    let raw = zstd::bulk::decompress(&b[64..64 + len], 1 << 24).unwrap();
    (raw, u32_at(16 + 12), u32_at(16 + 16))
}

fn read_varint(raw: &[u8], pos: &mut usize) -> u64 {
    let (mut v, mut shift) = (0u64, 0);
    loop {
        let b = raw[*pos];
        *pos += 1;
        v |= ((b & 0x7f) as u64) << shift;
        if b < 0x80 {
            return v;
        }
        shift += 7;
    }
}

/// Moves `pos` past the three length-prefixed streams of a mesh.
fn skip_streams(raw: &[u8], pos: &mut usize) {
    for _ in 0..3 {
        let len = read_varint(raw, pos) as usize;
        *pos += len;
    }
}

/// `raw` with the position stream of the mesh whose streams start at `*pos` replaced by
/// `n` residuals of `value` each.
fn replace_residuals(raw: &[u8], mut pos: usize, n: usize, value: u64) -> Vec<u8> {
    for _ in 0..2 {
        let len = read_varint(raw, &mut pos) as usize;
        pos += len;
    }
    let start = pos;
    let len = read_varint(raw, &mut pos) as usize;
    pos += len;
    let residuals = varints(&vec![value; n]);
    let mut out = raw[..start].to_vec();
    out.extend(varints(&[residuals.len() as u64]));
    out.extend(residuals);
    out.extend_from_slice(&raw[pos..]);
    out
}

#[test]
fn lattice_coordinates_that_overflow_are_decoded_or_refused_never_panic() {
    // Found by fuzzing (archive_payload): residuals of ±2^63 made `prediction + residual`
    // overflow i64 in the fused Loop decoder (a panic with overflow checks, as `cargo
    // test` builds; wrapped garbage otherwise). Predictions and residuals are now modular
    // on both sides, and a frame decoding to coordinates beyond f32 is refused.
    let dir = tempfile::tempdir().unwrap();
    let zigzag_max = u64::MAX - 1; // zigzag(i64::MAX)
    let spheres = SphereInstances {
        template: icosphere(0, 0.1),
        scales: Vec::new(),
        centers: vec![glam::Vec3::ZERO, glam::Vec3::X, glam::Vec3::Y],
        attributes: Vec::new(),
    };
    let none = SphereInstances::default();
    let closed = icosphere(0, 1.0);
    let mut open = icosphere(0, 1.0);
    open.triangles.truncate(5);
    // (fluid, Loop steps, spheres, what is damaged): the fused Loop decoder (closed mesh,
    // one step), the plain stream decoder (open mesh), the sphere centres.
    for (fluid, levels, spheres, centres) in [
        (&closed, 1, &none, false),
        (&open, 0, &none, false),
        (&closed, 0, &spheres, true),
    ] {
        let path = dir.path().join("real.mseq");
        let mut w = ArchiveWriter::create(&path, &ArchiveOptions::new(1e-3)).unwrap();
        let frame = ArchiveFrame {
            fluid,
            subdivision_levels: levels,
            spheres,
        };
        w.append_frame(0, &frame).unwrap();
        w.finish().unwrap();
        let (raw, vertices, triangles) = first_raw(&path);
        let mut pos = 0;
        let _levels = read_varint(&raw, &mut pos);
        pos += 1; // shape
        let fluid_vertices = read_varint(&raw, &mut pos) as usize;
        let _ = read_varint(&raw, &mut pos);
        let damaged = if centres {
            let mut raw = raw.clone();
            skip_streams(&raw, &mut pos);
            let count = read_varint(&raw, &mut pos) as usize;
            let _template_counts = (read_varint(&raw, &mut pos), read_varint(&raw, &mut pos));
            skip_streams(&raw, &mut pos);
            let centres = varints(&vec![zigzag_max; 3 * count]);
            raw.truncate(pos);
            raw.extend(centres);
            raw
        } else {
            replace_residuals(&raw, pos, 3 * fluid_vertices, zigzag_max)
        };
        // A step of 1e-3 keeps the wrapped coordinates within f32, one of f32::MAX
        // does not: decoded or refused, never a panic.
        for (step, refused) in [(2e-3, false), (f32::MAX as f64, true)] {
            let payload = zstd::bulk::compress(&damaged, 3).unwrap();
            let path = hostile_archive(dir.path(), &payload, vertices, triangles, step);
            let r = ArchiveReader::open(&path).unwrap();
            let result = r.read_surface(0);
            if refused {
                let e = result.unwrap_err().to_string();
                assert!(
                    e.contains("hostile.mseq") && e.contains("frame 0") && e.contains("beyond f32"),
                    "{e}"
                );
            } else if let Err(e) = result {
                panic!("levels {levels}, centres {centres}: {e}");
            }
        }
    }
}

/// A record repeated and the index gone (the shape the `archive` fuzz target built): the
/// scan lists the frame number twice, `verify` reports it once, as damage and never as
/// good, and every frame number the reader lists is in its report.
#[test]
fn a_repeated_record_is_one_damaged_frame() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("twice.mseq");
    let mut w = ArchiveWriter::create(&path, &ArchiveOptions::new(BOUND)).unwrap();
    w.append(3, &small_mesh(3)).unwrap();
    w.append(4, &small_mesh(4)).unwrap();
    w.finish().unwrap();
    let base = std::fs::read(&path).unwrap();
    let first = 16..16 + 48 + payload_len(&base, 16) as usize;
    // The file header, record 3, record 3 again, record 4; no index.
    let mut bytes = base[..first.end].to_vec();
    bytes.extend_from_slice(&base[first.clone()]);
    bytes.extend_from_slice(&base[first.end..index_offset(&base)]);
    std::fs::write(&path, &bytes).unwrap();
    let r = ArchiveReader::open(&path).unwrap();
    let numbers: Vec<i64> = r.frames().iter().map(|f| f.number).collect();
    let report = r.verify();
    assert_eq!(numbers, [3, 3, 4]);
    assert_eq!(report.good, [4]);
    assert_eq!(report.damaged.len(), 1, "{report:?}");
    assert_eq!(report.damaged[0].0, 3);
    assert!(report.damaged[0].1.contains("2 records"), "{report:?}");
    assert_every_frame_reported(&r, &report);
}

/// Every frame number `r` lists is in `report` (good or damaged), and a good frame is
/// held by one record and reads.
fn assert_every_frame_reported(r: &ArchiveReader, report: &VerifyReport) {
    let numbers: Vec<i64> = r.frames().iter().map(|f| f.number).collect();
    for &n in &numbers {
        let good = report.good.contains(&n);
        assert!(
            good || report.damaged.iter().any(|d| d.0 == n),
            "frame {n} lost"
        );
        if good {
            assert_eq!(numbers.iter().filter(|&&m| m == n).count(), 1, "frame {n}");
            assert!(r.read_surface(n).is_ok(), "frame {n} good but unreadable");
        }
    }
}
