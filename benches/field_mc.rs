//! Criterion benches of the field and marching-cubes stages on a real frame
//! (`dambreak_small` frame 25, 41 912 particles, r = 0.012, h = r).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use meniscus::field::{compute_field, FieldOptions};
use meniscus::io::particles::read_particles;
use meniscus::marching_cubes::extract_surface;
use std::path::Path;

fn frame_25() -> Vec<glam::Vec3> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("datasets/dambreak_small/ParticleData_Fluid_25.xyz");
    read_particles(&path, None)
        .expect("shipped dataset")
        .positions
}

fn bench(c: &mut Criterion) {
    let particles = frame_25();
    let options = FieldOptions::new(0.012);
    let mut group = c.benchmark_group("dambreak_frame_25");
    group.sample_size(20);
    group.throughput(Throughput::Elements(particles.len() as u64));
    group.bench_function("field", |b| {
        b.iter(|| compute_field(&particles, &options).unwrap())
    });
    let (field, _) = compute_field(&particles, &options).unwrap();
    group.bench_function("marching_cubes", |b| b.iter(|| extract_surface(&field)));
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
