//! Writes small USD stages with the stage writer, plus `usd_expected.json` with what each
//! must hold, for `tests/usd/check_stages.py` (Pixar's `usd-core` reads them back):
//!
//! * `sequence.usdc` and `sequence.usda`: frames 1, 2 and 5 (a gap), a fluid whose
//!   topology changes every frame, attributes of 1 to 4 components (velocity, density,
//!   `tex-coord`, colour), isolated particles in frames 1 and 5 only (a point cloud, the
//!   default), with a velocity and a density per point, those of frame 1 of three sizes
//!   (scales 1, 2, 0.5);
//! * `instanced.usdc` and `instanced.usda`: the same frames with the isolated particles
//!   as a point instancer of the icosphere;
//! * `no_spheres.usdc`: two frames without spheres, up axis Z, 100 frames per second,
//!   centimetres;
//! * `wide.usdc`: one frame with a 6-component attribute (`elementSize` 6) and no normals;
//! * `empty.usdc`, `empty.usda`: no frame (every frame of a run failed): the mesh with no
//!   samples, no time range.
//!
//! `cargo run --release --example usd_fixture -- OUT_DIR`

use glam::Vec3;
use meniscus::io::usd::{UpAxis, UsdDroplets, UsdOptions, UsdStageWriter};
use meniscus::isolated::icosphere;
use meniscus::mesh::{Attribute, SphereInstances, Surface, TriMesh};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// An attribute of `components` floats per item that varies from item to item (not a
/// constant that would hide an ordering mistake).
fn attribute(name: &str, components: usize, items: usize, seed: f32) -> Attribute {
    let values = (0..items * components)
        .map(|i| seed + (i * 37 % 101) as f32 * 0.125 - (i % components) as f32)
        .collect();
    Attribute {
        name: name.into(),
        components,
        values,
    }
}

/// The fluid of frame `frame`: an icosphere of a level that changes the topology, moved
/// and squashed, with the attributes of `layout` (name, components).
fn fluid(frame: i64, layout: &[(&str, usize)], normals: bool) -> TriMesh {
    let mut mesh = icosphere(1 + (frame % 2) as u32, 1.0);
    let shift = Vec3::new(0.1 * frame as f32, 1.0, -0.25);
    for p in &mut mesh.positions {
        *p = *p * Vec3::new(1.0, 0.5 + 0.1 * frame as f32, 1.0) + shift;
    }
    if normals {
        mesh.compute_normals();
    } else {
        mesh.normals.clear();
    }
    let n = mesh.positions.len();
    mesh.attributes = layout
        .iter()
        .map(|&(name, c)| attribute(name, c, n, frame as f32))
        .collect();
    mesh
}

/// Isolated spheres of frame `frame`: `count` centres with a velocity and a density;
/// in frame 1 of three sizes (scales 1, 2 and 0.5).
fn spheres(frame: i64, count: usize) -> SphereInstances {
    let centers: Vec<Vec3> = (0..count)
        .map(|i| Vec3::new(2.0 + i as f32, 0.5 * frame as f32, -(i as f32)))
        .collect();
    SphereInstances {
        template: icosphere(1, 0.05),
        scales: if frame == 1 {
            [1.0, 2.0, 0.5][..count].to_vec()
        } else {
            Vec::new()
        },
        attributes: vec![
            attribute("velocity", 3, count, 10.0 + frame as f32),
            attribute("density", 1, count, 1000.0),
        ],
        centers,
    }
}

