//! Mesh writers: round trips through the readers for every format, glTF structure, atomic
//! writes, and bad mesh input.

mod support;

use glam::Vec3;
use meniscus::io::mesh::{read_mesh, write_surface, MeshFormat, MeshWriteOptions};
use meniscus::isolated::icosphere;
use meniscus::mesh::{SphereInstances, Surface, TriMesh};
use meniscus::Error;
use std::path::Path;
use support::Rng;

fn surface() -> Surface {
    let mut fluid = icosphere(2, 1.5);
    for p in &mut fluid.positions {
        *p += Vec3::new(0.1, -0.2, 0.3);
    }
    Surface {
        fluid,
        spheres: SphereInstances {
            template: icosphere(1, 0.1),
            scales: Vec::new(),
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

// ---- attributes -------------------------------------------------------------------------

use meniscus::io::mesh::write_sequence_gltf;
use meniscus::mesh::Attribute;

/// Values that differ from item to item, so that an order or grouping mistake shows.
fn values(name: &str, components: usize, items: usize, seed: f32) -> Attribute {
    Attribute {
        name: name.into(),
        components,
        values: (0..components * items)
            .map(|v| seed + v as f32 * 0.37 - (v % 7) as f32 * 1.5e-3)
            .collect(),
    }
}

/// The test surface with a velocity (3) and a density (1), on the fluid and per sphere.
fn attributed() -> Surface {
    let mut s = surface();
    let (nv, ns) = (s.fluid.vertex_count(), s.spheres.centers.len());
    s.fluid.attributes = vec![
        values("velocity", 3, nv, 1.0),
        values("density", 1, nv, 1000.0),
    ];
    s.spheres.attributes = vec![
        values("velocity", 3, ns, -4.0),
        values("density", 1, ns, 990.0),
    ];
    s
}

fn attr_bits(a: &Attribute) -> (String, usize, Vec<u32>) {
    (
        a.name.clone(),
        a.components,
        a.values.iter().map(|v| v.to_bits()).collect(),
    )
}

/// Attributes as comparable tuples, sorted by name (glTF returns them sorted).
fn sorted(list: &[Attribute]) -> Vec<(String, usize, Vec<u32>)> {
    let mut out: Vec<_> = list.iter().map(attr_bits).collect();
    out.sort();
    out
}

#[test]
fn attributes_round_trip_bit_for_bit_through_ply_vtk_and_gltf() {
    let dir = tempfile::tempdir().unwrap();
    let s = attributed();
    let merged = s.merged();
    assert_eq!(merged.attributes.len(), 2);
    for ext in ["glb", "gltf", "ply", "vtk"] {
        let path = dir.path().join(format!("a.{ext}"));
        let stats = write_surface(&path, &s, &MeshWriteOptions::default()).unwrap();
        assert!(stats.dropped_attributes.is_empty(), "{ext}");
        let back = read_mesh(&path).unwrap();
        assert_eq!(back.triangles, merged.triangles, "{ext}");
        if ext == "ply" || ext == "vtk" {
            assert_eq!(back.attributes, merged.attributes, "{ext}: order kept too");
            assert_eq!(bits(&back.positions), bits(&merged.positions), "{ext}");
            assert_eq!(bits(&back.normals), bits(&merged.normals), "{ext}");
        } else {
            // Spheres with attributes are one merged mesh: positions as merged() has them.
            assert_eq!(back.vertex_count(), merged.vertex_count(), "{ext}");
            for (a, b) in back.positions.iter().zip(&merged.positions) {
                assert!((*a - *b).length() < 1e-6, "{ext}");
            }
        }
        assert_eq!(
            sorted(&back.attributes),
            sorted(&merged.attributes),
            "{ext}"
        );
    }
}

#[test]
fn attribute_columns_are_named_per_format() {
    let dir = tempfile::tempdir().unwrap();
    let s = attributed();
    let nv = s.merged().vertex_count();
    let ply = dir.path().join("a.ply");
    write_surface(&ply, &s, &MeshWriteOptions::default()).unwrap();
    let bytes = std::fs::read(&ply).unwrap();
    let head = String::from_utf8_lossy(&bytes[..600]);
    assert!(
        head.contains("property float nz\nproperty float velocity_x\nproperty float velocity_y\nproperty float velocity_z\nproperty float density\nelement face"),
        "{head}"
    );
    let vtk = dir.path().join("a.vtk");
    write_surface(&vtk, &s, &MeshWriteOptions::default()).unwrap();
    let text = String::from_utf8_lossy(&std::fs::read(&vtk).unwrap()).into_owned();
    assert_eq!(
        text.matches("POINT_DATA").count(),
        1,
        "one point-data section"
    );
    let at = |needle: &str| text.find(needle).unwrap_or_else(|| panic!("{needle}"));
    assert!(
        at(&format!("POINT_DATA {nv}\nNORMALS normals float\n")) < at("VECTORS velocity float\n")
    );
    assert!(at("VECTORS velocity float\n") < at("SCALARS density float 1\nLOOKUP_TABLE default\n"));
    let glb = dir.path().join("a.glb");
    write_surface(&glb, &s, &MeshWriteOptions::default()).unwrap();
    let gltf = gltf::Gltf::from_slice(&std::fs::read(&glb).unwrap()).unwrap();
    // Fluid plus one merged sphere mesh, no per-instance nodes.
    assert_eq!(gltf.meshes().count(), 2);
    assert_eq!(gltf.nodes().count(), 2);
    let sphere_vertices = s.spheres.template.vertex_count() * s.spheres.centers.len();
    for (mesh, count) in gltf.meshes().zip([s.fluid.vertex_count(), sphere_vertices]) {
        let prim = mesh.primitives().next().unwrap();
        let get = |name: &str| prim.get(&gltf::Semantic::Extras(name.into())).unwrap();
        let (v, d) = (get("VELOCITY"), get("DENSITY"));
        assert_eq!(v.dimensions(), gltf::accessor::Dimensions::Vec3);
        assert_eq!(d.dimensions(), gltf::accessor::Dimensions::Scalar);
        assert_eq!(v.data_type(), gltf::accessor::DataType::F32);
        assert_eq!((v.count(), d.count()), (count, count));
    }
}

#[test]
fn two_four_and_many_components_split_and_regroup() {
    let dir = tempfile::tempdir().unwrap();
    let mut s = surface();
    s.spheres = SphereInstances::default();
    let nv = s.fluid.vertex_count();
    s.fluid.attributes = vec![
        values("uv", 2, nv, 0.5),
        values("q", 4, nv, -2.0),
        values("stress", 6, nv, 7.0),
        values("temperature", 1, nv, 300.0),
    ];
    for ext in ["ply", "vtk", "glb"] {
        let path = dir.path().join(format!("m.{ext}"));
        write_surface(&path, &s, &MeshWriteOptions::default()).unwrap();
        let back = read_mesh(&path).unwrap();
        assert_eq!(
            sorted(&back.attributes),
            sorted(&s.fluid.attributes),
            "{ext}"
        );
        let text = String::from_utf8_lossy(&std::fs::read(&path).unwrap()).into_owned();
        let names: &[&str] = match ext {
            "ply" => &[
                "property float uv_y\n",
                "property float q_w\n",
                "property float stress_0\n",
                "property float stress_5\n",
            ],
            "vtk" => &[
                "FIELD FieldData 1\nuv 2 ",
                "FIELD FieldData 1\nq 4 ",
                "FIELD FieldData 1\nstress 6 ",
                "SCALARS temperature float 1",
            ],
            _ => &[
                "\"_UV\"",
                "\"_Q\"",
                "\"_STRESS_0\"",
                "\"_STRESS_5\"",
                "\"_TEMPERATURE\"",
            ],
        };
        for n in names {
            assert!(text.contains(n), "{ext}: {n}");
        }
    }
}

#[test]
fn obj_writes_the_mesh_and_reports_the_dropped_attributes() {
    let dir = tempfile::tempdir().unwrap();
    let s = attributed();
    let path = dir.path().join("a.obj");
    let stats = write_surface(&path, &s, &MeshWriteOptions::default()).unwrap();
    assert_eq!(stats.dropped_attributes, ["velocity", "density"]);
    let back = read_mesh(&path).unwrap();
    assert_eq!(back.triangles, s.merged().triangles);
    assert!(back.attributes.is_empty());
    let plain = write_surface(&path, &surface(), &MeshWriteOptions::default()).unwrap();
    assert!(plain.dropped_attributes.is_empty());
}

#[test]
fn attributes_only_the_fluid_carries_are_kept_where_the_format_allows() {
    let dir = tempfile::tempdir().unwrap();
    let mut s = attributed();
    s.spheres.attributes.clear();
    // One vertex table for fluid and spheres: PLY and VTK cannot hold them, and say so.
    for ext in ["ply", "vtk"] {
        let path = dir.path().join(format!("f.{ext}"));
        let stats = write_surface(&path, &s, &MeshWriteOptions::default()).unwrap();
        assert_eq!(stats.dropped_attributes, ["velocity", "density"], "{ext}");
        assert!(read_mesh(&path).unwrap().attributes.is_empty(), "{ext}");
    }
    // glTF keeps them on the fluid; the spheres stay instanced by nodes.
    let path = dir.path().join("f.glb");
    let stats = write_surface(&path, &s, &MeshWriteOptions::default()).unwrap();
    assert!(stats.dropped_attributes.is_empty());
    let gltf = gltf::Gltf::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    assert_eq!(gltf.nodes().count(), 2 + s.spheres.centers.len());
    let fluid = gltf.meshes().next().unwrap().primitives().next().unwrap();
    assert!(fluid
        .get(&gltf::Semantic::Extras("VELOCITY".into()))
        .is_some());
}

#[test]
fn a_sequence_carries_the_attributes_of_every_frame() {
    let dir = tempfile::tempdir().unwrap();
    let frames: Vec<(i64, TriMesh)> = (0..3)
        .map(|k| {
            let mut m = attributed().merged();
            m.attributes[0]
                .values
                .iter_mut()
                .for_each(|v| *v += k as f32);
            (k, m)
        })
        .collect();
    let path = dir.path().join("seq.glb");
    write_sequence_gltf(&path, &frames, 24.0, &MeshWriteOptions::default()).unwrap();
    let back = read_mesh(&path).unwrap();
    let mut all = frames[0].1.clone();
    all.append(&frames[1].1);
    all.append(&frames[2].1);
    assert_eq!(sorted(&back.attributes), sorted(&all.attributes));
}

#[test]
fn a_sequence_names_its_nodes_and_times_its_frames_by_their_numbers() {
    let dir = tempfile::tempdir().unwrap();
    // Out of order, with gaps: frame N is shown from N / 24 s (Blender's frame N).
    let frames: Vec<(i64, TriMesh)> = [7, 3, 4]
        .into_iter()
        .map(|n| (n, attributed().merged()))
        .collect();
    let path = dir.path().join("seq.glb");
    write_sequence_gltf(&path, &frames, 24.0, &MeshWriteOptions::default()).unwrap();
    let (doc, buffers, _) = gltf::import(&path).unwrap();
    let names: Vec<&str> = doc.nodes().filter_map(|n| n.name()).collect();
    assert_eq!(names, ["frame_3", "frame_4", "frame_7"]);
    let animation = doc.animations().next().unwrap();
    let channel = animation.channels().next().unwrap();
    let times: Vec<f32> = channel
        .reader(|b| Some(&buffers[b.index()]))
        .read_inputs()
        .unwrap()
        .collect();
    assert_eq!(times, [3.0 / 24.0, 4.0 / 24.0, 7.0 / 24.0]);
    // A sequence starting below 0 is shifted to start at time 0 (glTF times are >= 0).
    let negative: Vec<(i64, TriMesh)> = [-2, 0]
        .into_iter()
        .map(|n| (n, attributed().merged()))
        .collect();
    write_sequence_gltf(&path, &negative, 24.0, &MeshWriteOptions::default()).unwrap();
    let (doc, buffers, _) = gltf::import(&path).unwrap();
    let times: Vec<f32> = doc
        .animations()
        .next()
        .unwrap()
        .channels()
        .next()
        .unwrap()
        .reader(|b| Some(&buffers[b.index()]))
        .read_inputs()
        .unwrap()
        .collect();
    assert_eq!(times, [0.0, 2.0 / 24.0]);
    // One file holds one frame per number.
    let twice = [(3, frames[0].1.clone()), (3, frames[1].1.clone())];
    let err = write_sequence_gltf(&path, &twice, 24.0, &MeshWriteOptions::default()).unwrap_err();
    assert!(matches!(err, Error::FramesExist { .. }), "{err}");
}

#[test]
fn bad_attributes_are_refused_with_their_names() {
    let dir = tempfile::tempdir().unwrap();
    // A wrong value count: refused before anything is written.
    let mut s = attributed();
    s.fluid.attributes[1].values.pop();
    for ext in ["glb", "ply", "vtk", "obj"] {
        let path = dir.path().join(format!("bad.{ext}"));
        let msg = write_surface(&path, &s, &MeshWriteOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("density") && msg.contains("bad."),
            "{ext}: {msg}"
        );
        assert!(!path.exists());
    }
    // Two attributes with one glTF name; an attribute named like a PLY coordinate.
    let mut s = attributed();
    s.fluid.attributes[1] = Attribute {
        name: "Velocity".into(),
        ..s.fluid.attributes[0].clone()
    };
    let msg = write_surface(&dir.path().join("c.glb"), &s, &MeshWriteOptions::default())
        .unwrap_err()
        .to_string();
    assert!(msg.contains("_VELOCITY"), "{msg}");
    let mut s = attributed();
    s.fluid.attributes[1].name = "x".into();
    let msg = write_surface(&dir.path().join("c.ply"), &s, &MeshWriteOptions::default())
        .unwrap_err()
        .to_string();
    assert!(msg.contains("\"x\""), "{msg}");
    // A VTK point array with fewer tuples than points.
    let p = dir.path().join("short.vtk");
    std::fs::write(&p, "# vtk DataFile Version 4.2\nt\nASCII\nDATASET POLYDATA\nPOINTS 3 float\n0 0 0 1 0 0 0 1 0\nPOLYGONS 1 4\n3 0 1 2\nPOINT_DATA 3\nFIELD FieldData 1\npressure 1 2 float\n1 2\n").unwrap();
    let msg = read_mesh(&p).unwrap_err().to_string();
    assert!(
        msg.contains("short.vtk") && msg.contains("pressure"),
        "{msg}"
    );
    // A glTF attribute accessor shorter than POSITION.
    let p = dir.path().join("short.glb");
    std::fs::write(&p, glb_with_short_attribute()).unwrap();
    let msg = read_mesh(&p).unwrap_err().to_string();
    assert!(
        msg.contains("short.glb") && msg.contains("_DENSITY"),
        "{msg}"
    );
}

/// A GLB of one triangle whose `_DENSITY` accessor holds 2 values for 3 vertices.
fn glb_with_short_attribute() -> Vec<u8> {
    let mut bin = Vec::new();
    for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 5.0, 6.0] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    let json = serde_json::json!({
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "_DENSITY": 1}}]}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
             "min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 0.0]},
            {"bufferView": 1, "componentType": 5126, "count": 2, "type": "SCALAR"}
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 8}
        ],
        "buffers": [{"byteLength": 44}]
    });
    let mut text = serde_json::to_vec(&json).unwrap();
    while text.len() % 4 != 0 {
        text.push(b' ');
    }
    let mut out = Vec::new();
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&((12 + 8 + text.len() + 8 + bin.len()) as u32).to_le_bytes());
    out.extend_from_slice(&(text.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&text);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    out
}

