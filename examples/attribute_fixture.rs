//! Writes a small surface with a velocity (3 components) and a density (1 component)
//! attribute, on the fluid and on isolated-particle spheres, as `attributes.glb`,
//! `attributes.gltf`, `attributes.ply` and `attributes.vtk`, plus `attributes.json` with
//! the values every vertex should carry (per mesh: `fluid`, then `isolated_particles`, the
//! spheres merged), for the glTF validator and the Blender import check in `.ci/`; and
//! `scaled_spheres.glb` / `.gltf`, spheres of three sizes (instanced nodes with a scale),
//! for the validator.
//!
//! `cargo run --release --example attribute_fixture -- OUT_DIR`

use glam::Vec3;
use meniscus::io::mesh::{write_surface, MeshWriteOptions};
use meniscus::isolated::icosphere;
use meniscus::mesh::{Attribute, SphereInstances, Surface, TriMesh};
use serde_json::json;
use std::path::PathBuf;

/// A velocity and a density that vary from item to item (not a constant that would
/// hide a vertex-order mistake).
fn attributes(positions: &[Vec3]) -> Vec<Attribute> {
    let velocity = positions
        .iter()
        .enumerate()
        .flat_map(|(i, p)| [p.y - 0.5 * p.z, 0.25 * i as f32, -p.x])
        .collect();
    let density = (0..positions.len())
        .map(|i| 1000.0 + (i * 37 % 101) as f32 * 0.125)
        .collect();
    vec![
        Attribute {
            name: "velocity".into(),
            components: 3,
            values: velocity,
        },
        Attribute {
            name: "density".into(),
            components: 1,
            values: density,
        },
    ]
}

fn expected(mesh: &TriMesh) -> serde_json::Value {
    let find = |name: &str| {
        mesh.attributes
            .iter()
            .find(|a| a.name == name)
            .map(|a| a.values.clone())
            .expect("the attribute")
    };
    json!({
        "vertices": mesh.vertex_count(),
        "positions": mesh.positions.iter().map(|p| p.to_array()).collect::<Vec<_>>(),
        "velocity": find("velocity"),
        "density": find("density"),
    })
}

fn main() {
    let Some(dir) = std::env::args().nth(1).map(PathBuf::from) else {
        eprintln!("usage: attribute_fixture OUT_DIR");
        std::process::exit(2);
    };
    std::fs::create_dir_all(&dir).expect("an output directory");
    let mut fluid = icosphere(3, 1.0);
    for p in &mut fluid.positions {
        *p += Vec3::new(0.5, 1.0, -0.25);
    }
    fluid.attributes = attributes(&fluid.positions);
    let centers = vec![
        Vec3::new(2.0, 0.5, 0.0),
        Vec3::new(-1.5, 2.0, 0.5),
        Vec3::new(0.0, -1.0, 1.5),
    ];
    let spheres = SphereInstances {
        template: icosphere(1, 0.05),
        scales: Vec::new(),
        attributes: attributes(&centers),
        centers,
    };
    let surface = Surface { fluid, spheres };
    for ext in ["glb", "gltf", "ply", "vtk"] {
        let path = dir.join(format!("attributes.{ext}"));
        let stats = write_surface(&path, &surface, &MeshWriteOptions::default())
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(stats.dropped_attributes.is_empty(), "{ext}");
        println!("{}: {} bytes", path.display(), stats.bytes);
    }
    // Spheres of three sizes without attributes: instanced nodes with a scale each, for
    // the glTF validator.
    let sized = Surface {
        fluid: surface.fluid.clone(),
        spheres: SphereInstances {
            scales: vec![1.0, 2.0, 0.5],
            attributes: Vec::new(),
            ..surface.spheres.clone()
        },
    };
    for ext in ["glb", "gltf"] {
        let path = dir.join(format!("scaled_spheres.{ext}"));
        let stats = write_surface(&path, &sized, &MeshWriteOptions::default())
            .unwrap_or_else(|e| panic!("{e}"));
        println!("{}: {} bytes", path.display(), stats.bytes);
    }
    let spheres = surface.spheres.merged();
    let doc = json!({
        "fluid": expected(&surface.fluid),
        "isolated_particles": expected(&spheres),
        "merged": expected(&surface.merged()),
    });
    let path = dir.join("attributes.json");
    std::fs::write(&path, serde_json::to_string(&doc).expect("JSON")).expect("writable");
    println!("{}", path.display());
}
