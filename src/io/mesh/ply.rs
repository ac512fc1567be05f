//! PLY meshes.
//!
//! * Written: binary little-endian, float `x y z` (+ `nx ny nz`), the shared attributes as
//!   float vertex properties (named in [`super::columns`]), `uchar`/`uint` face lists.
//! * Read: ASCII, binary LE / BE, any scalar types, polygon faces fan-triangulated;
//!   `float`/`double` vertex properties other than `x y z nx ny nz` come back as
//!   attributes (regrouped by [`super::columns::regroup`]).

use super::columns;
use super::parts::{counts, write_chunked_par, Part, Shared};
use crate::error::Result;
use crate::io::ply_header;
use crate::io::text::{Cursor, Scalar};
use crate::mesh::TriMesh;
use glam::Vec3;
use std::io::Write;
use std::path::Path;

/// Reads a PLY mesh held in memory.
pub(super) fn read(path: &Path, bytes: &[u8]) -> Result<TriMesh> {
    let mut c = Cursor::new(path, bytes);
    let header = ply_header::parse(&mut c)?;
    ply_header::check_counts(&c, &header)?;
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
                // Float properties other than position and normal: attribute columns.
                let extra: Vec<usize> = (0..element.properties.len())
                    .filter(|&k| {
                        let p = &element.properties[k];
                        p.list_count.is_none()
                            && matches!(p.scalar, Scalar::F32 | Scalar::F64)
                            && !["x", "y", "z", "nx", "ny", "nz"].contains(&p.name.as_str())
                    })
                    .collect();
                let mut columns: Vec<(String, Vec<f32>)> = extra
                    .iter()
                    .map(|&k| (element.properties[k].name.clone(), Vec::new()))
                    .collect();
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
                    for (column, &k) in columns.iter_mut().zip(&extra) {
                        column.1.push(row[k]);
                    }
                }
                mesh.attributes = columns::regroup(columns, true);
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

/// Writes `parts` as binary little-endian PLY.
pub(super) fn write(
    w: &mut impl Write,
    parts: &[Part],
    normals: bool,
    shared: &Shared,
) -> std::io::Result<()> {
    let (nv, nt) = counts(parts);
    write!(
        w,
        "ply\nformat binary_little_endian 1.0\ncomment meniscus surface\nelement vertex {nv}\nproperty float x\nproperty float y\nproperty float z\n",
    )?;
    if normals {
        w.write_all(b"property float nx\nproperty float ny\nproperty float nz\n")?;
    }
    for a in &shared.list {
        for name in columns::ply_names(a) {
            writeln!(w, "property float {name}")?;
        }
    }
    write!(
        w,
        "element face {nt}\nproperty list uchar uint vertex_indices\nend_header\n",
    )?;
    for (p, m) in parts.iter().enumerate() {
        write_chunked_par(w, m.vertex_count(), |buf, i| {
            for v in m.position(i).to_array() {
                buf.extend_from_slice(&v.to_le_bytes());
            }
            if normals {
                for v in m.normal(i).to_array() {
                    buf.extend_from_slice(&v.to_le_bytes());
                }
            }
            shared.encode(parts, p, i, None, false, buf);
        })?;
    }
    let mut base = 0u32;
    for m in parts {
        write_chunked_par(w, m.triangle_count(), |buf, j| {
            buf.push(3);
            for i in m.triangle(j) {
                buf.extend_from_slice(&(i + base).to_le_bytes());
            }
        })?;
        base += m.vertex_count() as u32;
    }
    Ok(())
}