#[test]
fn a_ply_mesh_claiming_more_faces_than_bytes_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1000000000000000000\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
    b.extend_from_slice(&[0u8; 36]);
    b.push(3);
    for i in 0..3i32 {
        b.extend_from_slice(&i.to_le_bytes());
    }
    let path = dir.path().join("faces.ply");
    std::fs::write(&path, &b).unwrap();
    let e = read_mesh(&path).expect_err("10^18 faces").to_string();
    assert!(e.contains("faces.ply") && e.contains("\"face\""), "{e}");
    // The same file with its true count reads.
    let text = String::from_utf8_lossy(&b).replace("face 1000000000000000000", "face 1");
    let fixed = [
        &text.as_bytes()[..text.find("end_header\n").unwrap() + 11],
        &b[b.len() - 49..],
    ]
    .concat();
    std::fs::write(&path, fixed).unwrap();
    assert_eq!(read_mesh(&path).unwrap().triangles, vec![[0, 1, 2]]);
}

#[test]
fn mutated_mesh_files_are_read_or_rejected_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let s = Surface {
        fluid: icosphere(0, 1.0),
        spheres: SphereInstances {
            template: icosphere(0, 0.1),
            scales: Vec::new(),
            centers: vec![Vec3::new(3.0, 0.0, 0.0)],
            attributes: Vec::new(),
        },
    };
    let mut bases = Vec::new();
    for name in ["m.ply", "m.obj", "m.gltf", "m.glb", "m.vtk"] {
        let p = dir.path().join(name);
        write_surface(&p, &s, &MeshWriteOptions::default()).unwrap();
        bases.push((name, std::fs::read(&p).unwrap()));
    }
    let mut rng = Rng(0x2545_f491_4f6c_dd1d);
    for round in 0..2500 {
        let (name, base) = &bases[round % bases.len()];
        let huge = [
            "18446744073709551615",
            "4294967295",
            "999999999999",
            "1000000000000000000",
        ];
        let b = support::mutate(&mut rng, base, &huge, |_, _| {});
        let path = dir.path().join(name);
        std::fs::write(&path, &b).unwrap();
        if let Err(e) = support::without_panic(round, name, &b, || read_mesh(&path)) {
            assert!(e.to_string().contains(name), "{name}: {e}");
        }
    }
}

