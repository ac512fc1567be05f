//! Mesh readers: PLY (ASCII, binary LE / BE, any scalar types, polygon faces
//! fan-triangulated), OBJ (`v`, `f` with `v`, `v/t`, `v//n`, `v/t/n` and negative indices,
//! polygons fan-triangulated) and glTF (`.glb`, `.gltf` with embedded buffers: every
//! triangle primitive of the default scene, node transforms applied).

use crate::error::{Error, Result};
use crate::io::text::{Cursor, Scalar};
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

fn ply_scalar(name: &str) -> Option<Scalar> {
    Some(match name {
        "char" | "int8" => Scalar::I8,
        "uchar" | "uint8" => Scalar::U8,
        "short" | "int16" => Scalar::I16,
        "ushort" | "uint16" => Scalar::U16,
        "int" | "int32" => Scalar::I32,
        "uint" | "uint32" => Scalar::U32,
        "float" | "float32" => Scalar::F32,
        "double" | "float64" => Scalar::F64,
        _ => return None,
    })
}

fn read_ply(path: &Path, bytes: &[u8]) -> Result<TriMesh> {
    let mut c = Cursor::new(path, bytes);
    if c.line()?.trim() != "ply" {
        return Err(Error::parse(path, "line 1", "not a PLY file"));
    }
    let mut binary = None;
    // (element name, count, properties: (name, scalar, list count type))
    type Property = (String, Scalar, Option<Scalar>);
    let mut elements: Vec<(String, usize, Vec<Property>)> = Vec::new();
    loop {
        if c.pos >= bytes.len() {
            return Err(c.error("header has no end_header"));
        }
        let line = c.line()?;
        let w: Vec<&str> = line.split_whitespace().collect();
        match w.as_slice() {
            ["format", f, _] => {
                binary = Some(match *f {
                    "ascii" => None,
                    "binary_little_endian" => Some(false),
                    "binary_big_endian" => Some(true),
                    _ => return Err(c.error(format!("unknown format {f:?}"))),
                })
            }
            ["element", name, n] => elements.push((
                name.to_string(),
                n.parse().map_err(|_| c.error("bad element count"))?,
                Vec::new(),
            )),
            ["property", "list", ct, it, name] => {
                let (Some(ct), Some(it)) = (ply_scalar(ct), ply_scalar(it)) else {
                    return Err(c.error(format!("bad list property {line:?}")));
                };
                elements
                    .last_mut()
                    .ok_or_else(|| c.error("property before element"))?
                    .2
                    .push((name.to_string(), it, Some(ct)));
            }
            ["property", ty, name] => {
                let ty = ply_scalar(ty).ok_or_else(|| c.error(format!("unknown type {ty:?}")))?;
                elements
                    .last_mut()
                    .ok_or_else(|| c.error("property before element"))?
                    .2
                    .push((name.to_string(), ty, None));
            }
            ["end_header"] => break,
            ["comment", ..] | ["obj_info", ..] | [] => {}
            _ => return Err(c.error(format!("unexpected header line {line:?}"))),
        }
    }
    let binary = binary.ok_or_else(|| c.error("no format line"))?;
    let mut mesh = TriMesh::default();
    for (name, count, props) in &elements {
        let find = |n: &str| props.iter().position(|p| p.0 == n);
        let xyz = (find("x"), find("y"), find("z"));
        let nxyz = (find("nx"), find("ny"), find("nz"));
        for _ in 0..*count {
            let mut row = [0.0f32; 6];
            for (k, (pname, scalar, list)) in props.iter().enumerate() {
                match list {
                    None => {
                        let v = c.value(*scalar, binary)?;
                        if name == "vertex" {
                            for (slot, idx) in [xyz.0, xyz.1, xyz.2, nxyz.0, nxyz.1, nxyz.2]
                                .iter()
                                .enumerate()
                            {
                                if *idx == Some(k) {
                                    row[slot] = v;
                                }
                            }
                        }
                    }
                    Some(ct) => {
                        let n = c.value(*ct, binary)?;
                        if !(0.0..=1e6).contains(&n) {
                            return Err(c.error(format!("bad list length {n}")));
                        }
                        let items = c.values(n as usize, *scalar, binary)?;
                        if name == "face" && (pname == "vertex_indices" || pname == "vertex_index")
                        {
                            if items.iter().any(|&i| i < 0.0) {
                                return Err(c.error("negative vertex index"));
                            }
                            for j in 1..items.len().saturating_sub(1) {
                                mesh.triangles.push([
                                    items[0] as u32,
                                    items[j] as u32,
                                    items[j + 1] as u32,
                                ]);
                            }
                        }
                    }
                }
            }
            if name == "vertex" {
                if xyz.0.is_none() || xyz.1.is_none() || xyz.2.is_none() {
                    return Err(c.error("vertex element without x, y, z"));
                }
                mesh.positions.push(Vec3::new(row[0], row[1], row[2]));
                if nxyz.0.is_some() {
                    mesh.normals.push(Vec3::new(row[3], row[4], row[5]));
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
