//! VTK XML files, `.vtu` (UnstructuredGrid) and `.vtp` (PolyData), as ParaView, PySPH,
//! SPHinXsys and VTK's own `vtkXMLUnstructuredGridWriter` / `vtkXMLPolyDataWriter` write
//! them: every data mode (`ascii`, inline `binary`, `appended` raw or base64), zlib or LZ4
//! compressed blocks (`vtkZLibDataCompressor`, `vtkLZ4DataCompressor`), UInt32 or UInt64
//! block headers, either byte order, points and point data of any numeric type. The
//! points are the particles (cells are skipped), the point-data arrays their attributes.
//!
//! `scan.rs` finds the structure (one pass over the markup, stopping at the appended
//! data), `data.rs` decodes one array at a time from the file. A file of one piece
//! streams (the points, then each selected array); several pieces are read whole and
//! joined, their point data matched by name. `pvd.rs` reads ParaView's collection files
//! (`.pvd`), which list the files of a frame sequence.

mod data;
pub(crate) mod pvd;
mod scan;

use super::records::RecordSink;
use super::records::{non_finite, stream_ascii_records, truncated, AsciiRecords, CHUNK_RECORDS};
use super::{Attribute, ParticleCodec, Particles, StreamSink};
use crate::attributes::AttributeLayout;
use crate::error::{Error, Result};
use crate::io::atomic::write_atomically;
use glam::Vec3;
use scan::{Array, Layout, Location, Piece};
use std::io::Write;
use std::path::Path;

/// The VTK XML formats; `polydata` picks what the writer writes (the reader takes both).
pub(super) struct VtkXml {
    pub(super) polydata: bool,
}

impl ParticleCodec for VtkXml {
    fn read(&self, path: &Path) -> Result<Particles> {
        let layout = scan::scan(path)?;
        let mut all = Particles::default();
        for (p, piece) in layout.pieces.iter().enumerate() {
            let particles = read_piece(&layout, piece)?;
            join(&layout, &mut all, particles, p, piece)?;
        }
        Ok(all)
    }

    /// A file of one piece: its points, then the selected point-data arrays, each from
    /// where it is in the file (the structure is scanned first); the other arrays are
    /// decoded and dropped, so that the stream takes exactly the files the whole-file
    /// reader takes. `Ok(None)` for several pieces.
    fn stream(&self, path: &Path, sink: &mut dyn StreamSink) -> Result<Option<usize>> {
        let layout = scan::scan(path)?;
        let [piece] = layout.pieces.as_slice() else {
            return Ok(None);
        };
        let points = points_of(&layout, piece)?;
        let count = piece.count;
        layout.check(points, values(&layout, points, count)?)?;
        let declared: Vec<AttributeLayout> = piece
            .point_data
            .iter()
            .map(|a| AttributeLayout {
                name: a.name.clone(),
                components: a.components,
            })
            .collect();
        let chosen = sink.select(count, &declared)?;
        for a in &piece.point_data {
            layout.check(a, values(&layout, a, count)?)?;
        }
        // The arrays not streamed are decoded too (and dropped), as the whole-file reader
        // decodes them: a file the stream takes is one `read_particles` takes. First, so
        // that damage there fails the run before anything is spooled.
        for (k, a) in piece.point_data.iter().enumerate() {
            if !chosen.contains(&k) {
                stream_array(&layout, a, count, false, &mut |_, _| Ok(()))?;
            }
        }
        stream_array(&layout, points, count, true, &mut |p, _| {
            sink.records(p, &[])
        })?;
        for (j, &k) in chosen.iter().enumerate() {
            let a = &piece.point_data[k];
            stream_array(&layout, a, count, false, &mut |_, rows| sink.array(j, rows))?;
        }
        Ok(Some(count))
    }

    fn write(&self, path: &Path, particles: &Particles) -> Result<()> {
        write(path, particles, self.polydata)
    }
}

/// The points array of `piece` (three components).
fn points_of<'a>(layout: &Layout, piece: &'a Piece) -> Result<&'a Array> {
    let points = piece.points.as_ref().ok_or_else(|| {
        Error::parse(
            &layout.path,
            format!("<Piece> (line {})", piece.line),
            "no <Points> DataArray",
        )
    })?;
    if points.components != 3 {
        return Err(layout.error(
            points,
            format!("points of {} components, not 3", points.components),
        ));
    }
    Ok(points)
}

