//! Legacy VTK (`# vtk DataFile Version x.y`): ASCII or BINARY (big-endian), any dataset
//! whose points come in a `POINTS n type` section. Cell sections are skipped;
//! `POINT_DATA` SCALARS, VECTORS, NORMALS and FIELD arrays become attributes.
//!
//! Streamed two ways: positions alone when the points come first (one pass that stops
//! after them), or with attributes after `vtk_scan.rs` has found where every array is.

use super::records::{open_buffered, stream_ascii_records, stream_records};
use super::records::{AsciiRecords, Records};
use super::vtk_scan;
use super::{read_bytes, Attribute, ParticleCodec, Particles, StreamSink};
use crate::error::{Error, Result};
use crate::io::atomic::write_atomically;
use crate::io::text::Cursor;
use crate::io::vtk_legacy;
use glam::Vec3;
use std::io::{BufRead, Write};
use std::path::Path;

/// The legacy VTK format.
pub(super) struct Vtk;

impl ParticleCodec for Vtk {
    fn read(&self, path: &Path) -> Result<Particles> {
        read(path, &read_bytes(path)?)
    }

    /// Without attributes wanted: the positions of a file whose first data section is
    /// `POINTS n float|double` (what SPlisHSPlasH and DualSPHysics write); the rest of the
    /// file is not read. With attributes: the points and the `POINT_DATA` arrays, when a
    /// scan of the sections finds them (one more pass over the file, no value decoded).
    /// `Ok(None)` for any other layout.
    fn stream(&self, path: &Path, sink: &mut dyn StreamSink) -> Result<Option<usize>> {
        if !sink.wants_attributes() {
            return stream_points_first(path, sink);
        }
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

/// Where the points of a file whose first data section is `POINTS` start.
struct PointsFirst {
    /// Byte offset just past the `POINTS` line.
    offset: u64,
    /// Lines up to and including the `POINTS` line.
    lines: usize,
    count: usize,
    /// `double` points, else `float`.
    double: bool,
    /// BINARY, else ASCII.
    binary: bool,
}

/// Reads the header lines from `r` up to the `POINTS` line; `None` when the file is not
/// laid out that way (another section first, another point type, a line over 4 KiB).
fn points_first(path: &Path, r: &mut impl BufRead) -> Result<Option<PointsFirst>> {
    let mut offset = 0u64;
    let mut line = Vec::new();
    let mut next_line = |r: &mut dyn BufRead, offset: &mut u64| -> Result<Option<String>> {
        line.clear();
        let n = r
            .read_until(b'\n', &mut line)
            .map_err(|e| Error::io(path, e))?;
        *offset += n as u64;
        if n == 0 || line.len() > 4096 {
            return Ok(None);
        }
        Ok(Some(String::from_utf8_lossy(&line).trim().to_string()))
    };
    let header_ok =
        matches!(next_line(r, &mut offset)?, Some(l) if l.starts_with("# vtk DataFile Version"));
    let _title = next_line(r, &mut offset)?;
    let encoding = next_line(r, &mut offset)?;
    let binary = matches!(&encoding, Some(l) if l.eq_ignore_ascii_case("BINARY"));
    let ascii = matches!(&encoding, Some(l) if l.eq_ignore_ascii_case("ASCII"));
    if !(header_ok && (binary || ascii)) {
        return Ok(None);
    }
    let mut lines = 3;
    let (count, double) = loop {
        let Some(l) = next_line(r, &mut offset)? else {
            return Ok(None);
        };
        lines += 1;
        let tokens: Vec<&str> = l.split_whitespace().collect();
        match tokens.as_slice() {
            [] => continue,
            [k, _] if k.eq_ignore_ascii_case("DATASET") => continue,
            [k, n, ty] if k.eq_ignore_ascii_case("POINTS") => {
                let Ok(n) = n.parse::<usize>() else {
                    return Ok(None);
                };
                match ty.to_ascii_lowercase().as_str() {
                    "float" => break (n, false),
                    "double" => break (n, true),
                    _ => return Ok(None),
                }
            }
            _ => return Ok(None),
        }
    };
    Ok(Some(PointsFirst {
        offset,
        lines,
        count,
        double,
        binary,
    }))
}

/// Streams the positions of a file whose first data section is `POINTS n float|double`,
/// telling [`StreamSink::select`] the count (no attributes) before the first chunk; the
/// rest of the file is not read.
fn stream_points_first(path: &Path, sink: &mut dyn StreamSink) -> Result<Option<usize>> {
    let mut r = open_buffered(path)?;
    let Some(points) = points_first(path, &mut r)? else {
        return Ok(None);
    };
    let count = points.count;
    sink.select(count, &[])?;
    if !points.binary {
        stream_ascii_records(
            path,
            &mut r,
            AsciiRecords {
                line: points.lines + 1,
                count,
                fields: 3,
                xyz: Some([0, 1, 2]),
                payload: &[],
                one: "particle",
                many: "points",
            },
            &mut |chunk, _| sink.records(chunk, &[]),
        )?;
        return Ok(Some(count));
    }
    let double = points.double;
    let size = if double { 24 } else { 12 };
    let coordinate = |record: &[u8], i: usize| -> f32 {
        if double {
            f64::from_be_bytes(record[8 * i..8 * i + 8].try_into().expect("8 bytes")) as f32
        } else {
            f32::from_be_bytes(record[4 * i..4 * i + 4].try_into().expect("4 bytes"))
        }
    };
    stream_records(
        path,
        &mut r,
        Records {
            offset: points.offset,
            count,
            stride: size,
            one: "particle",
            many: "points",
        },
        &|record, _| {
            Some(Vec3::new(
                coordinate(record, 0),
                coordinate(record, 1),
                coordinate(record, 2),
            ))
        },
        &mut |chunk, _| sink.records(chunk, &[]),
    )?;
    Ok(Some(count))
}
