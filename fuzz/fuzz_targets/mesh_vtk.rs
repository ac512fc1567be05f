//! Mesh reader, vtk: `read_mesh` on a `.vtk` file.
#![no_main]

#[path = "../common/mod.rs"]
mod common;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    common::mesh::run("input.vtk", data);
});
