//! Wavefront OBJ meshes.
//!
//! * Written: `v`, `vn`, `f a//a` (1-based); no attributes (the writer reports them as
//!   dropped).
//! * Read: `v`, `vn`, `f` with `v`, `v/t`, `v//n`, `v/t/n` and negative indices, polygons
//!   fan-triangulated; normals kept when every vertex has one.

use super::parts::{all_normals, all_positions, all_triangles, counts, Part};
use crate::error::{Error, Result};
use crate::mesh::TriMesh;
use glam::Vec3;
use std::io::Write;
use std::path::Path;

/// Reads an OBJ mesh held in memory.
pub(super) fn read(path: &Path, bytes: &[u8]) -> Result<TriMesh> {
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

/// Writes `parts` as OBJ text.
pub(super) fn write(w: &mut impl Write, parts: &[Part], normals: bool) -> std::io::Result<()> {
    let (nv, nt) = counts(parts);
    writeln!(w, "# meniscus surface: {nv} vertices, {nt} triangles")?;
    for p in all_positions(parts) {
        writeln!(w, "v {} {} {}", p.x, p.y, p.z)?;
    }
    if normals {
        for n in all_normals(parts) {
            writeln!(w, "vn {} {} {}", n.x, n.y, n.z)?;
        }
        for t in all_triangles(parts) {
            let [a, b, c] = t.map(|i| i + 1);
            writeln!(w, "f {a}//{a} {b}//{b} {c}//{c}")?;
        }
    } else {
        for t in all_triangles(parts) {
            let [a, b, c] = t.map(|i| i + 1);
            writeln!(w, "f {a} {b} {c}")?;
        }
    }
    Ok(())
}
