//! Legacy VTK meshes.
//!
//! * Written: binary POLYDATA with POLYGONS, NORMALS point data, and the shared
//!   attributes in the same `POINT_DATA` section: `SCALARS name float 1` (1 component),
//!   `VECTORS name float` (3), a `FIELD` array otherwise.
//! * Read: ASCII or BINARY, `POINTS` and `POLYGONS` (classic or 5.x offsets/connectivity
//!   layout), polygons fan-triangulated; point data `NORMALS` as normals, every other
//!   point array as an attribute; other cells and cell data are skipped.

use super::columns;
use super::parts::{
    all_normals, all_positions, all_triangles, counts, write_chunked, Part, Shared,
};
use crate::attributes::Attribute;
use crate::error::{Error, Result};
use crate::io::text::{Cursor, Scalar};
use crate::io::vtk_legacy;
use crate::mesh::TriMesh;
use glam::Vec3;
use std::io::Write;
use std::path::Path;

/// Reads a legacy VTK mesh held in memory: `POINTS`, `POLYGONS` (classic or 5.x
/// offsets/connectivity layout), point data (`NORMALS` as normals, every other array as an
/// attribute); other cells and cell data are skipped.
pub(super) fn read(path: &Path, bytes: &[u8]) -> Result<TriMesh> {
    let mut c = Cursor::new(path, bytes);
    let header = vtk_legacy::header(&mut c)?;
    let mut r = Reader {
        path,
        c,
        new_cells: header.new_cells,
        binary: header.binary.then_some(true),
        mesh: TriMesh::default(),
        npoints: 0,
        section: None,
    };
    while !r.c.at_end() {
        let keyword = r.c.token("a section keyword")?.to_ascii_uppercase();
        match keyword.as_str() {
            "DATASET" => r.dataset()?,
            "POINTS" => r.points()?,
            "VERTICES" | "LINES" | "POLYGONS" | "TRIANGLE_STRIPS" => r.cells(&keyword)?,
            "POINT_DATA" | "CELL_DATA" => r.data_section(&keyword)?,
            k if vtk_legacy::is_attribute(k) => r.attribute(&keyword)?,
            "FIELD" => r.field()?,
            "LOOKUP_TABLE" => r.lookup_table()?,
            "METADATA" => vtk_legacy::skip_metadata(&mut r.c)?,
            other => return Err(r.c.error(format!("unknown section {other:?}"))),
        }
    }
    let mut mesh = r.mesh;
    if mesh.normals.len() != mesh.positions.len() {
        mesh.normals.clear();
    }
    Ok(mesh)
}

/// The mesh reader between sections.
struct Reader<'a> {
    path: &'a Path,
    c: Cursor<'a>,
    /// Cells in the 5.x offsets/connectivity layout.
    new_cells: bool,
    /// `Some(true)` for BINARY (big-endian), `None` for ASCII.
    binary: Option<bool>,
    mesh: TriMesh,
    npoints: usize,
    /// The item count of the current data section and whether it is point data.
    section: Option<(usize, bool)>,
}