/// Values of `array` for `count` points.
fn values(layout: &Layout, array: &Array, count: usize) -> Result<usize> {
    count
        .checked_mul(array.components)
        .ok_or_else(|| layout.error(array, format!("{count} points overflow")))
}

/// The points and point data of one piece.
fn read_piece(layout: &Layout, piece: &Piece) -> Result<Particles> {
    let points = points_of(layout, piece)?;
    let count = piece.count;
    layout.check(points, values(layout, points, count)?)?;
    let mut positions = Vec::new();
    stream_array(layout, points, count, true, &mut |p, _| {
        positions.extend_from_slice(p);
        Ok(())
    })?;
    let mut attributes = Vec::with_capacity(piece.point_data.len());
    for a in &piece.point_data {
        layout.check(a, values(layout, a, count)?)?;
        let mut values = Vec::new();
        stream_array(layout, a, count, false, &mut |_, rows| {
            values.extend_from_slice(rows);
            Ok(())
        })?;
        attributes.push(Attribute {
            name: a.name.clone(),
            components: a.components,
            values,
        });
    }
    Ok(Particles {
        positions,
        attributes,
    })
}

/// Appends piece `p` to `all`: the first piece's arrays are the file's, and every later
/// piece must hold the same (by name and components).
fn join(
    layout: &Layout,
    all: &mut Particles,
    next: Particles,
    p: usize,
    piece: &Piece,
) -> Result<()> {
    if p == 0 {
        *all = next;
        return Ok(());
    }
    let Particles {
        positions,
        attributes,
    } = next;
    let names = |a: &[Attribute]| -> Vec<(String, usize)> {
        a.iter().map(|a| (a.name.clone(), a.components)).collect()
    };
    if names(&attributes) != names(&all.attributes) {
        return Err(Error::parse(
            &layout.path,
            format!("<Piece> {p} (line {})", piece.line),
            format!(
                "its point data {:?} differ from the first piece's {:?}",
                names(&attributes),
                names(&all.attributes)
            ),
        ));
    }
    all.positions.extend(positions);
    for (to, from) in all.attributes.iter_mut().zip(attributes) {
        to.values.extend(from.values);
    }
    Ok(())
}

/// Streams the values of `array` for `count` points to `sink` in chunks of at most
/// 65 536 points: positions (checked finite) when `position`, else payload rows of all
/// its components.
fn stream_array(
    layout: &Layout,
    array: &Array,
    count: usize,
    position: bool,
    sink: &mut RecordSink<'_>,
) -> Result<()> {
    let fields = array.components;
    let many = if position {
        "points"
    } else {
        "point data values"
    };
    if let Location::Ascii { .. } = array.location {
        let (mut text, line) = layout.text(array, values(layout, array, count)?)?;
        let all: Vec<usize> = (0..fields).collect();
        return stream_ascii_records(
            &layout.path,
            &mut text,
            AsciiRecords {
                line,
                count,
                fields,
                xyz: position.then_some([0, 1, 2]),
                payload: if position { &[] } else { &all },
                one: "particle",
                many,
            },
            sink,
        );
    }
    let mut r = layout.values(array, values(layout, array, count)?)?;
    let (scalar, size) = (array.scalar, array.scalar.size());
    let stride = size * fields;
    let big_endian = layout.big_endian;
    let value = |record: &[u8], k: usize| {
        scalar.decode(&record[size * k..size * (k + 1)], big_endian) as f32
    };
    let mut bytes = vec![0u8; CHUNK_RECORDS.min(count) * stride];
    let (mut positions, mut rows) = (Vec::new(), Vec::new());
    let mut first = 0;
    while first < count {
        let n = CHUNK_RECORDS.min(count - first);
        let at = |k: usize| format!("{}, particle {}", layout.location(array), first + k);
        r.read_exact(&mut bytes[..n * stride]).map_err(|e| {
            let message = if e.kind() == std::io::ErrorKind::UnexpectedEof {
                truncated(count, many)
            } else {
                e.to_string()
            };
            Error::parse(&layout.path, at(0), message)
        })?;
        positions.clear();
        rows.clear();
        for (k, record) in bytes[..n * stride].chunks_exact(stride).enumerate() {
            if position {
                let p = Vec3::new(value(record, 0), value(record, 1), value(record, 2));
                if !p.is_finite() {
                    return Err(non_finite(&layout.path, at(k), p));
                }
                positions.push(p);
            } else {
                rows.extend((0..fields).map(|c| value(record, c)));
            }
        }
        sink(&positions, &rows)?;
        first += n;
    }
    Ok(())
}

