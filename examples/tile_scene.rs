//! Builds a large benchmark scene by tiling copies of a real frame side by side in x and z
//! (never committed; write it to a temporary folder).
//!
//! `cargo run --release --example tile_scene -- INPUT COPIES OUTPUT`
//! e.g. `... datasets/dambreak_small/ParticleData_Fluid_25.xyz 96 /tmp/scene_4m.xyz`;
//! an OUTPUT `.ply` or `.vtk` keeps the input's point attributes (a `.vtk` frame's
//! velocity: `... ParticleData_Fluid_25.vtk 96 /tmp/scene_4m_velocity.ply`).
//!
//! A fifth argument `splash` turns each copy into a violent splash (deterministic): a
//! smooth displacement field, strongest at the top of the fluid, stretches it into sheets
//! and filaments, and one particle in twenty is thrown up to 12 r away as spray.

use glam::Vec3;
use meniscus::io::particles::{read_particles, write_particles, ParticleFormat, Particles};
use std::path::Path;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if !(args.len() == 4 || args.len() == 5 && args[4] == "splash") {
        eprintln!("usage: tile_scene INPUT COPIES OUTPUT(.xyz|.ply|.vtk) [splash]");
        std::process::exit(2);
    }
    let mut frame = read_particles(Path::new(&args[1]), None).expect("readable input");
    if args.len() == 5 {
        splash(&mut frame.positions);
    }
    let copies: usize = args[2].parse().expect("COPIES is a whole number");
    let (lo, hi) = frame.positions.iter().fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(l, h), p| (l.min(*p), h.max(*p)),
    );
    let step = (hi - lo) + Vec3::splat(0.1);
    let per_row = (copies as f64).sqrt().ceil() as usize;
    let mut positions = Vec::with_capacity(frame.positions.len() * copies);
    for n in 0..copies {
        let offset = Vec3::new(
            (n % per_row) as f32 * step.x,
            0.0,
            (n / per_row) as f32 * step.z,
        );
        positions.extend(frame.positions.iter().map(|p| *p + offset));
    }
    let count = positions.len();
    let output = Path::new(&args[3]);
    let format = ParticleFormat::from_path(output).expect("OUTPUT is .xyz, .ply or .vtk");
    let mut attributes = frame.attributes;
    for a in &mut attributes {
        a.values = a.values.repeat(copies);
    }
    write_particles(
        output,
        &Particles {
            positions,
            attributes,
        },
        format,
    )
    .expect("writable output");
    println!("{count} particles written to {}", args[3]);
}

/// Stretches the fluid into sheets and filaments and throws spray (see the module docs).
fn splash(positions: &mut [Vec3]) {
    let (lo, hi) = positions.iter().fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(l, h), p| (l.min(*p), h.max(*p)),
    );
    let extent = hi - lo;
    let spacing = spacing(positions);
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    let mut random = move || {
        // splitmix64
        state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 11) as f32 / (1u64 << 53) as f32
    };
    let wave = 2.0 * std::f32::consts::PI / (0.35 * extent.max_element());
    let amplitude = 0.12 * extent.max_element();
    for p in positions.iter_mut() {
        let height = ((p.y - lo.y) / extent.y.max(f32::MIN_POSITIVE)).clamp(0.0, 1.0);
        let w = height * height * (3.0 - 2.0 * height);
        let d = Vec3::new(
            (wave * (p.y + 0.7 * p.z) + 1.0).sin(),
            (wave * (p.x - 0.4 * p.z) + 2.0).sin().abs(),
            (wave * (p.x + p.y) + 3.0).sin(),
        );
        *p += amplitude * w * d;
        if random() < 0.05 {
            let kick = Vec3::new(random() - 0.5, random(), random() - 0.5);
            *p += kick.normalize_or_zero() * (12.0 * 0.5 * spacing * random());
        }
    }
}

/// Median distance to the nearest other particle, sampled (the rest spacing 2r).
fn spacing(positions: &[Vec3]) -> f32 {
    let stride = (positions.len() / 200).max(1);
    let mut d: Vec<f32> = positions
        .iter()
        .step_by(stride)
        .map(|p| {
            positions
                .iter()
                .map(|q| p.distance(*q))
                .filter(|d| *d > 0.0)
                .fold(f32::MAX, f32::min)
        })
        .collect();
    d.sort_by(f32::total_cmp);
    d[d.len() / 2]
}
