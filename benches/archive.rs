//! Criterion benches of the `.mseq` codec on a real reconstructed frame (`dambreak_small`
//! frame 25, full pipeline, about 90k triangles): encode (append) and decode (read) speed,
//! and the bytes per triangle printed once.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use meniscus::archive::{ArchiveOptions, ArchiveReader, ArchiveWriter};
use meniscus::io::particles::read_particles;
use meniscus::pipeline::{reconstruct, ReconstructOptions};
use std::path::Path;

fn bench(c: &mut Criterion) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("datasets/dambreak_small/ParticleData_Fluid_25.xyz");
    let particles = read_particles(&path, None)
        .expect("shipped dataset")
        .positions;
    let r = 0.012;
    let (surface, _) = reconstruct(&particles, &ReconstructOptions::new(r)).unwrap();
    let mesh = surface.fluid;
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("bench.mseq");
    let options = ArchiveOptions::new(0.01 * r as f64);
    {
        let mut w = ArchiveWriter::create(&file, &options).unwrap();
        let bytes = w.append(25, &mesh).unwrap();
        w.finish().unwrap();
        println!(
            "{:.3} bytes per triangle at 0.01 r",
            bytes as f64 / mesh.triangle_count() as f64
        );
    }
    let mut group = c.benchmark_group("archive_frame_25");
    group.sample_size(10);
    group.throughput(Throughput::Elements(mesh.triangle_count() as u64));
    // Encoding and appending (no fsync: finish() runs once per archive, not per frame).
    let mut w = ArchiveWriter::create(&dir.path().join("e.mseq"), &options).unwrap();
    let mut frame = 0i64;
    group.bench_function("encode", |b| {
        b.iter(|| {
            frame += 1;
            w.append(frame, &mesh).unwrap()
        })
    });
    let reader = ArchiveReader::open(&file).unwrap();
    group.bench_function("decode", |b| b.iter(|| reader.read_frame(25).unwrap()));
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
