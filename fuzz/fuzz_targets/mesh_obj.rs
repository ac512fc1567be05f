//! Mesh reader, obj: `read_mesh` on a `.obj` file.
#![no_main]

#[path = "../common/mod.rs"]
mod common;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    common::mesh::run("input.obj", data);
});
