//! Legacy VTK (`# vtk DataFile Version x.y`): ASCII or BINARY (big-endian), any dataset
//! whose points come in a `POINTS n type` section. Cell sections are skipped;
//! `POINT_DATA` SCALARS, VECTORS, NORMALS and FIELD arrays become attributes.
//!
//! Streamed after `vtk_scan.rs` has found where the points and every array are (and
//! checked every value the whole-file reader would decode).

use super::vtk_scan;
use super::{read_bytes, Attribute, ParticleCodec, Particles, StreamSink};
use crate::error::{Error, Result};
use crate::io::atomic::write_atomically;
use crate::io::text::Cursor;
use crate::io::vtk_legacy;
use glam::Vec3;
use std::io::Write;
use std::path::Path;

/// The legacy VTK format.
pub(super) struct Vtk;

impl ParticleCodec for Vtk {
    fn read(&self, path: &Path) -> Result<Particles> {
        read(path, &read_bytes(path)?)
    }

    /// The points and the selected `POINT_DATA` arrays, when a scan of the sections finds
    /// them (one more pass over the file: binary blocks are seeked over, ASCII values
    /// parsed as the whole-file reader parses them), so that the stream takes exactly the
    /// files [`read_particles`](super::read_particles) takes. `Ok(None)` for any other
    /// layout.
    fn stream(&self, path: &Path, sink: &mut dyn StreamSink) -> Result<Option<usize>> {
        let Some(layout) = vtk_scan::scan(path)? else {
            return Ok(None);
        };
        layout.stream(path, sink)?;
        Ok(Some(layout.count()))
    }

    fn write(&self, path: &Path, particles: &Particles) -> Result<()> {
        write(path, particles)
    }
}

/// Reads a whole legacy VTK file held in memory.
fn read(path: &Path, bytes: &[u8]) -> Result<Particles> {
    let mut c = Cursor::new(path, bytes);
    let header = vtk_legacy::header(&mut c)?;
    let new_cells = header.new_cells;
    let mut r = Reader {
        c,
        binary: header.binary.then_some(true),
        positions: None,
        attributes: Vec::new(),
        point_data: false,
        npoints: 0,
    };
    while !r.c.at_end() {
        let keyword = r.c.token("a section keyword")?.to_ascii_uppercase();
        let binary = r.binary.is_some();
        match keyword.as_str() {
            "DATASET" => {
                r.c.token("a dataset type")?;
            }
            "POINTS" => r.points()?,
            "VERTICES" | "LINES" | "POLYGONS" | "TRIANGLE_STRIPS" | "CELLS" => {
                vtk_legacy::skip_cells(&mut r.c, new_cells, binary)?;
            }
            "CELL_TYPES" => {
                vtk_legacy::skip_cell_types(&mut r.c, binary)?;
            }
            "POINT_DATA" => {
                let n: usize = r.c.number("the point count")?;
                if n != r.npoints {
                    return Err(r.c.error(format!(
                        "POINT_DATA has {n} values, POINTS has {}",
                        r.npoints
                    )));
                }
                r.point_data = true;
            }
            "CELL_DATA" => {
                let _n: usize = r.c.number("the cell count")?;
                r.point_data = false;
            }
            k if vtk_legacy::is_attribute(k) => r.attribute(&keyword)?,
            "FIELD" => r.field()?,
            "METADATA" => vtk_legacy::skip_metadata(&mut r.c)?,
            other => return Err(r.c.error(format!("unknown section {other:?}"))),
        }
    }
    let positions = r
        .positions
        .ok_or_else(|| Error::parse(path, "header", "no POINTS section"))?;
    Ok(Particles {
        positions,
        attributes: r.attributes,
    })
}

/// The whole-file reader between sections.
struct Reader<'a> {
    c: Cursor<'a>,
    /// `Some(true)` for BINARY (big-endian), `None` for ASCII.
    binary: Option<bool>,
    positions: Option<Vec<Vec3>>,
    attributes: Vec<Attribute>,
    /// Whether the arrays that follow are point data.
    point_data: bool,
    npoints: usize,
}