impl Reader<'_> {
    /// The value type of a data block, named `what` in errors.
    fn typed(&mut self, what: &str) -> Result<Scalar> {
        vtk_legacy::scalar(&mut self.c, what, what)
    }

    /// Steps past the end of a binary block's header line (ASCII values follow on it).
    fn block_start(&mut self) {
        if self.binary.is_some() {
            self.c.finish_line();
        }
    }

    /// `DATASET POLYDATA`: any other dataset is refused.
    fn dataset(&mut self) -> Result<()> {
        let kind = self.c.token("a dataset type")?;
        if !kind.eq_ignore_ascii_case("POLYDATA") {
            return Err(self
                .c
                .error(format!("a mesh must be a POLYDATA dataset, found {kind:?}")));
        }
        Ok(())
    }

    /// `POINTS n type`, then the positions.
    fn points(&mut self) -> Result<()> {
        let (n, scalar) = vtk_legacy::points(&mut self.c, "point type")?;
        self.npoints = n;
        self.block_start();
        // Checked: a wrapped product would read a few values as the points.
        let values = n
            .checked_mul(3)
            .ok_or_else(|| self.c.error(format!("the point count {n} overflows")))?;
        let v = self.c.values(values, scalar, self.binary)?;
        self.mesh.positions = v
            .chunks_exact(3)
            .map(|p| Vec3::new(p[0], p[1], p[2]))
            .collect();
        Ok(())
    }

    /// A cell section: `POLYGONS` fan-triangulated, other cells skipped, triangle strips
    /// refused.
    fn cells(&mut self, keyword: &str) -> Result<()> {
        let cells: usize = self.c.number("the cell count")?;
        let size: usize = self.c.number("the cell list size")?;
        if keyword == "TRIANGLE_STRIPS" {
            return Err(self
                .c
                .error("TRIANGLE_STRIPS are not supported; write POLYGONS"));
        }
        let polygons = keyword == "POLYGONS";
        let lists = if self.new_cells {
            self.offset_cells(cells, size, polygons)?
        } else {
            self.classic_cells(cells, size, polygons)?
        };
        for ids in lists {
            for j in 1..ids.len().saturating_sub(1) {
                self.mesh.triangles.push([ids[0], ids[j], ids[j + 1]]);
            }
        }
        Ok(())
    }

    /// The 5.x layout: `OFFSETS` then `CONNECTIVITY`, each with its index type; the
    /// polygons' vertex lists (none when `polygons` is false: skipped).
    fn offset_cells(&mut self, cells: usize, size: usize, polygons: bool) -> Result<Vec<Vec<u32>>> {
        let mut lists = Vec::new();
        let mut offsets = Vec::new();
        for part in ["OFFSETS", "CONNECTIVITY"] {
            let found = self.c.token(part)?;
            if !found.eq_ignore_ascii_case(part) {
                return Err(self.c.error(format!("expected {part}, found {found:?}")));
            }
            let scalar = self.typed("index type")?;
            self.block_start();
            let count = if part == "OFFSETS" { cells } else { size };
            if !polygons {
                self.c.skip_values(count, scalar, self.binary)?;
            } else if part == "OFFSETS" {
                offsets = self.c.indices(count, scalar, self.binary)?;
            } else {
                let ids = self.c.indices(count, scalar, self.binary)?;
                for w in offsets.windows(2) {
                    let (a, b) = (w[0] as usize, w[1] as usize);
                    if a > b || b > ids.len() {
                        return Err(self.c.error("polygon offsets out of order"));
                    }
                    lists.push(ids[a..b].to_vec());
                }
            }
        }
        Ok(lists)
    }

    /// The classic layout: `n id…` per cell, `size` values in all; the polygons' vertex
    /// lists (none when `polygons` is false: skipped).
    fn classic_cells(
        &mut self,
        cells: usize,
        size: usize,
        polygons: bool,
    ) -> Result<Vec<Vec<u32>>> {
        self.block_start();
        let mut lists = Vec::new();
        if polygons {
            let mut left = size;
            for _ in 0..cells {
                let n = self.c.indices(1, Scalar::I32, self.binary)?[0] as usize;
                if n >= left {
                    return Err(self.c.error("a polygon overruns the cell list size"));
                }
                lists.push(self.c.indices(n, Scalar::I32, self.binary)?);
                left -= n + 1;
            }
        } else {
            self.c.skip_values(size, Scalar::I32, self.binary)?;
        }
        Ok(lists)
    }

    /// `POINT_DATA n` or `CELL_DATA n`: the arrays that follow describe these items.
    fn data_section(&mut self, keyword: &str) -> Result<()> {
        let n: usize = self.c.number("the item count")?;
        let points = keyword == "POINT_DATA";
        if points && n != self.npoints {
            return Err(self.c.error(format!(
                "POINT_DATA has {n} values, POINTS has {}",
                self.npoints
            )));
        }
        self.section = Some((n, points));
        Ok(())
    }

    /// The current data section: item count and whether it is point data.
    fn section(&self, keyword: &str) -> Result<(usize, bool)> {
        self.section.ok_or_else(|| {
            self.c
                .error(format!("{keyword} outside POINT_DATA or CELL_DATA"))
        })
    }

    /// A `SCALARS`, `VECTORS`, `NORMALS`, ... array: the normals, an attribute, or
    /// skipped (cell data).
    fn attribute(&mut self, keyword: &str) -> Result<()> {
        let (items, points) = self.section(keyword)?;
        let name = self.c.token("an array name")?.to_string();
        let (components, scalar) = match keyword {
            "SCALARS" => {
                let scalar = self.typed("scalar type")?;
                (vtk_legacy::scalars_tail(&mut self.c)?, scalar)
            }
            "VECTORS" | "NORMALS" => (3, self.typed("vector type")?),
            "TENSORS" => (9, self.typed("tensor type")?),
            "TEXTURE_COORDINATES" => {
                let k: usize = self.c.number("a dimension")?;
                (k, self.typed("texture coordinate type")?)
            }
            _ => {
                let k: usize = self.c.number("a component count")?;
                (k, self.color_type())
            }
        };
        self.block_start();
        let count = items
            .checked_mul(components)
            .ok_or_else(|| self.c.error("value count overflows"))?;
        if !points {
            return self.c.skip_values(count, scalar, self.binary);
        }
        let mut values = self.c.values(count, scalar, self.binary)?;
        if keyword == "COLOR_SCALARS" && self.binary.is_some() {
            values.iter_mut().for_each(|v| *v /= 255.0);
        }
        if keyword == "NORMALS" {
            self.mesh.normals = values
                .chunks_exact(3)
                .map(|n| Vec3::new(n[0], n[1], n[2]))
                .collect();
        } else {
            self.mesh.attributes.push(Attribute {
                name,
                components,
                values,
            });
        }
        Ok(())
    }

    /// The value type of colour scalars and lookup tables: bytes in binary files, floats in
    /// ASCII ones.
    fn color_type(&self) -> Scalar {
        if self.binary.is_some() {
            Scalar::U8
        } else {
            Scalar::F32
        }
    }

    /// `FIELD name n` and its arrays: point-data arrays become attributes, cell-data ones
    /// are skipped.
    fn field(&mut self) -> Result<()> {
        let (items, points) = self.section("FIELD")?;
        let arrays = vtk_legacy::field(&mut self.c)?;
        for _ in 0..arrays {
            let (name, components, tuples, scalar) = vtk_legacy::field_array(
                &mut self.c,
                self.binary.is_some(),
                "array type",
                "array type",
            )?;
            let count = tuples
                .checked_mul(components)
                .ok_or_else(|| self.c.error("value count overflows"))?;
            if !points {
                self.c.skip_values(count, scalar, self.binary)?;
                continue;
            }
            if tuples != items || components == 0 {
                return Err(Error::parse(
                    self.path,
                    format!("attribute {name}"),
                    format!("{tuples} tuples of {components} components for {items} points"),
                ));
            }
            let values = self.c.values(count, scalar, self.binary)?;
            self.mesh.attributes.push(Attribute {
                name,
                components,
                values,
            });
        }
        Ok(())
    }

    /// `LOOKUP_TABLE name size`: skipped.
    fn lookup_table(&mut self) -> Result<()> {
        self.c.token("a lookup table name")?;
        let size: usize = self.c.number("a table size")?;
        let scalar = self.color_type();
        self.block_start();
        self.c.skip_values(size * 4, scalar, self.binary)
    }
}

