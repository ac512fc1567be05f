//! Criterion benches of the `.mseq` codec on the six shipped `dambreak_small` frames,
//! reconstructed with the full pipeline the way `meniscus reconstruct … -o run.mseq` stores
//! them (the decimated control mesh plus one Loop step, subdivided on decoding, and the
//! isolated-particle spheres as instances), at an error bound of 0.01 r: encode (append)
//! and decode (read, normals recomputed) speed in output triangles per second, and the
//! bytes per triangle printed once. Frame 25 also with a velocity field (the velocity of
//! the nearest particle of `ParticleData_Fluid_25.vtk` at every control vertex, default
//! attribute bound): its bytes with and without printed once, its encode and decode timed.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use meniscus::archive::{ArchiveFrame, ArchiveOptions, ArchiveReader, ArchiveWriter};
use meniscus::io::particles::read_particles;
use meniscus::mesh::{Attribute, Surface, TriMesh};
use meniscus::pipeline::{reconstruct, ReconstructOptions};
use std::path::Path;

const FRAMES: [i64; 6] = [1, 9, 17, 25, 31, 45];

/// The velocity of the nearest particle at every vertex of `mesh`.
fn nearest_particle_velocity(
    mesh: &TriMesh,
    particles: &[glam::Vec3],
    velocity: &Attribute,
    cell: f32,
) -> Attribute {
    let key = |p: glam::Vec3| (p / cell).floor().as_ivec3();
    let mut grid: hashbrown::HashMap<glam::IVec3, Vec<u32>> = hashbrown::HashMap::new();
    for (i, &p) in particles.iter().enumerate() {
        grid.entry(key(p)).or_default().push(i as u32);
    }
    let nearest = |p: glam::Vec3| {
        let c = key(p);
        let near = (0..27).flat_map(|d| {
            let k = c + glam::IVec3::new(d % 3 - 1, d / 3 % 3 - 1, d / 9 - 1);
            grid.get(&k)
                .map(|v| v.as_slice())
                .unwrap_or(&[])
                .iter()
                .map(|&i| i as usize)
        });
        near.min_by(|&a, &b| {
            let (da, db) = (
                particles[a].distance_squared(p),
                particles[b].distance_squared(p),
            );
            da.total_cmp(&db)
        })
        .unwrap_or_else(|| {
            (0..particles.len())
                .min_by(|&a, &b| {
                    let (da, db) = (
                        particles[a].distance_squared(p),
                        particles[b].distance_squared(p),
                    );
                    da.total_cmp(&db)
                })
                .expect("particles")
        })
    };
    Attribute {
        name: "velocity".into(),
        components: 3,
        values: mesh
            .positions
            .iter()
            .flat_map(|&p| velocity.item(nearest(p)).to_vec())
            .collect(),
    }
}

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
    // Frame 25 with its velocities.
    let vtk = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("datasets/dambreak_small/ParticleData_Fluid_25.vtk");
    let particles = read_particles(&vtk, None).expect("shipped dataset");
    let velocity = particles
        .attributes
        .iter()
        .find(|a| a.name == "velocity")
        .expect("velocities in the VTK");
    let mut with_velocity = surfaces[3].clone();
    with_velocity.fluid.attributes = vec![nearest_particle_velocity(
        &with_velocity.fluid,
        &particles.positions,
        velocity,
        2.0 * r,
    )];
    let frame_25 = ArchiveFrame {
        fluid: &with_velocity.fluid,
        subdivision_levels: levels,
        spheres: &with_velocity.spheres,
    };
    let velocity_file = dir.path().join("velocity.mseq");
    let mut w25 = ArchiveWriter::create(&velocity_file, &archive_options).unwrap();
    let with = w25.append_frame(25, &frame_25).unwrap();
    w25.finish().unwrap();
    let mut plain = ArchiveWriter::create(&dir.path().join("p.mseq"), &archive_options).unwrap();
    let without = plain.append_frame(25, &frames[3]).unwrap();
    println!(
        "frame 25: {without} bytes without velocity, {with} with (default attribute bound {}), {} control vertices",
        archive_options.attribute_error_bound,
        with_velocity.fluid.vertex_count()
    );
    let velocity_reader = ArchiveReader::open(&velocity_file).unwrap();
    group.throughput(Throughput::Elements(
        velocity_reader.frames()[0].triangles as u64,
    ));
    group.bench_function("encode_frame_25_with_velocity", |b| {
        b.iter(|| {
            next += 1;
            w.append_frame(next, &frame_25).unwrap();
        })
    });
    group.bench_function("decode_frame_25_with_velocity", |b| {
        b.iter(|| velocity_reader.read_geometry(25).unwrap())
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