#[test]
fn a_gltf_whose_position_accessor_index_is_out_of_range_is_an_error() {
    // Found by the mutation test: the gltf crate's validation panicked on it.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.gltf");
    write_surface(&path, &surface(), &MeshWriteOptions::default()).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("\"POSITION\":0"), "{}", &text[..200]);
    std::fs::write(
        &path,
        text.replacen("\"POSITION\":0", "\"POSITION\":4294967295", 1),
    )
    .unwrap();
    let e = read_mesh(&path)
        .expect_err("out-of-range accessor")
        .to_string();
    assert!(
        e.contains("m.gltf") && e.contains("POSITION") && e.contains("does not exist"),
        "{e}"
    );
}

/// A one-triangle glTF built by hand: positions (accessor 0, view 0) and u16 indices
/// (accessor 1, view 1) in one embedded buffer; node 0 holds mesh 0.
fn tiny_gltf() -> serde_json::Value {
    let mut data = Vec::new();
    for v in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
        for c in v {
            data.extend_from_slice(&c.to_le_bytes());
        }
    }
    for i in [0u16, 1, 2, 0] {
        data.extend_from_slice(&i.to_le_bytes());
    }
    let uri = format!("data:application/octet-stream;base64,{}", base64(&data));
    serde_json::json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
             "min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 0.0]},
            {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 8}
        ],
        "buffers": [{"byteLength": data.len(), "uri": uri}]
    })
}

