//! `.mseq` frame decoders behind zstd: the input is a frame's *decompressed* payload,
//! which this target compresses and wraps in a valid one-record archive (header, record
//! with checksums, index), then reads like the `archive` target. Mutating compressed
//! bytes almost never yields a valid zstd frame, so without this the decoders (streams,
//! fused Loop step, parts, spheres, attribute streams) would see few inputs.
//!
//! Input: `u8 mode | u32 vertices | u32 triangles | body` (little-endian), where
//! `mode & 3` picks the layout and `mode >> 2 & 3` the quantization step:
//! * 0: version 1, payload = zstd(body) (one plain mesh),
//! * 1: version 3, payload = zstd(body) (`raw` of src/archive/frame.rs),
//! * 2: version 4 with attributes, body = `u16 descriptor length | descriptor |
//!   u16 geometry length | geometry raw | attribute streams raw`; the payload is built as
//!   src/archive/attributes.rs lays it out (descriptor checksum, geometry and streams
//!   each zstd-compressed with their content size),
//! * 3: as 1 with the attribute flag set but version 3 (an inconsistent record).
#![no_main]

#[path = "../common/mod.rs"]
mod common;

use libfuzzer_sys::fuzz_target;
use meniscus::archive::ArchiveReader;

const STEPS: [f64; 4] = [1e-3, 1e-9, 1.0, 1e30];

fn take<'a>(b: &mut &'a [u8], n: usize) -> Option<&'a [u8]> {
    let (head, rest) = (b.get(..n)?, b.get(n..)?);
    *b = rest;
    Some(head)
}

fn u16_of(b: &mut &[u8]) -> Option<usize> {
    Some(u16::from_le_bytes(take(b, 2)?.try_into().ok()?) as usize)
}

fn compress(raw: &[u8]) -> Vec<u8> {
    zstd::bulk::compress(raw, 1).expect("zstd")
}

/// The archive holding one frame (number 0) of `payload`.
fn archive(
    version: u32,
    vertices: u32,
    triangles: u32,
    step: f64,
    flags: u32,
    payload: &[u8],
) -> Vec<u8> {
    let mut b = Vec::new();
    b.extend_from_slice(b"MNSCMSEQ");
    b.extend_from_slice(&version.to_le_bytes());
    b.extend_from_slice(&0u32.to_le_bytes());
    let mut h = Vec::new();
    h.extend_from_slice(b"FRAM");
    h.extend_from_slice(&0i64.to_le_bytes());
    h.extend_from_slice(&vertices.to_le_bytes());
    h.extend_from_slice(&triangles.to_le_bytes());
    h.extend_from_slice(&step.to_le_bytes());
    h.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    h.extend_from_slice(&crc32fast::hash(payload).to_le_bytes());
    h.extend_from_slice(&flags.to_le_bytes());
    let crc = crc32fast::hash(&h);
    h.extend_from_slice(&crc.to_le_bytes());
    b.extend_from_slice(&h);
    b.extend_from_slice(payload);
    let index_offset = b.len() as u64;
    let mut index = Vec::new();
    index.extend_from_slice(b"INDX");
    index.extend_from_slice(&1u64.to_le_bytes());
    index.extend_from_slice(&0i64.to_le_bytes());
    index.extend_from_slice(&16u64.to_le_bytes());
    let crc = crc32fast::hash(&index);
    b.extend_from_slice(&index);
    b.extend_from_slice(&crc.to_le_bytes());
    b.extend_from_slice(&index_offset.to_le_bytes());
    b.extend_from_slice(b"MSEQEND!");
    b
}

fn build(data: &[u8]) -> Option<Vec<u8>> {
    let mut b = data;
    let mode = take(&mut b, 1)?[0];
    let vertices = u32::from_le_bytes(take(&mut b, 4)?.try_into().ok()?);
    let triangles = u32::from_le_bytes(take(&mut b, 4)?.try_into().ok()?);
    let step = STEPS[(mode >> 2 & 3) as usize];
    Some(match mode & 3 {
        0 => archive(1, vertices, triangles, step, 0, &compress(b)),
        1 => archive(3, vertices, triangles, step, 0, &compress(b)),
        2 => {
            let n = u16_of(&mut b)?;
            let descriptor = take(&mut b, n)?;
            let n = u16_of(&mut b)?;
            let geometry = compress(take(&mut b, n)?);
            let streams = compress(b);
            let mut payload = Vec::new();
            payload.extend_from_slice(&(descriptor.len() as u32).to_le_bytes());
            payload.extend_from_slice(descriptor);
            payload.extend_from_slice(&crc32fast::hash(descriptor).to_le_bytes());
            payload.extend_from_slice(&(geometry.len() as u64).to_le_bytes());
            payload.extend_from_slice(&geometry);
            payload.extend_from_slice(&streams);
            archive(4, vertices, triangles, step, 1, &payload)
        }
        _ => archive(3, vertices, triangles, step, 1, &compress(b)),
    })
}

fuzz_target!(|data: &[u8]| {
    static ONE_THREAD: std::sync::Once = std::sync::Once::new();
    ONE_THREAD.call_once(|| std::env::set_var("RAYON_NUM_THREADS", "1"));
    let Some(bytes) = build(data) else { return };
    let path = common::input_file("payload.mseq", &bytes);
    let reader = match ArchiveReader::open(&path) {
        Ok(r) => r,
        Err(e) => return common::check_error(&path, &e),
    };
    let report = reader.verify();
    assert!(report.good.len() + report.damaged.len() >= reader.frames().len());
    for f in reader.frames() {
        match reader.read_surface(f.number) {
            Ok(s) => {
                let v = s.fluid.positions.len() as u32;
                assert!(s.fluid.triangles.iter().flatten().all(|&i| i < v));
                for a in &s.fluid.attributes {
                    assert_eq!(a.values.len(), a.components * s.fluid.positions.len());
                }
            }
            Err(e) => common::check_error(&path, &e),
        }
    }
});
