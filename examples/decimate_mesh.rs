//! Decimates a mesh file and prints the time, the throughput and the decimation stats:
//! a quick way to profile the decimator on big surfaces without the rest of the pipeline.
//!
//! `cargo run --release --example decimate_mesh -- raw.ply [out.ply] [reduction|error=E|reduction,error=E]`

use meniscus::decimation::{decimate, DecimateOptions};
use meniscus::io::mesh::{read_mesh, write_surface, MeshWriteOptions};
use meniscus::mesh::Surface;
use std::path::Path;
use std::time::Instant;

fn main() {
    meniscus::tune_allocator();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(input) = args.first() else {
        eprintln!("usage: decimate_mesh IN.ply [OUT.ply] [reduction|error=E|reduction,error=E]");
        std::process::exit(2);
    };
    let mut mesh = read_mesh(Path::new(input)).expect("readable mesh");
    let mut options = DecimateOptions::default();
    // `0.8`, `error=0.0012`, or both: `0.81,error=0.0012` (the default's shape).
    if let Some(mode) = args.get(2) {
        options.target_reduction = None;
        for part in mode.split(',') {
            if let Some(e) = part.strip_prefix("error=") {
                options.max_error = Some(e.parse().expect("an error bound"));
            } else {
                options.target_reduction = Some(part.parse().expect("a reduction fraction"));
            }
        }
    }
    let before = mesh.triangle_count();
    let start = Instant::now();
    let stats = decimate(&mut mesh, &options);
    let seconds = start.elapsed().as_secs_f64();
    println!(
        "{before} -> {} triangles in {seconds:.3} s ({:.2} M input triangles/s)\n{stats:?}",
        mesh.triangle_count(),
        before as f64 / seconds / 1e6
    );
    if let Some(out) = args.get(1) {
        let surface = Surface {
            fluid: mesh,
            ..Default::default()
        };
        write_surface(Path::new(out), &surface, &MeshWriteOptions::default())
            .expect("writable output");
    }
}
