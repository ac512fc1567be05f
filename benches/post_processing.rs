//! Criterion benches of decimation and Loop subdivision on the raw marching-cubes surface
//! of a real frame (`dambreak_small` frame 25, about 112k triangles).

use criterion::{criterion_group, criterion_main, BatchSize, Criterion, Throughput};
use meniscus::decimation::{decimate, DecimateOptions};
use meniscus::io::particles::read_particles;
use meniscus::pipeline::{reconstruct, ReconstructOptions};
use meniscus::subdivision::{subdivide, SubdivideOptions};
use std::path::Path;

fn bench(c: &mut Criterion) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("datasets/dambreak_small/ParticleData_Fluid_25.xyz");
    let particles = read_particles(&path, None)
        .expect("shipped dataset")
        .positions;
    let (surface, _) = reconstruct(&particles, &ReconstructOptions::raw(0.012)).unwrap();
    let raw = surface.fluid;
    let mut group = c.benchmark_group("post_processing_frame_25");
    group.sample_size(10);
    group.throughput(Throughput::Elements(raw.triangle_count() as u64));
    group.bench_function("decimate_80_percent", |b| {
        b.iter_batched(
            || raw.clone(),
            |mut m| decimate(&mut m, &DecimateOptions::default()),
            BatchSize::LargeInput,
        )
    });
    let mut decimated = raw.clone();
    decimate(&mut decimated, &DecimateOptions::default());
    group.throughput(Throughput::Elements(4 * decimated.triangle_count() as u64));
    group.bench_function("loop_subdivision_1", |b| {
        b.iter_batched(
            || decimated.clone(),
            |mut m| subdivide(&mut m, &SubdivideOptions::default()),
            BatchSize::LargeInput,
        )
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
