//! Mesh readers: PLY (ASCII, binary LE / BE, any scalar types, polygon faces
//! fan-triangulated), OBJ (`v`, `f` with `v`, `v/t`, `v//n`, `v/t/n` and negative indices,
//! polygons fan-triangulated) and glTF (`.glb`, `.gltf` with embedded buffers: every
//! triangle primitive of the default scene, node transforms applied).

use crate::error::{Error, Result};
use crate::io::ply_header;
use crate::io::text::Cursor;
use crate::mesh::TriMesh;
use glam::{Mat4, Vec3};
use std::path::Path;

/// Reads a triangle mesh; the format comes from the extension.
pub fn read_mesh(path: &Path) -> Result<TriMesh> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or_default()
        .to_ascii_lowercase();
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let mesh = match ext.as_str() {
        "ply" => read_ply(path, &bytes)?,
        "obj" => read_obj(path, &bytes)?,
        "glb" | "gltf" => read_gltf(path, &bytes)?,
        _ => {
            return Err(Error::UnsupportedFormat {
                path: path.to_path_buf(),
                message: "mesh input must be .ply, .obj, .glb or .gltf".into(),
            })
        }
    };
    let n = mesh.positions.len() as u32;
    if let Some(t) = mesh
        .triangles
        .iter()
        .position(|t| t.iter().any(|&i| i >= n))
    {
        return Err(Error::parse(
            path,
            format!("face {t}"),
            format!("vertex index out of range (the mesh has {n} vertices)"),
        ));
    }
    Ok(mesh)
}

fn read_ply(path: &Path, bytes: &[u8]) -> Result<TriMesh> {
    let mut c = Cursor::new(path, bytes);
    let header = ply_header::parse(&mut c)?;
    let binary = header.binary;
    let mut mesh = TriMesh::default();
    for element in &header.elements {
        match element.name.as_str() {
            "vertex" => {
                let (Some(x), Some(y), Some(z)) =
                    (element.find("x"), element.find("y"), element.find("z"))
                else {
                    return Err(c.error("vertex element without x, y, z"));
                };
                let normal = (element.find("nx"), element.find("ny"), element.find("nz"));
                let mut row = vec![0.0f32; element.properties.len()];
                for _ in 0..element.count {
                    for (slot, p) in row.iter_mut().zip(&element.properties) {
                        if p.list_count.is_some() {
                            return Err(
                                c.error("list properties in the vertex element are not supported")
                            );
                        }
                        *slot = c.value(p.scalar, binary)?;
                    }
                    mesh.positions.push(Vec3::new(row[x], row[y], row[z]));
                    if let (Some(a), Some(b), Some(cz)) = normal {
                        mesh.normals.push(Vec3::new(row[a], row[b], row[cz]));
                    }
                }
            }
            "face" => {
                for _ in 0..element.count {
                    for p in &element.properties {
                        let Some(count) = p.list_count else {
                            c.skip_values(1, p.scalar, binary)?;
                            continue;
                        };
                        let n = c.value(count, binary)?;
                        if !(0.0..=1e6).contains(&n) {
                            return Err(c.error(format!("bad list length {n}")));
                        }
                        if p.name == "vertex_indices" || p.name == "vertex_index" {
                            let items = c.indices(n as usize, p.scalar, binary)?;
                            for j in 1..items.len().saturating_sub(1) {
                                mesh.triangles.push([items[0], items[j], items[j + 1]]);
                            }
                        } else {
                            c.skip_values(n as usize, p.scalar, binary)?;
                        }
                    }
                }
            }
            _ => {
                for _ in 0..element.count {
                    ply_header::skip_row(&mut c, element, binary)?;
                }
            }
        }
    }
    Ok(mesh)
}

