//! The mesh reader on one input, written with the extension that picks the format.

use super::{check_error, input_file};

pub fn run(name: &str, data: &[u8]) {
    let path = input_file(name, data);
    match meniscus::io::mesh::read_mesh(&path) {
        Ok(mesh) => {
            let n = mesh.positions.len() as u32;
            assert!(mesh.triangles.iter().flatten().all(|&i| i < n));
        }
        Err(e) => check_error(&path, &e),
    }
}
