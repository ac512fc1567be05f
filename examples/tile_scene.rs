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

#[path = "../tests/support/splash.rs"]
mod splash;

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
        splash::splash(&mut frame.positions);
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