fn read_obj(path: &Path, bytes: &[u8]) -> Result<TriMesh> {
    let text = std::str::from_utf8(bytes)
        .map_err(|_| Error::parse(path, "file", "OBJ is not UTF-8 text"))?;
    let mut mesh = TriMesh::default();
    let mut normals: Vec<Vec3> = Vec::new();
    let mut normal_of: Vec<Option<u32>> = Vec::new();
    for (ln, line) in text.lines().enumerate() {
        let err = |m: String| Error::parse(path, format!("line {}", ln + 1), m);
        let mut w = line.split_whitespace();
        match w.next() {
            Some("v") | Some("vn") => {
                let kind = line.split_whitespace().next().unwrap_or_default();
                let v: Vec<f32> = w
                    .take(3)
                    .map(|t| t.parse().map_err(|_| err(format!("bad number {t:?}"))))
                    .collect::<Result<_>>()?;
                if v.len() != 3 {
                    return Err(err(format!("{kind} needs three numbers")));
                }
                if kind == "v" {
                    mesh.positions.push(Vec3::new(v[0], v[1], v[2]));
                    normal_of.push(None);
                } else {
                    normals.push(Vec3::new(v[0], v[1], v[2]));
                }
            }
            Some("f") => {
                let mut idx = Vec::new();
                for t in w {
                    let mut parts = t.split('/');
                    let resolve = |s: &str, n: usize| -> Result<u32> {
                        let i: i64 = s.parse().map_err(|_| err(format!("bad index {s:?}")))?;
                        let r = if i < 0 { n as i64 + i } else { i - 1 };
                        if r < 0 || r >= n as i64 {
                            return Err(err(format!("index {i} out of range")));
                        }
                        Ok(r as u32)
                    };
                    let v = resolve(parts.next().unwrap_or_default(), mesh.positions.len())?;
                    let _texture = parts.next();
                    if let Some(n) = parts.next().filter(|s| !s.is_empty()) {
                        normal_of[v as usize] = Some(resolve(n, normals.len())?);
                    }
                    idx.push(v);
                }
                if idx.len() < 3 {
                    return Err(err("a face needs three vertices".into()));
                }
                for j in 1..idx.len() - 1 {
                    mesh.triangles.push([idx[0], idx[j], idx[j + 1]]);
                }
            }
            _ => {}
        }
    }
    if !normals.is_empty() && normal_of.iter().all(|n| n.is_some()) {
        mesh.normals = normal_of
            .iter()
            .map(|n| normals[n.unwrap() as usize])
            .collect();
    }
    Ok(mesh)
}

fn read_gltf(path: &Path, bytes: &[u8]) -> Result<TriMesh> {
    let bad = |m: String| Error::parse(path, "glTF", m);
    let (doc, buffers, _) = gltf::import_slice(bytes).map_err(|e| bad(e.to_string()))?;
    let mut mesh = TriMesh::default();
    let mut all_normals = true;
    let scene = doc
        .default_scene()
        .or_else(|| doc.scenes().next())
        .ok_or_else(|| bad("no scene".into()))?;
    // Depth-first in document order: the stack holds nodes reversed.
    let mut stack: Vec<(gltf::Node, Mat4)> = scene.nodes().map(|n| (n, Mat4::IDENTITY)).collect();
    stack.reverse();
    while let Some((node, parent)) = stack.pop() {
        let transform = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if let Some(m) = node.mesh() {
            for prim in m.primitives() {
                if prim.mode() != gltf::mesh::Mode::Triangles {
                    continue;
                }
                let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
                let base = mesh.positions.len() as u32;
                let positions: Vec<Vec3> = reader
                    .read_positions()
                    .ok_or_else(|| bad("a primitive has no POSITION".into()))?
                    .map(|p| transform.transform_point3(Vec3::from(p)))
                    .collect();
                let n = positions.len() as u32;
                mesh.positions.extend(positions);
                match reader.read_normals() {
                    Some(ns) => mesh.normals.extend(ns.map(|v| {
                        transform
                            .transform_vector3(Vec3::from(v))
                            .normalize_or_zero()
                    })),
                    None => all_normals = false,
                }
                match reader.read_indices() {
                    Some(ix) => {
                        let ix: Vec<u32> = ix.into_u32().collect();
                        for t in ix.chunks_exact(3) {
                            mesh.triangles.push([t[0] + base, t[1] + base, t[2] + base]);
                        }
                    }
                    None => {
                        for i in (0..n / 3 * 3).step_by(3) {
                            mesh.triangles.push([base + i, base + i + 1, base + i + 2]);
                        }
                    }
                }
            }
        }
        let children: Vec<gltf::Node> = node.children().collect();
        for child in children.into_iter().rev() {
            stack.push((child, transform));
        }
    }
    if !all_normals {
        mesh.normals.clear();
    }
    Ok(mesh)
}