/// Writes a `.vtp` (PolyData, one vertex per point) or `.vtu` (UnstructuredGrid, one
/// VTK_VERTEX cell per point): little-endian, UInt64 headers, raw appended data, Float32
/// points and attributes.
fn write(path: &Path, particles: &Particles, polydata: bool) -> Result<()> {
    let n = particles.positions.len();
    let (kind, cells) = if polydata {
        ("PolyData", "Verts")
    } else {
        ("UnstructuredGrid", "Cells")
    };
    write_atomically(path, |w| {
        let mut offset = 0u64;
        let mut next = |bytes: u64| {
            let at = offset;
            offset += 8 + bytes;
            at
        };
        writeln!(w, "<?xml version=\"1.0\"?>")?;
        writeln!(w, "<VTKFile type=\"{kind}\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">")?;
        writeln!(w, "  <{kind}>")?;
        let counts = if polydata {
            format!("NumberOfVerts=\"{n}\"")
        } else {
            format!("NumberOfCells=\"{n}\"")
        };
        writeln!(w, "    <Piece NumberOfPoints=\"{n}\" {counts}>")?;
        writeln!(w, "      <PointData>")?;
        for a in &particles.attributes {
            let name = escape(&a.name);
            let at = next(4 * a.values.len() as u64);
            writeln!(w, "        <DataArray type=\"Float32\" Name=\"{name}\" NumberOfComponents=\"{}\" format=\"appended\" offset=\"{at}\"/>", a.components)?;
        }
        writeln!(w, "      </PointData>")?;
        let at = next(12 * n as u64);
        writeln!(w, "      <Points>\n        <DataArray type=\"Float32\" Name=\"Points\" NumberOfComponents=\"3\" format=\"appended\" offset=\"{at}\"/>\n      </Points>")?;
        writeln!(w, "      <{cells}>")?;
        for name in ["connectivity", "offsets"] {
            let at = next(8 * n as u64);
            writeln!(w, "        <DataArray type=\"Int64\" Name=\"{name}\" format=\"appended\" offset=\"{at}\"/>")?;
        }
        if !polydata {
            let at = next(n as u64);
            writeln!(w, "        <DataArray type=\"UInt8\" Name=\"types\" format=\"appended\" offset=\"{at}\"/>")?;
        }
        writeln!(w, "      </{cells}>\n    </Piece>\n  </{kind}>")?;
        write!(w, "  <AppendedData encoding=\"raw\">\n   _")?;
        for a in &particles.attributes {
            w.write_all(&(4 * a.values.len() as u64).to_le_bytes())?;
            for v in &a.values {
                w.write_all(&v.to_le_bytes())?;
            }
        }
        w.write_all(&(12 * n as u64).to_le_bytes())?;
        for p in &particles.positions {
            for v in p.to_array() {
                w.write_all(&v.to_le_bytes())?;
            }
        }
        for first in [0i64, 1] {
            w.write_all(&(8 * n as u64).to_le_bytes())?;
            for i in 0..n as i64 {
                w.write_all(&(i + first).to_le_bytes())?;
            }
        }
        if !polydata {
            w.write_all(&(n as u64).to_le_bytes())?;
            w.write_all(&vec![1u8; n])?;
        }
        writeln!(w, "\n  </AppendedData>\n</VTKFile>")?;
        Ok(())
    })
    .map(|_| ())
}

/// `name` for an XML attribute value.
fn escape(name: &str) -> String {
    name.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}
