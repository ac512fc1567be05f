//! Measures the USD stage writer on a long sequence (not a criterion bench: one run that
//! prints its figures; `docs/usd.md` records them). One real frame is read from a mesh file
//! and appended `FRAMES` times, its points moved a little each frame (the writer does not
//! look at the topology, so a real frame's index locality gives real compression), then:
//! time per appended frame (mean, max), time of `finish`, bytes per triangle of the stage
//! against a binary PLY of the same frame, and the process's peak resident memory before
//! and after the sequence (Linux `VmHWM`): a writer that held earlier frames would grow by
//! one frame's arrays per frame.
//!
//! ```text
//! cargo run --release -- reconstruct datasets/dambreak_small/ParticleData_Fluid_25.vtk \
//!     -r 0.012 -c 0.7 --decimate off --subdivide 1 -o /tmp/frame.ply      # ~1M triangles
//! cargo bench --bench usd_stage -- /tmp/frame.ply 200 /tmp/shot.usdc     # or shot.usda
//! ```
//!
//! The stage is removed afterwards (200 such frames take about 4.6 GB) unless `--keep`
//! follows (to open it with another program).

use glam::Vec3;
use meniscus::io::mesh::{read_mesh, write_surface, MeshWriteOptions};
use meniscus::io::usd::{UsdOptions, UsdStageWriter};
use meniscus::mesh::Surface;
use std::path::PathBuf;
use std::time::Instant;

/// A `/proc/self/status` figure in MiB (`VmHWM`: peak resident, `VmRSS`: now).
fn memory_mib(field: &str) -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find(|l| l.starts_with(field))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|kb| kb.parse::<f64>().ok())
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

fn main() {
    let mut args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| a != "--bench")
        .collect();
    let keep = args.last().is_some_and(|a| a == "--keep");
    if keep {
        args.pop();
    }
    let [input, frames, output] = args.as_slice() else {
        eprintln!(
            "usage: cargo bench --bench usd_stage -- FRAME.ply FRAMES OUT.usdc|OUT.usda [--keep]"
        );
        std::process::exit(2);
    };
    let frames: i64 = frames.parse().expect("a frame count");
    let output = PathBuf::from(output);
    let mut surface = Surface {
        fluid: read_mesh(input.as_ref()).unwrap_or_else(|e| panic!("{e}")),
        ..Surface::default()
    };
    if surface.fluid.normals.is_empty() {
        surface.fluid.compute_normals();
    }
    let triangles = surface.fluid.triangle_count();
    let attributes: Vec<String> = surface
        .fluid
        .attributes
        .iter()
        .map(|a| format!("{} ({})", a.name, a.components))
        .collect();
    let ply = output.with_extension("ply");
    let start = Instant::now();
    let ply_bytes = write_surface(&ply, &surface, &MeshWriteOptions::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .bytes;
    let ply_seconds = start.elapsed().as_secs_f64();
    std::fs::remove_file(&ply).ok();
    let before = memory_mib("VmHWM");
    let resident = memory_mib("VmRSS");

    let mut stage =
        UsdStageWriter::create(&output, &UsdOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    let mut times = Vec::with_capacity(frames as usize);
    for frame in 1..=frames {
        let shift = Vec3::new(1e-4, -2e-4, 5e-5);
        for p in &mut surface.fluid.positions {
            *p += shift;
        }
        let start = Instant::now();
        stage
            .append_frame(frame, &surface)
            .unwrap_or_else(|e| panic!("{e}"));
        times.push(start.elapsed().as_secs_f64());
    }
    let start = Instant::now();
    let stats = stage.finish().unwrap_or_else(|e| panic!("{e}"));
    let finish = start.elapsed().as_secs_f64();
    if !keep {
        std::fs::remove_file(&output).ok();
    }

    let mean = times.iter().sum::<f64>() / times.len() as f64;
    let max = times.iter().copied().fold(0.0, f64::max);
    let per_triangle = stats.bytes as f64 / (triangles as f64 * frames as f64);
    println!(
        "input: {input}: {triangles} triangles, {} vertices, attributes {attributes:?}",
        surface.fluid.vertex_count()
    );
    println!(
        "stage: {} ({frames} frames): {} bytes, {per_triangle:.2} bytes/triangle",
        output.display(),
        stats.bytes
    );
    println!(
        "binary PLY of the frame: {ply_bytes} bytes, {:.2} bytes/triangle, written in {:.1} ms",
        ply_bytes as f64 / triangles as f64,
        ply_seconds * 1e3
    );
    println!(
        "append_frame: mean {:.1} ms, max {:.1} ms; finish {:.1} ms",
        mean * 1e3,
        max * 1e3,
        finish * 1e3
    );
    println!("resident before the stage {resident:.1} MiB (the frame); peak before {before:.1} MiB, after {:.1} MiB", memory_mib("VmHWM"));
}
