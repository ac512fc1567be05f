//! Criterion benches of the `.mseq` codec on the six shipped `dambreak_small` frames,
//! reconstructed with the full pipeline the way `meniscus reconstruct … -o run.mseq` stores
//! them (the decimated control mesh plus one Loop step, subdivided on decoding, and the
//! isolated-particle spheres as instances), at an error bound of 0.01 r: encode (append)
//! and decode (read, normals recomputed) speed in output triangles per second, and the
//! bytes per triangle printed once.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use meniscus::archive::{ArchiveFrame, ArchiveOptions, ArchiveReader, ArchiveWriter};
use meniscus::io::particles::read_particles;
use meniscus::mesh::Surface;
use meniscus::pipeline::{reconstruct, ReconstructOptions};
use std::path::Path;

const FRAMES: [i64; 6] = [1, 9, 17, 25, 31, 45];

fn bench(c: &mut Criterion) {
    // As the `meniscus` command runs.
    meniscus::tune_allocator();
    let r = 0.012;
    let mut options = ReconstructOptions::new(r);
    let levels = options.subdivide.levels;
    options.subdivide.levels = 0;
    let surfaces: Vec<Surface> = FRAMES
        .iter()
        .map(|k| {
            let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!(
                "datasets/dambreak_small/ParticleData_Fluid_{k}.xyz"
            ));
            let particles = read_particles(&path, None).expect("shipped dataset");
            reconstruct(&particles.positions, &options).unwrap().0
        })
        .collect();
    let frames: Vec<ArchiveFrame> = surfaces
        .iter()
        .map(|s| ArchiveFrame {
            fluid: &s.fluid,
            subdivision_levels: levels,
            spheres: &s.spheres,
        })
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("bench.mseq");
    let archive_options = ArchiveOptions::new(0.01 * r as f64);
    let mut w = ArchiveWriter::create(&file, &archive_options).unwrap();
    for (n, f) in FRAMES.iter().zip(&frames) {
        w.append_frame(*n, f).unwrap();
    }
    w.finish().unwrap();
    let reader = ArchiveReader::open(&file).unwrap();
    let triangles: u64 = reader.frames().iter().map(|f| f.triangles as u64).sum();
    let bytes = std::fs::metadata(&file).unwrap().len();
    println!(
        "{} frames, {triangles} triangles, {bytes} bytes: {:.3} bytes per triangle at 0.01 r",
        FRAMES.len(),
        bytes as f64 / triangles as f64
    );
    let mut group = c.benchmark_group("archive_dambreak_small");
    group.sample_size(10);
    group.throughput(Throughput::Elements(triangles));
    // Encoding and appending (no fsync: finish() runs once per archive, not per frame).
    let mut w = ArchiveWriter::create(&dir.path().join("e.mseq"), &archive_options).unwrap();
    let mut next = 0i64;
    group.bench_function("encode", |b| {
        b.iter(|| {
            for f in &frames {
                next += 1;
                w.append_frame(next, f).unwrap();
            }
        })
    });
    // Positions and triangles (like a positions-only Draco or meshoptimizer decode) ...
    group.bench_function("decode", |b| {
        b.iter(|| {
            for n in FRAMES {
                reader.read_geometry(n).unwrap();
            }
        })
    });
    // A sequence on both cores: one frame per worker thread.
    group.bench_function("decode_sequence_parallel", |b| {
        use rayon::prelude::*;
        b.iter(|| {
            FRAMES.par_iter().for_each(|&n| {
                reader.read_geometry(n).unwrap();
            })
        })
    });
    // ... and with the area-weighted normals recomputed.
    group.bench_function("decode_with_normals", |b| {
        b.iter(|| {
            for n in FRAMES {
                reader.read_surface(n).unwrap();
            }
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
