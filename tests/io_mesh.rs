//! Mesh writers: round trips through the readers for every format, glTF structure, atomic
//! writes, and bad mesh input.

use glam::Vec3;
use meniscus::io::mesh::{read_mesh, write_surface, MeshFormat, MeshWriteOptions};
use meniscus::isolated::icosphere;
use meniscus::mesh::{SphereInstances, Surface, TriMesh};
use meniscus::Error;
use std::path::Path;

fn surface() -> Surface {
    let mut fluid = icosphere(2, 1.5);
    for p in &mut fluid.positions {
        *p += Vec3::new(0.1, -0.2, 0.3);
    }
    Surface {
        fluid,
        spheres: SphereInstances {
            template: icosphere(1, 0.1),
            centers: vec![Vec3::new(3.0, 0.0, 0.0), Vec3::new(-3.0, 1.0, 0.5)],
            attributes: Vec::new(),
        },
    }
}

fn bits(p: &[Vec3]) -> Vec<[u32; 3]> {
    p.iter().map(|v| v.to_array().map(f32::to_bits)).collect()
}

#[test]
fn every_format_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let s = surface();
    let merged = s.merged();
    for ext in ["glb", "gltf", "ply", "obj", "vtk"] {
        let path = dir.path().join(format!("s.{ext}"));
        let stats = write_surface(&path, &s, &MeshWriteOptions::default()).unwrap();
        assert_eq!(stats.triangles, merged.triangle_count(), "{ext}");
        assert_eq!(
            stats.bytes,
            std::fs::metadata(&path).unwrap().len(),
            "{ext}"
        );
        if ext == "vtk" {
            continue; // no VTK mesh reader: checked by its header below
        }
        let back = read_mesh(&path).unwrap();
        assert_eq!(back.triangles, merged.triangles, "{ext}");
        if ext == "glb" || ext == "gltf" {
            // Instances come back translated by their node: equal up to f32 rounding.
            for (a, b) in back.positions.iter().zip(&merged.positions) {
                assert!((*a - *b).length() < 1e-6, "{ext}");
            }
        } else {
            assert_eq!(bits(&back.positions), bits(&merged.positions), "{ext}");
            assert_eq!(bits(&back.normals), bits(&merged.normals), "{ext}");
        }
    }
    let vtk = std::fs::read(dir.path().join("s.vtk")).unwrap();
    let head = String::from_utf8_lossy(&vtk[..200]);
    assert!(
        head.contains(&format!("POINTS {} float", merged.vertex_count())),
        "{head}"
    );
}

#[test]
fn glb_holds_one_fluid_node_and_one_node_per_sphere() {
    let dir = tempfile::tempdir().unwrap();
    let s = surface();
    let path = dir.path().join("s.glb");
    write_surface(&path, &s, &MeshWriteOptions::default()).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(bytes.len() % 4, 0);
    let gltf = gltf::Gltf::from_slice(&bytes).unwrap();
    assert_eq!(gltf.meshes().count(), 2);
    assert_eq!(gltf.nodes().count(), 2 + s.spheres.centers.len());
    let fluid = gltf.meshes().next().unwrap().primitives().next().unwrap();
    let pos = fluid.get(&gltf::Semantic::Positions).unwrap();
    assert_eq!(pos.count(), s.fluid.vertex_count());
    let bounds = fluid.bounding_box();
    let max = s
        .fluid
        .positions
        .iter()
        .fold(Vec3::splat(f32::MIN), |m, p| m.max(*p));
    assert_eq!(bounds.max, max.to_array());
    assert!(fluid.get(&gltf::Semantic::Normals).is_some());
    // Without spheres and without normals.
    let plain = Surface {
        fluid: TriMesh {
            normals: vec![],
            ..s.fluid.clone()
        },
        spheres: SphereInstances::default(),
    };
    write_surface(&path, &plain, &MeshWriteOptions::default()).unwrap();
    let gltf = gltf::Gltf::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    assert_eq!(gltf.nodes().count(), 1);
    assert!(gltf
        .meshes()
        .next()
        .unwrap()
        .primitives()
        .next()
        .unwrap()
        .get(&gltf::Semantic::Normals)
        .is_none());
}

fn temporaries(dir: &Path) -> usize {
    std::fs::read_dir(dir)
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .file_name()
                .to_string_lossy()
                .contains(".tmp-")
        })
        .count()
}

#[test]
fn failed_writes_leave_nothing_behind() {
    let dir = tempfile::tempdir().unwrap();
    let s = surface();
    // A missing directory: an I/O error naming the path, no file.
    let missing = dir.path().join("no/such/dir/s.ply");
    match write_surface(&missing, &s, &MeshWriteOptions::default()) {
        Err(Error::Io { path, .. }) => assert_eq!(path, missing),
        other => panic!("expected an I/O error, got {other:?}"),
    }
    assert!(!missing.exists());
    // The target is a directory: refused, the directory intact, no temporary file.
    let target = dir.path().join("out.glb");
    std::fs::create_dir(&target).unwrap();
    assert!(write_surface(&target, &s, &MeshWriteOptions::default()).is_err());
    assert!(target.is_dir());
    assert_eq!(temporaries(dir.path()), 0);
    // An unknown extension is refused before anything is written.
    let odd = dir.path().join("s.stl");
    assert!(matches!(
        write_surface(&odd, &s, &MeshWriteOptions::default()),
        Err(Error::UnsupportedFormat { .. })
    ));
    assert!(!odd.exists());
    // An existing file is replaced whole.
    let ply = dir.path().join("s.ply");
    std::fs::write(&ply, b"old").unwrap();
    write_surface(
        &ply,
        &s,
        &MeshWriteOptions {
            format: Some(MeshFormat::Ply),
            normals: false,
        },
    )
    .unwrap();
    assert_eq!(
        read_mesh(&ply).unwrap().triangle_count(),
        s.merged().triangle_count()
    );
    assert_eq!(temporaries(dir.path()), 0);
}

#[test]
fn bad_meshes_are_rejected_with_their_location() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.obj");
    std::fs::write(&p, "v 0 0 0\nv 1 0 0\nf 1 2 3\n").unwrap();
    let msg = read_mesh(&p).unwrap_err().to_string();
    assert!(
        msg.contains("line 3") && msg.contains("out of range"),
        "{msg}"
    );
    let p = dir.path().join("bad.ply");
    std::fs::write(&p, b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n\0\0\0\0").unwrap();
    let msg = read_mesh(&p).unwrap_err().to_string();
    assert!(msg.contains("truncated"), "{msg}");
    let p = dir.path().join("range.ply");
    std::fs::write(&p, "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n").unwrap();
    let msg = read_mesh(&p).unwrap_err().to_string();
    assert!(msg.contains("face 0"), "{msg}");
}