impl Reader<'_> {
    /// `POINTS n type`, then the positions.
    fn points(&mut self) -> Result<()> {
        let (n, scalar) = vtk_legacy::points(&mut self.c, "the point type")?;
        if self.binary.is_some() {
            self.c.finish_line();
        }
        let values = n
            .checked_mul(3)
            .ok_or_else(|| self.c.error(format!("the point count {n} overflows")))?;
        let v = self.c.values(values, scalar, self.binary)?;
        self.npoints = n;
        self.positions = Some(
            v.chunks_exact(3)
                .map(|p| Vec3::new(p[0], p[1], p[2]))
                .collect(),
        );
        Ok(())
    }

    /// A `SCALARS`, `VECTORS`, `NORMALS`, ... array: an attribute of the points (cell data
    /// is refused).
    fn attribute(&mut self, keyword: &str) -> Result<()> {
        let (name, components, scalar) = vtk_legacy::attribute(&mut self.c, keyword)?;
        if self.binary.is_some() {
            self.c.finish_line();
        }
        if !self.point_data {
            return Err(self
                .c
                .error("CELL_DATA arrays are not supported in particle files"));
        }
        let count = self
            .npoints
            .checked_mul(components)
            .ok_or_else(|| self.c.error("value count overflows"))?;
        let values = self.c.values(count, scalar, self.binary)?;
        self.attributes.push(Attribute {
            name,
            components,
            values,
        });
        Ok(())
    }

    /// `FIELD name n` and its arrays: those of as many tuples as points, in point data,
    /// become attributes.
    fn field(&mut self) -> Result<()> {
        let arrays = vtk_legacy::field(&mut self.c)?;
        for _ in 0..arrays {
            let (name, components, tuples, scalar) = vtk_legacy::field_array(
                &mut self.c,
                self.binary.is_some(),
                "an array type",
                "type",
            )?;
            let count = components
                .checked_mul(tuples)
                .ok_or_else(|| self.c.error("value count overflows"))?;
            let values = self.c.values(count, scalar, self.binary)?;
            if self.point_data && tuples == self.npoints {
                self.attributes.push(Attribute {
                    name,
                    components,
                    values,
                });
            }
        }
        Ok(())
    }
}

/// Writes binary POLYDATA: `POINTS`, one `VERTICES` cell per point, and every attribute
/// as point data (`VECTORS` for 3 components, `SCALARS` otherwise).
fn write(path: &Path, particles: &Particles) -> Result<()> {
    let n = particles.positions.len();
    write_atomically(path, |w| {
        write!(w, "# vtk DataFile Version 4.2\nmeniscus particles\nBINARY\nDATASET POLYDATA\nPOINTS {n} float\n")?;
        for p in &particles.positions {
            for v in p.to_array() {
                w.write_all(&v.to_be_bytes())?;
            }
        }
        write!(w, "\nVERTICES {n} {}\n", 2 * n)?;
        for i in 0..n as i32 {
            w.write_all(&1i32.to_be_bytes())?;
            w.write_all(&i.to_be_bytes())?;
        }
        w.write_all(b"\n")?;
        if !particles.attributes.is_empty() {
            writeln!(w, "POINT_DATA {n}")?;
            for a in &particles.attributes {
                let name: String = a.name.chars().map(|ch| if ch.is_whitespace() { '_' } else { ch }).collect();
                if a.components == 3 {
                    writeln!(w, "VECTORS {name} float")?;
                } else {
                    writeln!(w, "SCALARS {name} float {}\nLOOKUP_TABLE default", a.components)?;
                }
                for v in &a.values {
                    w.write_all(&v.to_be_bytes())?;
                }
                w.write_all(b"\n")?;
            }
        }
        Ok(())
    })
    .map(|_| ())
}
