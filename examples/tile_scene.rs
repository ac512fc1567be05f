//! Builds a large benchmark scene by tiling copies of a real frame side by side in x and z
//! (never committed; write it to a temporary folder).
//!
//! `cargo run --release --example tile_scene -- INPUT COPIES OUTPUT.xyz`
//! e.g. `... datasets/dambreak_small/ParticleData_Fluid_25.xyz 96 /tmp/scene_4m.xyz`

use glam::Vec3;
use meniscus::io::particles::{read_particles, write_particles, ParticleFormat, Particles};
use std::path::Path;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() != 4 {
        eprintln!("usage: tile_scene INPUT COPIES OUTPUT.xyz");
        std::process::exit(2);
    }
    let frame = read_particles(Path::new(&args[1]), None).expect("readable input");
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
    write_particles(
        Path::new(&args[3]),
        &Particles {
            positions,
            attributes: Vec::new(),
        },
        ParticleFormat::Xyz,
    )
    .expect("writable output");
    println!("{count} particles written to {}", args[3]);
}