/// What a frame must read back as.
fn expected_frame(frame: i64, surface: &Surface) -> Value {
    let mesh = |m: &TriMesh| {
        json!({
            "points": m.positions.iter().map(|p| p.to_array()).collect::<Vec<_>>(),
            "normals": m.normals.iter().map(|p| p.to_array()).collect::<Vec<_>>(),
            "indices": m.triangles.iter().flatten().collect::<Vec<_>>(),
            "attributes": m.attributes.iter().map(|a| json!({
                "name": a.name, "components": a.components, "values": a.values,
            })).collect::<Vec<_>>(),
        })
    };
    let s = &surface.spheres;
    json!({
        "frame": frame,
        "fluid": mesh(&surface.fluid),
        "spheres": {
            "centers": s.centers.iter().map(|p| p.to_array()).collect::<Vec<_>>(),
            "scales": s.scales,
            "attributes": s.attributes.iter().map(|a| json!({
                "name": a.name, "components": a.components, "values": a.values,
            })).collect::<Vec<_>>(),
            "template": mesh(&s.template),
        },
    })
}

/// Writes `frames` to `path` and returns what the check expects of it.
fn write(path: &Path, options: &UsdOptions, frames: &[(i64, Surface)]) -> Value {
    let mut stage = UsdStageWriter::create(path, options).unwrap_or_else(|e| panic!("{e}"));
    for (frame, surface) in frames {
        stage
            .append_frame(*frame, surface)
            .unwrap_or_else(|e| panic!("{e}"));
    }
    let stats = stage.finish().unwrap_or_else(|e| panic!("{e}"));
    println!(
        "{}: {} bytes, {} frames",
        path.display(),
        stats.bytes,
        stats.frames
    );
    json!({
        "file": path.file_name().unwrap().to_string_lossy(),
        "droplets": options.droplets.name(),
        "fps": options.fps,
        "up_axis": options.up_axis.token(),
        "meters_per_unit": options.meters_per_unit,
        "frames": frames.iter().map(|(n, s)| expected_frame(*n, s)).collect::<Vec<_>>(),
    })
}

fn main() {
    let Some(dir) = std::env::args().nth(1).map(PathBuf::from) else {
        eprintln!("usage: usd_fixture OUT_DIR");
        std::process::exit(2);
    };
    std::fs::create_dir_all(&dir).expect("an output directory");
    let layout = [
        ("velocity", 3),
        ("density", 1),
        ("tex-coord", 2),
        ("color", 4),
    ];
    let sequence: Vec<(i64, Surface)> = [(1, 3), (2, 0), (5, 2)]
        .into_iter()
        .map(|(frame, count)| {
            let surface = Surface {
                fluid: fluid(frame, &layout, true),
                spheres: if count > 0 {
                    spheres(frame, count)
                } else {
                    SphereInstances::default()
                },
            };
            (frame, surface)
        })
        .collect();
    let mut stages = Vec::new();
    for name in ["sequence.usdc", "sequence.usda"] {
        stages.push(write(&dir.join(name), &UsdOptions::default(), &sequence));
    }
    let instanced = UsdOptions {
        droplets: UsdDroplets::Instancer,
        ..UsdOptions::default()
    };
    for name in ["instanced.usdc", "instanced.usda"] {
        stages.push(write(&dir.join(name), &instanced, &sequence));
    }
    let plain: Vec<(i64, Surface)> = [10, 11]
        .into_iter()
        .map(|frame| {
            (
                frame,
                Surface {
                    fluid: fluid(frame, &[("velocity", 3)], true),
                    ..Default::default()
                },
            )
        })
        .collect();
    let options = UsdOptions {
        fps: 100.0,
        up_axis: UpAxis::Z,
        meters_per_unit: 0.01,
        ..UsdOptions::default()
    };
    stages.push(write(&dir.join("no_spheres.usdc"), &options, &plain));
    let wide = vec![(
        0,
        Surface {
            fluid: fluid(0, &[("stress", 6)], false),
            ..Default::default()
        },
    )];
    stages.push(write(&dir.join("wide.usdc"), &UsdOptions::default(), &wide));
    for name in ["empty.usdc", "empty.usda"] {
        stages.push(write(&dir.join(name), &UsdOptions::default(), &[]));
    }
    let path = dir.join("usd_expected.json");
    std::fs::write(
        &path,
        serde_json::to_string(&json!({ "stages": stages })).expect("JSON"),
    )
    .expect("writable");
    println!("{}", path.display());
}
