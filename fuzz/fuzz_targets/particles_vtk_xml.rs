//! Particle reader, VTK XML (`.vtu`; the reader takes `.vtp` the same): `read_particles`,
//! the streaming reader and the spooled source.
#![no_main]

#[path = "../common/mod.rs"]
mod common;

use libfuzzer_sys::fuzz_target;
use meniscus::io::particles::ParticleFormat;

fuzz_target!(|data: &[u8]| {
    common::particles::run("input.vtu", ParticleFormat::Vtu, data);
});
