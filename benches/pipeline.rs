//! Whole-pipeline benchmark over real datasets: per-stage wall time (median of several
//! runs) and the peak resident memory of a process that reconstructs one frame.
//!
//! `cargo bench --bench pipeline` runs the shipped frames, frame 25 twice: as `.xyz`
//! (positions only) and as `.vtk` carrying its velocity to the surface, as the CLI does by
//! default; `MENISCUS_BENCH_SCENES` adds more as `path:radius` pairs separated by commas
//! (for example large scenes made by `cargo run --release --example tile_scene`, a `.ply`
//! one with velocity). Every scene runs in a child process so that its peak RSS (Linux
//! VmHWM) is its own.
//!
//! `MENISCUS_BENCH_PRESET=steady` times [`ReconstructOptions::steady`] instead of the
//! still default ([`ReconstructOptions::new`]); `MENISCUS_BENCH_ONLY=1` runs the scenes of
//! `MENISCUS_BENCH_SCENES` alone; `MENISCUS_BENCH_RUNS=N` sets the runs per scene (default
//! 5, 1 above 2M particles).

use meniscus::attributes::AttributeSelection;
use meniscus::io::particles::read_particles;
use meniscus::job::peak_rss_bytes;
use meniscus::pipeline::{reconstruct_source, ReconstructOptions};
use meniscus::CancelToken;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

const CHILD_ENV: &str = "MENISCUS_BENCH_CHILD";

fn main() {
    // As the `meniscus` command runs.
    meniscus::tune_allocator();
    // Cargo passes `--bench`; criterion-style filters are ignored.
    if let Ok(spec) = std::env::var(CHILD_ENV) {
        let (path, radius) = spec.rsplit_once(':').expect("path:radius");
        child(Path::new(path), radius.parse().expect("radius"));
        return;
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets");
    let only = std::env::var_os("MENISCUS_BENCH_ONLY").is_some();
    let mut scenes: Vec<(PathBuf, f32)> = vec![
        (root.join("dambreak_small/ParticleData_Fluid_25.xyz"), 0.012),
        (root.join("dambreak_small/ParticleData_Fluid_25.vtk"), 0.012),
        (root.join("dambreak_small/ParticleData_Fluid_45.xyz"), 0.012),
        (
            root.join("double_dambreak/ParticleData_Fluid_13.xyz"),
            0.025,
        ),
    ];
    if only {
        scenes.clear();
    }
    if let Ok(extra) = std::env::var("MENISCUS_BENCH_SCENES") {
        for item in extra.split(',').filter(|s| !s.is_empty()) {
            let (p, r) = item
                .rsplit_once(':')
                .expect("MENISCUS_BENCH_SCENES: path:radius,...");
            scenes.push((PathBuf::from(p), r.parse().expect("radius")));
        }
    }
    let exe = std::env::current_exe().expect("bench executable");
    for (path, radius) in scenes {
        let out = Command::new(&exe)
            .env(CHILD_ENV, format!("{}:{radius}", path.display()))
            .output()
            .expect("run child");
        print!("{}", String::from_utf8_lossy(&out.stdout));
        if !out.status.success() {
            eprintln!(
                "{} failed: {}",
                path.display(),
                String::from_utf8_lossy(&out.stderr)
            );
        }
    }
}

fn child(path: &Path, radius: f32) {
    let clock = Instant::now();
    // The velocity, when the file has one, as the CLI's default.
    let particles = read_particles(path, None)
        .expect("readable scene")
        .select(path, &AttributeSelection::Velocity)
        .expect("valid attributes");
    let carried: Vec<String> = particles
        .attributes
        .iter()
        .map(|a| a.name.clone())
        .collect();
    let read = clock.elapsed().as_secs_f64();
    let preset = std::env::var("MENISCUS_BENCH_PRESET").unwrap_or_else(|_| "still".into());
    let options = match preset.as_str() {
        "still" => ReconstructOptions::new(radius),
        "steady" => ReconstructOptions::steady(radius),
        other => panic!("MENISCUS_BENCH_PRESET: still or steady, got {other}"),
    };
    let count = particles.positions.len();
    let runs = match std::env::var("MENISCUS_BENCH_RUNS") {
        Ok(n) => n.parse().expect("MENISCUS_BENCH_RUNS: a count"),
        Err(_) if count > 2_000_000 => 1,
        Err(_) => 5,
    };
    let mut all = Vec::new();
    let mut digest = 0;
    for _ in 0..runs {
        let (surface, stats) =
            reconstruct_source(particles.clone(), &options, &|_| {}, &CancelToken::new())
                .expect("reconstruction");
        digest = surface_digest(&surface.fluid);
        all.push(stats);
    }
    let mut totals: Vec<f64> = all.iter().map(|s| s.total_seconds()).collect();
    totals.sort_by(f64::total_cmp);
    let median = &all[all
        .iter()
        .position(|s| s.total_seconds() == totals[totals.len() / 2])
        .unwrap()];
    println!(
        "\n{} ({preset}) — {} particles, r = {radius}, attributes [{}], read {:.1} ms, median of {runs} runs, peak RSS {:.1} MiB",
        path.display(),
        count,
        carried.join(", "),
        read * 1e3,
        peak_rss_bytes().unwrap_or(0) as f64 / (1 << 20) as f64
    );
    print!("{}", median.table());
    // What a change that should leave the output as it was compares, run against run.
    println!("surface digest {digest:016x}");
    if let Some(c) = &median.containment {
        println!("containment {c:?}");
    }
}

/// FNV-1a over the bits of the fluid surface's positions, triangles and normals.
fn surface_digest(mesh: &meniscus::mesh::TriMesh) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    let mut eat = |x: u32| {
        for b in x.to_le_bytes() {
            h = (h ^ b as u64).wrapping_mul(0x0100_0000_01b3);
        }
    };
    for p in mesh.positions.iter().chain(&mesh.normals) {
        for c in p.to_array() {
            eat(c.to_bits());
        }
    }
    for &[a, b, c] in &mesh.triangles {
        [a, b, c].into_iter().for_each(&mut eat);
    }
    h
}