/// Writes `parts` as binary legacy VTK POLYDATA.
pub(super) fn write(
    w: &mut impl Write,
    parts: &[Part],
    normals: bool,
    shared: &Shared,
) -> std::io::Result<()> {
    let (nv, nt) = counts(parts);
    write!(w, "# vtk DataFile Version 4.2\nmeniscus surface\nBINARY\nDATASET POLYDATA\nPOINTS {nv} float\n")?;
    write_chunked(w, all_positions(parts), |buf, p| {
        for v in p.to_array() {
            buf.extend_from_slice(&v.to_be_bytes());
        }
    })?;
    write!(w, "\nPOLYGONS {nt} {}\n", 4 * nt)?;
    write_chunked(w, all_triangles(parts), |buf, t| {
        buf.extend_from_slice(&3i32.to_be_bytes());
        for i in t {
            buf.extend_from_slice(&(i as i32).to_be_bytes());
        }
    })?;
    w.write_all(b"\n")?;
    // One POINT_DATA section holds every point array.
    if normals || !shared.list.is_empty() {
        writeln!(w, "POINT_DATA {nv}")?;
    }
    if normals {
        w.write_all(b"NORMALS normals float\n")?;
        write_chunked(w, all_normals(parts), |buf, n| {
            for v in n.to_array() {
                buf.extend_from_slice(&v.to_be_bytes());
            }
        })?;
        w.write_all(b"\n")?;
    }
    for (k, a) in shared.list.iter().enumerate() {
        let name = columns::word(&a.name);
        match a.components {
            1 => writeln!(w, "SCALARS {name} float 1\nLOOKUP_TABLE default")?,
            3 => writeln!(w, "VECTORS {name} float")?,
            c => writeln!(w, "FIELD FieldData 1\n{name} {c} {nv} float")?,
        }
        for p in 0..parts.len() {
            write_chunked(w, 0..parts[p].vertex_count(), |buf, i| {
                shared.encode(parts, p, i, Some(k), true, buf)
            })?;
        }
        w.write_all(b"\n")?;
    }
    Ok(())
}
