//! PLY, OBJ and legacy VTK mesh writers.
//!
//! A surface is written as a list of parts (the fluid, the merged isolated spheres) that
//! share one vertex numbering, so nothing is copied into one merged mesh first; binary
//! data goes out in chunks of [`CHUNK_BYTES`], so writing adds no more than that to the
//! memory peak.

use crate::mesh::TriMesh;
use std::io::{Result, Write};

/// Bytes encoded before each write.
const CHUNK_BYTES: usize = 1 << 20;

fn counts(parts: &[&TriMesh]) -> (usize, usize) {
    parts.iter().fold((0, 0), |(v, t), m| {
        (v + m.vertex_count(), t + m.triangle_count())
    })
}

/// Encodes `items` with `encode` into chunks and writes them.
fn write_chunked<T>(
    w: &mut impl Write,
    items: impl Iterator<Item = T>,
    mut encode: impl FnMut(&mut Vec<u8>, T),
) -> Result<()> {
    let mut buf = Vec::with_capacity(CHUNK_BYTES + 64);
    for item in items {
        encode(&mut buf, item);
        if buf.len() >= CHUNK_BYTES {
            w.write_all(&buf)?;
            buf.clear();
        }
    }
    w.write_all(&buf)
}

/// The triangles of all parts, with vertex indices offset to the shared numbering.
fn all_triangles<'a>(parts: &'a [&'a TriMesh]) -> impl Iterator<Item = [u32; 3]> + 'a {
    let mut base = 0u32;
    parts.iter().flat_map(move |m| {
        let b = base;
        base += m.vertex_count() as u32;
        m.triangles.iter().map(move |t| t.map(|i| i + b))
    })
}

pub(super) fn write_ply(w: &mut impl Write, parts: &[&TriMesh], normals: bool) -> Result<()> {
    let (nv, nt) = counts(parts);
    write!(
        w,
        "ply\nformat binary_little_endian 1.0\ncomment meniscus surface\nelement vertex {nv}\nproperty float x\nproperty float y\nproperty float z\n",
    )?;
    if normals {
        w.write_all(b"property float nx\nproperty float ny\nproperty float nz\n")?;
    }
    write!(
        w,
        "element face {nt}\nproperty list uchar uint vertex_indices\nend_header\n",
    )?;
    for m in parts {
        write_chunked(w, 0..m.vertex_count(), |buf, i| {
            for v in m.positions[i].to_array() {
                buf.extend_from_slice(&v.to_le_bytes());
            }
            if normals {
                for v in m.normals[i].to_array() {
                    buf.extend_from_slice(&v.to_le_bytes());
                }
            }
        })?;
    }
    write_chunked(w, all_triangles(parts), |buf, t| {
        buf.push(3);
        for i in t {
            buf.extend_from_slice(&i.to_le_bytes());
        }
    })
}

pub(super) fn write_obj(w: &mut impl Write, parts: &[&TriMesh], normals: bool) -> Result<()> {
    let (nv, nt) = counts(parts);
    writeln!(w, "# meniscus surface: {nv} vertices, {nt} triangles")?;
    for m in parts {
        for p in &m.positions {
            writeln!(w, "v {} {} {}", p.x, p.y, p.z)?;
        }
    }
    if normals {
        for m in parts {
            for n in &m.normals {
                writeln!(w, "vn {} {} {}", n.x, n.y, n.z)?;
            }
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

pub(super) fn write_vtk(w: &mut impl Write, parts: &[&TriMesh], normals: bool) -> Result<()> {
    let (nv, nt) = counts(parts);
    write!(w, "# vtk DataFile Version 4.2\nmeniscus surface\nBINARY\nDATASET POLYDATA\nPOINTS {nv} float\n")?;
    for m in parts {
        write_chunked(w, m.positions.iter(), |buf, p| {
            for v in p.to_array() {
                buf.extend_from_slice(&v.to_be_bytes());
            }
        })?;
    }
    write!(w, "\nPOLYGONS {nt} {}\n", 4 * nt)?;
    write_chunked(w, all_triangles(parts), |buf, t| {
        buf.extend_from_slice(&3i32.to_be_bytes());
        for i in t {
            buf.extend_from_slice(&(i as i32).to_be_bytes());
        }
    })?;
    w.write_all(b"\n")?;
    if normals {
        write!(w, "POINT_DATA {nv}\nNORMALS normals float\n")?;
        for m in parts {
            write_chunked(w, m.normals.iter(), |buf, n| {
                for v in n.to_array() {
                    buf.extend_from_slice(&v.to_be_bytes());
                }
            })?;
        }
        w.write_all(b"\n")?;
    }
    Ok(())
}
