//! PLY, OBJ and legacy VTK mesh writers.

use crate::mesh::TriMesh;
use std::io::{Result, Write};

pub(super) fn write_ply(w: &mut impl Write, mesh: &TriMesh, normals: bool) -> Result<()> {
    write!(
        w,
        "ply\nformat binary_little_endian 1.0\ncomment meniscus surface\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\n",
        mesh.vertex_count()
    )?;
    if normals {
        w.write_all(b"property float nx\nproperty float ny\nproperty float nz\n")?;
    }
    write!(
        w,
        "element face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        mesh.triangle_count()
    )?;
    let mut buf = Vec::with_capacity(mesh.vertex_count() * 24);
    for (i, p) in mesh.positions.iter().enumerate() {
        for v in p.to_array() {
            buf.extend_from_slice(&v.to_le_bytes());
        }
        if normals {
            for v in mesh.normals[i].to_array() {
                buf.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    w.write_all(&buf)?;
    buf.clear();
    for t in &mesh.triangles {
        buf.push(3);
        for i in t {
            buf.extend_from_slice(&i.to_le_bytes());
        }
    }
    w.write_all(&buf)
}

pub(super) fn write_obj(w: &mut impl Write, mesh: &TriMesh, normals: bool) -> Result<()> {
    writeln!(
        w,
        "# meniscus surface: {} vertices, {} triangles",
        mesh.vertex_count(),
        mesh.triangle_count()
    )?;
    for p in &mesh.positions {
        writeln!(w, "v {} {} {}", p.x, p.y, p.z)?;
    }
    if normals {
        for n in &mesh.normals {
            writeln!(w, "vn {} {} {}", n.x, n.y, n.z)?;
        }
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|i| i + 1);
            writeln!(w, "f {a}//{a} {b}//{b} {c}//{c}")?;
        }
    } else {
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|i| i + 1);
            writeln!(w, "f {a} {b} {c}")?;
        }
    }
    Ok(())
}

pub(super) fn write_vtk(w: &mut impl Write, mesh: &TriMesh, normals: bool) -> Result<()> {
    let (nv, nt) = (mesh.vertex_count(), mesh.triangle_count());
    write!(w, "# vtk DataFile Version 4.2\nmeniscus surface\nBINARY\nDATASET POLYDATA\nPOINTS {nv} float\n")?;
    let mut buf = Vec::with_capacity(nv * 12);
    for p in &mesh.positions {
        for v in p.to_array() {
            buf.extend_from_slice(&v.to_be_bytes());
        }
    }
    w.write_all(&buf)?;
    write!(w, "\nPOLYGONS {nt} {}\n", 4 * nt)?;
    buf.clear();
    for t in &mesh.triangles {
        buf.extend_from_slice(&3i32.to_be_bytes());
        for i in t {
            buf.extend_from_slice(&(*i as i32).to_be_bytes());
        }
    }
    w.write_all(&buf)?;
    w.write_all(b"\n")?;
    if normals {
        write!(w, "POINT_DATA {nv}\nNORMALS normals float\n")?;
        buf.clear();
        for n in &mesh.normals {
            for v in n.to_array() {
                buf.extend_from_slice(&v.to_be_bytes());
            }
        }
        w.write_all(&buf)?;
        w.write_all(b"\n")?;
    }
    Ok(())
}