fn base64(bytes: &[u8]) -> String {
    const A: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in bytes.chunks(3) {
        let n = (c[0] as u32) << 16
            | (*c.get(1).unwrap_or(&0) as u32) << 8
            | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            if k <= c.len() {
                s.push(A[(n >> (18 - 6 * k)) as usize & 63] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

/// Reads `doc` written as `m.gltf`; returns the error's text, or "" when it reads.
fn gltf_error(doc: &serde_json::Value) -> String {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.gltf");
    std::fs::write(&path, serde_json::to_vec(doc).unwrap()).unwrap();
    match read_mesh(&path) {
        Ok(_) => String::new(),
        Err(e) => {
            let e = e.to_string();
            assert!(e.contains("m.gltf"), "{e}");
            e
        }
    }
}

#[test]
fn a_hand_built_gltf_reads() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.gltf");
    std::fs::write(&path, serde_json::to_vec(&tiny_gltf()).unwrap()).unwrap();
    let mesh = read_mesh(&path).unwrap();
    assert_eq!(mesh.positions.len(), 3);
    assert_eq!(mesh.triangles, vec![[0, 1, 2]]);
}

#[test]
fn a_gltf_node_that_is_its_own_child_is_an_error() {
    let mut doc = tiny_gltf();
    doc["nodes"][0]["children"] = serde_json::json!([0]);
    let e = gltf_error(&doc);
    assert!(e.contains("nodes[0]") && e.contains("its own child"), "{e}");
}

#[test]
fn a_gltf_node_cycle_is_an_error() {
    let mut doc = tiny_gltf();
    doc["nodes"] = serde_json::json!([{"mesh": 0, "children": [1]}, {"children": [0]}]);
    let e = gltf_error(&doc);
    assert!(e.contains("cycle"), "{e}");
}

#[test]
fn a_gltf_node_with_two_parents_is_an_error() {
    // A diamond chain would make the scene walk visit 2^n paths.
    let mut doc = tiny_gltf();
    let mut nodes = vec![serde_json::json!({"mesh": 0})];
    for i in 1..64 {
        nodes.push(serde_json::json!({"children": [i - 1]}));
        nodes.push(serde_json::json!({"children": [i - 1]}));
    }
    doc["nodes"] = serde_json::Value::Array(nodes);
    let e = gltf_error(&doc);
    assert!(e.contains("one parent"), "{e}");
}

#[test]
fn a_gltf_primitive_pointing_at_a_missing_accessor_is_an_error() {
    let mut doc = tiny_gltf();
    doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = serde_json::json!(7);
    let e = gltf_error(&doc);
    assert!(
        e.contains("POSITION") && e.contains("does not exist"),
        "{e}"
    );
    let mut doc = tiny_gltf();
    doc["meshes"][0]["primitives"][0]["indices"] = serde_json::json!(2);
    let e = gltf_error(&doc);
    assert!(e.contains("indices") && e.contains("out of range"), "{e}");
    let mut doc = tiny_gltf();
    doc["nodes"][0]["mesh"] = serde_json::json!(1);
    assert!(gltf_error(&doc).contains("nodes[0].mesh"));
    let mut doc = tiny_gltf();
    doc["accessors"][0]["bufferView"] = serde_json::json!(5);
    assert!(gltf_error(&doc).contains("accessors[0].bufferView"));
    let mut doc = tiny_gltf();
    doc["bufferViews"][1]["buffer"] = serde_json::json!(1);
    assert!(gltf_error(&doc).contains("bufferViews[1].buffer"));
}

#[test]
fn gltf_float_indices_are_an_error() {
    let mut doc = tiny_gltf();
    doc["accessors"][1] =
        serde_json::json!({"bufferView": 1, "componentType": 5126, "count": 2, "type": "SCALAR"});
    let e = gltf_error(&doc);
    assert!(
        e.contains("indices") && e.contains("not an unsigned integer"),
        "{e}"
    );
}

#[test]
fn a_gltf_accessor_past_its_buffer_is_an_error() {
    let mut doc = tiny_gltf();
    doc["accessors"][0]["count"] = serde_json::json!(1_000_000);
    let e = gltf_error(&doc);
    assert!(
        e.contains("accessors[0]") && e.contains("exceed buffer view 0"),
        "{e}"
    );
    let mut doc = tiny_gltf();
    doc["accessors"][0]["count"] = serde_json::json!(u64::MAX);
    assert!(gltf_error(&doc).contains("exceed buffer view 0"));
    let mut doc = tiny_gltf();
    doc["bufferViews"][1]["byteLength"] = serde_json::json!(80);
    let e = gltf_error(&doc);
    assert!(
        e.contains("bufferViews[1]") && e.contains("exceed buffer 0"),
        "{e}"
    );
    let mut doc = tiny_gltf();
    doc["buffers"][0]["uri"] = serde_json::json!("/dev/zero");
    assert!(gltf_error(&doc).contains("external file"));
}

#[test]
fn a_gltf_scene_that_would_walk_or_allocate_without_end_is_an_error() {
    // A chain of nodes all listed as roots: the walk would be quadratic.
    let mut doc = tiny_gltf();
    doc["nodes"] = serde_json::json!([{"mesh": 0, "children": [1]}, {"mesh": 0}]);
    doc["scenes"][0]["nodes"] = serde_json::json!([0, 1]);
    assert!(gltf_error(&doc).contains("is a child of node 0"));
    let mut doc = tiny_gltf();
    doc["scenes"][0]["nodes"] = serde_json::json!([0, 0]);
    assert!(gltf_error(&doc).contains("listed twice"));
    // A zero-filled accessor (no bufferView) of 10^12 elements.
    let mut doc = tiny_gltf();
    doc["accessors"][0] = serde_json::json!(
        {"componentType": 5126, "count": 1_000_000_000_000u64, "type": "VEC3"});
    let e = gltf_error(&doc);
    assert!(
        e.contains("accessors[0]") && e.contains("without a bufferView"),
        "{e}"
    );
    // One mesh of 10^8 vertices instanced by 43 nodes: more vertices than a mesh can
    // index (found from the declared lengths, before any buffer is decoded).
    let mut doc = tiny_gltf();
    doc["buffers"][0]["byteLength"] = serde_json::json!(1_200_000_000u64);
    doc["bufferViews"][0]["byteLength"] = serde_json::json!(1_200_000_000u64);
    doc["accessors"][0]["count"] = serde_json::json!(100_000_000u64);
    doc["nodes"] = serde_json::json!(vec![serde_json::json!({"mesh": 0}); 43]);
    doc["scenes"][0]["nodes"] = serde_json::json!((0..43).collect::<Vec<_>>());
    let e = gltf_error(&doc);
    assert!(e.contains("instantiates 4300000000 vertices"), "{e}");
}

#[test]
fn a_gltf_index_past_its_primitive_is_an_error() {
    // Found by fuzzing (mesh_gltf): the second primitive's index 2^32 − 1, offset by the
    // first primitive's 3 vertices, overflowed (a panic with overflow checks; without,
    // it wrapped to vertex 2 and the file read as a mesh it does not hold).
    let mut bin = Vec::new();
    for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    for i in [0u32, 1, 2, 0, 1, u32::MAX] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let json = serde_json::json!({
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [
            {"attributes": {"POSITION": 0}, "indices": 1},
            {"attributes": {"POSITION": 0}, "indices": 2}
        ]}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
             "min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 0.0]},
            {"bufferView": 1, "componentType": 5125, "count": 3, "type": "SCALAR"},
            {"bufferView": 2, "componentType": 5125, "count": 3, "type": "SCALAR"}
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 12},
            {"buffer": 0, "byteOffset": 48, "byteLength": 12}
        ],
        "buffers": [{"byteLength": 60}]
    });
    let mut glb = glb_of(&json, &bin);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("index.glb");
    std::fs::write(&path, &glb).unwrap();
    let e = read_mesh(&path)
        .expect_err("index past the primitive")
        .to_string();
    assert!(
        e.contains("index.glb") && e.contains("4294967295") && e.contains("3 vertices"),
        "{e}"
    );
    // With an index in range both primitives read.
    let at = glb.len() - 4;
    glb[at..].copy_from_slice(&2u32.to_le_bytes());
    std::fs::write(&path, &glb).unwrap();
    let mesh = read_mesh(&path).unwrap();
    assert_eq!(mesh.triangles, vec![[0, 1, 2], [3, 4, 5]]);
}

