//! Particle reader, xyz: `read_particles`, the streaming reader and the spooled source.
#![no_main]

#[path = "../common/mod.rs"]
mod common;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    common::particles::run_xyz(data);
});
