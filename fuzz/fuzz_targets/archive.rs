//! `.mseq` archive reader: `ArchiveReader::open`, `frames()`, `verify()`, decoding every
//! frame, and `archive::repair` (every frame that reads is kept, bit for bit), on the input
//! as it is and on a copy whose checksums are recomputed
//! ("resealed"), so that mutations reach the frame decoders behind the CRC-32 checks.
#![no_main]

#[path = "../common/mod.rs"]
mod common;

use libfuzzer_sys::fuzz_target;
use meniscus::archive::ArchiveReader;

const HEADER_LEN: usize = 16;
const RECORD_HEADER_LEN: usize = 48;

fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}

/// Recomputes the payload and header checksums of the records that follow each other
/// from the file header on, and the index checksum when the trailer points at an index
/// that ends where the trailer starts (docs/archive-format.md).
fn reseal(bytes: &mut [u8]) {
    let mut pos = HEADER_LEN;
    while pos + RECORD_HEADER_LEN <= bytes.len() && &bytes[pos..pos + 4] == b"FRAM" {
        let start = pos + RECORD_HEADER_LEN;
        let Some(end) = usize::try_from(u64_at(bytes, pos + 28))
            .ok()
            .and_then(|len| start.checked_add(len))
            .filter(|&end| end <= bytes.len())
        else {
            break;
        };
        let crc = crc32fast::hash(&bytes[start..end]);
        bytes[pos + 36..pos + 40].copy_from_slice(&crc.to_le_bytes());
        let crc = crc32fast::hash(&bytes[pos..pos + 44]);
        bytes[pos + 44..pos + 48].copy_from_slice(&crc.to_le_bytes());
        pos = end;
    }
    let len = bytes.len();
    if len >= HEADER_LEN + 32 && &bytes[len - 8..] == b"MSEQEND!" {
        let index = usize::try_from(u64_at(bytes, len - 16)).unwrap_or(usize::MAX);
        if index >= HEADER_LEN
            && index.checked_add(16).is_some_and(|end| end <= len - 16)
            && &bytes[index..index + 4] == b"INDX"
        {
            let crc = crc32fast::hash(&bytes[index..len - 20]);
            bytes[len - 20..len - 16].copy_from_slice(&crc.to_le_bytes());
        }
    }
}

fn read(name: &str, data: &[u8]) {
    let path = common::input_file(name, data);
    let reader = match ArchiveReader::open(&path) {
        Ok(r) => r,
        Err(e) => return common::check_error(&path, &e),
    };
    let mut numbers: Vec<i64> = reader.frames().iter().map(|f| f.number).collect();
    let report = reader.verify();
    // `verify` lists each frame number once: a number that several records hold is one
    // damaged frame. A good frame is held by one record and reads.
    let records = |n: i64| numbers.iter().filter(|&&m| m == n).count();
    for &n in &report.good {
        assert_eq!(
            records(n),
            1,
            "verify calls frame {n} good, held by several records"
        );
    }
    numbers.sort_unstable();
    numbers.dedup();
    for n in numbers {
        let good = report.good.contains(&n);
        assert!(
            good || report.damaged.iter().any(|(m, _)| *m == n),
            "verify lost frame {n}"
        );
        match reader.read_frame(n) {
            Ok(mesh) => {
                let v = mesh.positions.len() as u32;
                assert!(mesh.triangles.iter().flatten().all(|&i| i < v));
            }
            Err(e) if good => panic!("verify calls frame {n} good, but it does not read: {e}"),
            Err(e) => common::check_error(&path, &e),
        }
    }
    // Repair keeps every frame that read: the same mesh, bit for bit.
    let repaired = common::scratch_dir().join("repaired.mseq");
    let _ = std::fs::remove_file(&repaired);
    match meniscus::archive::repair(&path, &repaired) {
        Ok(_) => {
            let after = ArchiveReader::open(&repaired).expect("a repaired archive opens");
            for &n in &report.good {
                let before = reader.read_frame(n).expect("a good frame reads");
                let kept = after
                    .read_frame(n)
                    .unwrap_or_else(|e| panic!("repair lost good frame {n}: {e}"));
                assert!(same(&before, &kept), "repair changed good frame {n}");
            }
        }
        Err(e) => common::check_error(&path, &e),
    }
}

/// The same mesh, compared bit for bit (NaN included).
fn same(a: &meniscus::mesh::TriMesh, b: &meniscus::mesh::TriMesh) -> bool {
    let bits = |v: &[glam::Vec3]| {
        v.iter()
            .flat_map(|p| p.to_array().map(f32::to_bits))
            .collect::<Vec<_>>()
    };
    a.triangles == b.triangles
        && bits(&a.positions) == bits(&b.positions)
        && bits(&a.normals) == bits(&b.normals)
        && format!("{:?}", a.attributes) == format!("{:?}", b.attributes)
}

fuzz_target!(|data: &[u8]| {
    // One decoding thread: the fuzzer runs beside other work.
    static ONE_THREAD: std::sync::Once = std::sync::Once::new();
    ONE_THREAD.call_once(|| std::env::set_var("RAYON_NUM_THREADS", "1"));
    read("input.mseq", data);
    let mut resealed = data.to_vec();
    reseal(&mut resealed);
    if resealed != data {
        read("resealed.mseq", &resealed);
    }
});