#[test]
fn a_vtk_mesh_point_count_whose_triple_overflows_is_an_error() {
    // Found by fuzzing (mesh_vtk): 3·n overflowed (a panic with overflow checks). Without
    // them it wrapped: this n made the reader take 10 values as the points and read a
    // 3-vertex mesh from a file claiming 1.2·10^19 points.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("count.vtk");
    let n: u64 = 12_297_829_382_473_034_414;
    assert_eq!(n.wrapping_mul(3), 10);
    std::fs::write(
        &path,
        format!(
            "# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\nPOINTS {n} float\n0 0 0 1 0 0 0 1 0 7\nPOLYGONS 1 4\n3 0 1 2\n"
        ),
    )
    .unwrap();
    let e = read_mesh(&path).expect_err("overflowing count").to_string();
    assert!(
        e.contains("count.vtk") && e.contains("point count") && e.contains("overflows"),
        "{e}"
    );
}

/// A GLB of `json` and the binary chunk `bin`.
fn glb_of(json: &serde_json::Value, bin: &[u8]) -> Vec<u8> {
    let mut text = serde_json::to_vec(json).unwrap();
    while text.len() % 4 != 0 {
        text.push(b' ');
    }
    let mut glb = Vec::new();
    glb.extend_from_slice(b"glTF");
    glb.extend_from_slice(&2u32.to_le_bytes());
    glb.extend_from_slice(&((12 + 8 + text.len() + 8 + bin.len()) as u32).to_le_bytes());
    glb.extend_from_slice(&(text.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"JSON");
    glb.extend_from_slice(&text);
    glb.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"BIN\0");
    glb.extend_from_slice(bin);
    glb
}

#[test]
fn gltf_accessors_of_the_wrong_type_or_layout_are_errors() {
    // Found by fuzzing (mesh_gltf): a NORMAL accessor of scalars tripped the gltf
    // crate's debug assertion (12-byte items expected, 4 found); in release builds it
    // read the scalars as vectors. A byte stride shorter than the element made its reader
    // index out of range, in any build. Both are checked before reading.
    let mut bin = Vec::new();
    for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    let document = |normal_type: &str, stride: Option<u32>| {
        let mut view = serde_json::json!({"buffer": 0, "byteOffset": 0, "byteLength": 36});
        if let Some(s) = stride {
            view["byteStride"] = s.into();
        }
        serde_json::json!({
            "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}}]}],
            "accessors": [
                {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                 "min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 0.0]},
                {"bufferView": 1, "componentType": 5126, "count": 3, "type": normal_type}
            ],
            "bufferViews": [view, {"buffer": 0, "byteOffset": 0, "byteLength": 36}],
            "buffers": [{"byteLength": 36}]
        })
    };
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("acc.glb");
    for (normal_type, stride, what) in [
        ("SCALAR", None, "accessor 1 (SCALAR"),
        (
            "VEC3",
            Some(4),
            "accessors[0]: buffer view 0 has byteStride 4",
        ),
    ] {
        std::fs::write(&path, glb_of(&document(normal_type, stride), &bin)).unwrap();
        let e = std::panic::catch_unwind(|| read_mesh(&path))
            .unwrap_or_else(|_| panic!("{what}: the reader panicked"))
            .expect_err(what)
            .to_string();
        assert!(e.contains("acc.glb") && e.contains(what), "{e}");
    }
    // The same document with VEC3 normals and no stride reads.
    std::fs::write(&path, glb_of(&document("VEC3", None), &bin)).unwrap();
    assert_eq!(read_mesh(&path).unwrap().positions.len(), 3);
}
