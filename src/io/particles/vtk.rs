//! Legacy VTK (`# vtk DataFile Version x.y`): ASCII or BINARY (big-endian), any dataset
//! whose points come in a `POINTS n type` section. Cell sections are skipped;
//! `POINT_DATA` SCALARS, VECTORS, NORMALS and FIELD arrays become attributes.

use super::{Attribute, Particles};
use crate::attributes::AttributeLayout;
use crate::error::{Error, Result};
use crate::io::atomic::write_atomically;
use crate::io::text::{Cursor, Scalar};
use glam::Vec3;
use std::io::Write;
use std::path::Path;

fn scalar_type(name: &str) -> Option<Scalar> {
    Some(match name.to_ascii_lowercase().as_str() {
        "bit" => return None,
        "char" => Scalar::I8,
        "unsigned_char" => Scalar::U8,
        "short" => Scalar::I16,
        "unsigned_short" => Scalar::U16,
        "int" | "vtkidtype" => Scalar::I32,
        "unsigned_int" => Scalar::U32,
        "long" | "vtktypeint64" => Scalar::I64,
        "unsigned_long" | "vtktypeuint64" => Scalar::U64,
        "float" => Scalar::F32,
        "double" => Scalar::F64,
        _ => return None,
    })
}

pub(super) fn read(path: &Path, bytes: &[u8]) -> Result<Particles> {
    let mut c = Cursor::new(path, bytes);
    let version = c.line()?;
    if !version.starts_with("# vtk DataFile Version") {
        return Err(Error::parse(
            path,
            "line 1",
            format!("not a legacy VTK file: first line is {version:?}"),
        ));
    }
    let new_cells = version
        .rsplit(' ')
        .next()
        .and_then(|v| v.parse::<f32>().ok())
        .is_some_and(|v| v >= 5.0);
    c.line()?; // title
    let encoding = c.line()?.trim().to_ascii_uppercase();
    let binary = match encoding.as_str() {
        "BINARY" => Some(true),
        "ASCII" => None,
        other => return Err(c.error(format!("expected ASCII or BINARY, found {other:?}"))),
    };
    let mut positions: Option<Vec<Vec3>> = None;
    let mut attributes = Vec::new();
    let mut point_data = false;
    let mut npoints = 0usize;
    while !c.at_end() {
        let keyword = c.token("a section keyword")?.to_ascii_uppercase();
        match keyword.as_str() {
            "DATASET" => {
                c.token("a dataset type")?;
            }
            "POINTS" => {
                let n: usize = c.number("the point count")?;
                let ty = c.token("the point type")?;
                let scalar = scalar_type(ty)
                    .ok_or_else(|| c.error(format!("unsupported point type {ty:?}")))?;
                if binary.is_some() {
                    c.finish_line();
                }
                let v = c.values(n * 3, scalar, binary)?;
                npoints = n;
                positions = Some(
                    v.chunks_exact(3)
                        .map(|p| Vec3::new(p[0], p[1], p[2]))
                        .collect(),
                );
            }
            "VERTICES" | "LINES" | "POLYGONS" | "TRIANGLE_STRIPS" | "CELLS" => {
                let _n: usize = c.number("the cell count")?;
                let size: usize = c.number("the cell list size")?;
                if new_cells {
                    for _ in 0..2 {
                        let part = c.token("OFFSETS or CONNECTIVITY")?;
                        let ty = c.token("an index type")?;
                        let scalar = scalar_type(ty)
                            .ok_or_else(|| c.error(format!("unsupported {part} type {ty:?}")))?;
                        if binary.is_some() {
                            c.finish_line();
                        }
                        let count = if part.eq_ignore_ascii_case("OFFSETS") {
                            _n
                        } else {
                            size
                        };
                        c.skip_values(count, scalar, binary)?;
                    }
                } else {
                    if binary.is_some() {
                        c.finish_line();
                    }
                    c.skip_values(size, Scalar::I32, binary)?;
                }
            }
            "CELL_TYPES" => {
                let n: usize = c.number("the cell count")?;
                if binary.is_some() {
                    c.finish_line();
                }
                c.skip_values(n, Scalar::I32, binary)?;
            }
            "POINT_DATA" => {
                let n: usize = c.number("the point count")?;
                if n != npoints {
                    return Err(c.error(format!("POINT_DATA has {n} values, POINTS has {npoints}")));
                }
                point_data = true;
            }
            "CELL_DATA" => {
                let _n: usize = c.number("the cell count")?;
                point_data = false;
            }
            "SCALARS"
            | "VECTORS"
            | "NORMALS"
            | "TENSORS"
            | "COLOR_SCALARS"
            | "TEXTURE_COORDINATES" => {
                let name = c.token("an attribute name")?.to_string();
                let (components, scalar) = match keyword.as_str() {
                    "SCALARS" => {
                        let ty = c.token("a scalar type")?;
                        let scalar = scalar_type(ty)
                            .ok_or_else(|| c.error(format!("unsupported type {ty:?}")))?;
                        let rest = c.line()?.trim().to_string();
                        let comps = if rest.is_empty() {
                            1
                        } else {
                            rest.parse()
                                .map_err(|_| c.error(format!("bad component count {rest:?}")))?
                        };
                        let table = c.token("LOOKUP_TABLE")?;
                        if !table.eq_ignore_ascii_case("LOOKUP_TABLE") {
                            return Err(c.error(format!(
                                "expected LOOKUP_TABLE after SCALARS, found {table:?}"
                            )));
                        }
                        c.token("a lookup table name")?;
                        (comps, scalar)
                    }
                    "VECTORS" | "NORMALS" => {
                        let ty = c.token("a vector type")?;
                        (
                            3,
                            scalar_type(ty)
                                .ok_or_else(|| c.error(format!("unsupported type {ty:?}")))?,
                        )
                    }
                    "TENSORS" => {
                        let ty = c.token("a tensor type")?;
                        (
                            9,
                            scalar_type(ty)
                                .ok_or_else(|| c.error(format!("unsupported type {ty:?}")))?,
                        )
                    }
                    "COLOR_SCALARS" => (c.number("a component count")?, Scalar::U8),
                    _ => {
                        let d: usize = c.number("a dimension")?;
                        let ty = c.token("a type")?;
                        (
                            d,
                            scalar_type(ty)
                                .ok_or_else(|| c.error(format!("unsupported type {ty:?}")))?,
                        )
                    }
                };
                if binary.is_some() {
                    c.finish_line();
                }
                if point_data {
                    let values = c.values(npoints * components, scalar, binary)?;
                    attributes.push(Attribute {
                        name,
                        components,
                        values,
                    });
                } else {
                    return Err(c.error("CELL_DATA arrays are not supported in particle files"));
                }
            }
            "FIELD" => {
                c.token("a field name")?;
                let arrays: usize = c.number("the array count")?;
                for _ in 0..arrays {
                    let name = c.token("an array name")?.to_string();
                    let components: usize = c.number("a component count")?;
                    let tuples: usize = c.number("a tuple count")?;
                    let ty = c.token("an array type")?;
                    let scalar = scalar_type(ty)
                        .ok_or_else(|| c.error(format!("unsupported type {ty:?}")))?;
                    if binary.is_some() {
                        c.finish_line();
                    }
                    let values = c.values(components * tuples, scalar, binary)?;
                    if point_data && tuples == npoints {
                        attributes.push(Attribute {
                            name,
                            components,
                            values,
                        });
                    }
                }
            }
            "METADATA" => {
                // Skip to the blank line that ends the metadata block.
                loop {
                    if c.pos >= c.bytes.len() || c.line()?.trim().is_empty() {
                        break;
                    }
                }
            }
            other => return Err(c.error(format!("unknown section {other:?}"))),
        }
    }
    let positions = positions.ok_or_else(|| Error::parse(path, "header", "no POINTS section"))?;
    Ok(Particles {
        positions,
        attributes,
    })
}

pub(super) fn write(path: &Path, particles: &Particles) -> Result<()> {
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

/// Streams the positions of a legacy VTK file (BINARY or ASCII) whose first data section
/// is `POINTS n float|double` (what SPlisHSPlasH and DualSPHysics write) from disk in
/// chunks of at most 65 536 particles; the rest of the file is not read. Returns
/// `Ok(None)` for any other layout (another section first, another point type), which the
/// whole-file reader handles and reports on. Memory: one chunk (and, for ASCII, one line),
/// whatever the file size.
pub fn stream_positions(
    path: &Path,
    positions: &mut dyn FnMut(&[Vec3]) -> Result<()>,
) -> Result<Option<usize>> {
    use std::io::BufRead;
    let mut r = super::open_buffered(path)?;
    let mut offset = 0u64;
    let mut line = Vec::new();
    let mut next_line =
        |r: &mut std::io::BufReader<std::fs::File>, offset: &mut u64| -> Result<Option<String>> {
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
    let header_ok = matches!(next_line(&mut r, &mut offset)?, Some(l) if l.starts_with("# vtk DataFile Version"));
    let _title = next_line(&mut r, &mut offset)?;
    let encoding = next_line(&mut r, &mut offset)?;
    let binary = matches!(&encoding, Some(l) if l.eq_ignore_ascii_case("BINARY"));
    let ascii = matches!(&encoding, Some(l) if l.eq_ignore_ascii_case("ASCII"));
    if !(header_ok && (binary || ascii)) {
        return Ok(None);
    }
    let mut lines_read = 3;
    let (count, double) = loop {
        let Some(l) = next_line(&mut r, &mut offset)? else {
            return Ok(None);
        };
        lines_read += 1;
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
    if ascii {
        super::stream_ascii_records(
            path,
            &mut r,
            super::AsciiRecords {
                line: lines_read + 1,
                count,
                fields: 3,
                xyz: Some([0, 1, 2]),
                payload: &[],
                one: "particle",
                many: "points",
            },
            &mut |chunk, _| positions(chunk),
        )?;
        return Ok(Some(count));
    }
    let size = if double { 24 } else { 12 };
    let coordinate = |record: &[u8], i: usize| -> f32 {
        if double {
            f64::from_be_bytes(record[8 * i..8 * i + 8].try_into().expect("8 bytes")) as f32
        } else {
            f32::from_be_bytes(record[4 * i..4 * i + 4].try_into().expect("4 bytes"))
        }
    };
    super::stream_records(
        path,
        &mut r,
        super::Records {
            offset,
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
        &mut |chunk, _| positions(chunk),
    )?;
    Ok(Some(count))
}

/// Where one data block of a legacy VTK file starts: byte offset (binary: its first byte;
/// ASCII: just after its header's last token), 1-based line there, value type.
#[derive(Clone, Copy, Debug)]
struct Block {
    offset: u64,
    line: usize,
    scalar: Scalar,
}

/// The layout of a legacy VTK file found by [`scan`]: where its points are and where each
/// `POINT_DATA` array is, without reading any value.
pub(crate) struct Layout {
    /// BINARY (big-endian), else ASCII.
    binary: bool,
    count: usize,
    points: Block,
    /// The point attributes in file order, named as the whole-file reader names them.
    arrays: Vec<(AttributeLayout, Block)>,
}

/// A token reader over a file for [`scan`]: tracks the byte offset and line number, skips
/// blocks of values without decoding them. Tokens longer than 4 KiB end the scan.
struct Scanner {
    path: std::path::PathBuf,
    r: std::io::BufReader<std::fs::File>,
    len: u64,
    pos: u64,
    line: usize,
}

/// A layout [`scan`] does not follow (the whole-file reader takes over and reports).
struct Unstreamable;

/// The scan's outcome: an error, or a layout it does not follow.
enum ScanError {
    Error(Error),
    Unstreamable,
}

impl From<Error> for ScanError {
    fn from(e: Error) -> Self {
        ScanError::Error(e)
    }
}

impl From<Unstreamable> for ScanError {
    fn from(_: Unstreamable) -> Self {
        ScanError::Unstreamable
    }
}

type Scan<T> = std::result::Result<T, ScanError>;

impl Scanner {
    fn peek(&mut self) -> Scan<Option<u8>> {
        use std::io::BufRead;
        let buf = self.r.fill_buf().map_err(|e| Error::io(&self.path, e))?;
        Ok(buf.first().copied())
    }

    fn bump(&mut self, b: u8) {
        use std::io::BufRead;
        self.r.consume(1);
        self.pos += 1;
        if b == b'\n' {
            self.line += 1;
        }
    }

    fn skip_whitespace(&mut self) -> Scan<()> {
        while let Some(b) = self.peek()? {
            if !b.is_ascii_whitespace() {
                break;
            }
            self.bump(b);
        }
        Ok(())
    }

    /// The next whitespace-separated token; `None` at the end of the file.
    fn token(&mut self) -> Scan<Option<String>> {
        self.skip_whitespace()?;
        let mut t = Vec::new();
        while let Some(b) = self.peek()? {
            if b.is_ascii_whitespace() {
                break;
            }
            if t.len() == 4096 {
                return Err(Unstreamable.into());
            }
            t.push(b);
            self.bump(b);
        }
        if t.is_empty() {
            return Ok(None);
        }
        Ok(Some(String::from_utf8(t).map_err(|_| Unstreamable)?))
    }

    /// The next token, which must exist.
    fn word(&mut self) -> Scan<String> {
        Ok(self.token()?.ok_or(Unstreamable)?)
    }

    fn number<T: std::str::FromStr>(&mut self) -> Scan<T> {
        Ok(self.word()?.parse().map_err(|_| Unstreamable)?)
    }

    /// The rest of the current line, consuming its newline (as [`Cursor::line`]).
    fn line(&mut self) -> Scan<String> {
        let mut t = Vec::new();
        while let Some(b) = self.peek()? {
            self.bump(b);
            if b == b'\n' {
                break;
            }
            if t.len() == 4096 {
                return Err(Unstreamable.into());
            }
            t.push(b);
        }
        let t = String::from_utf8(t).map_err(|_| Unstreamable)?;
        Ok(t.trim_end_matches('\r').to_string())
    }

    /// Skips to just past the next newline (as [`Cursor::finish_line`]).
    fn finish_line(&mut self) -> Scan<()> {
        while let Some(b) = self.peek()? {
            self.bump(b);
            if b == b'\n' {
                break;
            }
        }
        Ok(())
    }

    /// Where the scanner is, as a data block of `scalar`.
    fn block(&self, scalar: Scalar) -> Block {
        Block {
            offset: self.pos,
            line: self.line,
            scalar,
        }
    }

    fn error(&self, message: String) -> Error {
        Error::parse(
            &self.path,
            format!("line {} (byte offset {})", self.line, self.pos),
            message,
        )
    }

    /// Skips `count` values of `scalar`: binary by seeking (the file must hold them),
    /// ASCII token by token.
    fn skip_values(&mut self, count: usize, scalar: Scalar, binary: bool) -> Scan<()> {
        if binary {
            let need = (count as u64)
                .checked_mul(scalar.size() as u64)
                .ok_or_else(|| self.error("value count overflows".into()))?;
            if self.len - self.pos < need {
                return Err(self
                    .error(format!(
                        "truncated: {count} values of {} bytes need {need} bytes, {} left",
                        scalar.size(),
                        self.len - self.pos
                    ))
                    .into());
            }
            self.r
                .seek_relative(need as i64)
                .map_err(|e| Error::io(&self.path, e))?;
            self.pos += need;
        } else {
            for _ in 0..count {
                if self.token()?.is_none() {
                    return Err(self
                        .error("unexpected end of file, expected a number".into())
                        .into());
                }
            }
        }
        Ok(())
    }
}

/// Finds where the points and the `POINT_DATA` arrays of a legacy VTK file are, following
/// the grammar of the whole-file reader but reading no value: binary blocks are seeked
/// over, ASCII ones skipped token by token. `Ok(None)` for what it does not follow (an
/// unknown section, `CELL_DATA` arrays, a count that disagrees, ...), which the whole-file
/// reader then reports on; a truncated block is an error. Memory: one buffer.
pub(crate) fn scan(path: &Path) -> Result<Option<Layout>> {
    match scan_layout(path) {
        Ok(layout) => Ok(Some(layout)),
        Err(ScanError::Unstreamable) => Ok(None),
        Err(ScanError::Error(e)) => Err(e),
    }
}

fn scan_layout(path: &Path) -> Scan<Layout> {
    let r = super::open_buffered(path)?;
    let len = r
        .get_ref()
        .metadata()
        .map_err(|e| Error::io(path, e))?
        .len();
    let mut s = Scanner {
        path: path.to_path_buf(),
        r,
        len,
        pos: 0,
        line: 1,
    };
    let version = s.line()?;
    if !version.starts_with("# vtk DataFile Version") {
        return Err(Unstreamable.into());
    }
    let new_cells = version
        .rsplit(' ')
        .next()
        .and_then(|v| v.parse::<f32>().ok())
        .is_some_and(|v| v >= 5.0);
    s.line()?; // title
    let binary = match s.line()?.trim().to_ascii_uppercase().as_str() {
        "BINARY" => true,
        "ASCII" => false,
        _ => return Err(Unstreamable.into()),
    };
    let scalar_of = |ty: &str| scalar_type(ty).ok_or(Unstreamable);
    let mut points: Option<(usize, Block)> = None;
    let mut arrays = Vec::new();
    let mut point_data = false;
    while let Some(keyword) = s.token()? {
        let keyword = keyword.to_ascii_uppercase();
        match keyword.as_str() {
            "DATASET" => {
                s.word()?;
            }
            "POINTS" => {
                let n: usize = s.number()?;
                let scalar = scalar_of(&s.word()?)?;
                if points.is_some() {
                    return Err(Unstreamable.into());
                }
                if binary {
                    s.finish_line()?;
                }
                let block = s.block(scalar);
                let values = n.checked_mul(3).ok_or(Unstreamable)?;
                s.skip_values(values, scalar, binary)?;
                points = Some((n, block));
            }
            "VERTICES" | "LINES" | "POLYGONS" | "TRIANGLE_STRIPS" | "CELLS" => {
                let n: usize = s.number()?;
                let size: usize = s.number()?;
                if new_cells {
                    for _ in 0..2 {
                        let part = s.word()?;
                        let scalar = scalar_of(&s.word()?)?;
                        if binary {
                            s.finish_line()?;
                        }
                        let count = if part.eq_ignore_ascii_case("OFFSETS") {
                            n
                        } else {
                            size
                        };
                        s.skip_values(count, scalar, binary)?;
                    }
                } else {
                    if binary {
                        s.finish_line()?;
                    }
                    s.skip_values(size, Scalar::I32, binary)?;
                }
            }
            "CELL_TYPES" => {
                let n: usize = s.number()?;
                if binary {
                    s.finish_line()?;
                }
                s.skip_values(n, Scalar::I32, binary)?;
            }
            "POINT_DATA" => {
                let n: usize = s.number()?;
                if points.is_none_or(|(count, _)| count != n) {
                    return Err(Unstreamable.into());
                }
                point_data = true;
            }
            "CELL_DATA" => {
                let _n: usize = s.number()?;
                point_data = false;
            }
            "SCALARS"
            | "VECTORS"
            | "NORMALS"
            | "TENSORS"
            | "COLOR_SCALARS"
            | "TEXTURE_COORDINATES" => {
                let name = s.word()?;
                let (components, scalar) = match keyword.as_str() {
                    "SCALARS" => {
                        let scalar = scalar_of(&s.word()?)?;
                        let rest = s.line()?.trim().to_string();
                        let comps = if rest.is_empty() {
                            1
                        } else {
                            rest.parse().map_err(|_| Unstreamable)?
                        };
                        if !s.word()?.eq_ignore_ascii_case("LOOKUP_TABLE") {
                            return Err(Unstreamable.into());
                        }
                        s.word()?;
                        (comps, scalar)
                    }
                    "VECTORS" | "NORMALS" => (3, scalar_of(&s.word()?)?),
                    "TENSORS" => (9, scalar_of(&s.word()?)?),
                    "COLOR_SCALARS" => (s.number()?, Scalar::U8),
                    _ => {
                        let d: usize = s.number()?;
                        (d, scalar_of(&s.word()?)?)
                    }
                };
                if !point_data || components == 0 {
                    return Err(Unstreamable.into());
                }
                if binary {
                    s.finish_line()?;
                }
                let count = points.map_or(0, |(n, _)| n);
                let block = s.block(scalar);
                let values = count.checked_mul(components).ok_or(Unstreamable)?;
                s.skip_values(values, scalar, binary)?;
                arrays.push((AttributeLayout { name, components }, block));
            }
            "FIELD" => {
                s.word()?;
                let n: usize = s.number()?;
                for _ in 0..n {
                    let name = s.word()?;
                    let components: usize = s.number()?;
                    let tuples: usize = s.number()?;
                    let scalar = scalar_of(&s.word()?)?;
                    if binary {
                        s.finish_line()?;
                    }
                    let block = s.block(scalar);
                    let values = components.checked_mul(tuples).ok_or(Unstreamable)?;
                    s.skip_values(values, scalar, binary)?;
                    if point_data && points.is_some_and(|(count, _)| count == tuples) {
                        if components == 0 {
                            return Err(Unstreamable.into());
                        }
                        arrays.push((AttributeLayout { name, components }, block));
                    }
                }
            }
            "METADATA" => loop {
                if s.peek()?.is_none() || s.line()?.trim().is_empty() {
                    break;
                }
            },
            _ => return Err(Unstreamable.into()),
        }
    }
    let (count, points) = points.ok_or(Unstreamable)?;
    Ok(Layout {
        binary,
        count,
        points,
        arrays,
    })
}

impl Layout {
    /// Number of points.
    pub(crate) fn count(&self) -> usize {
        self.count
    }

    /// The point attributes, in file order.
    pub(crate) fn attributes(&self) -> Vec<AttributeLayout> {
        self.arrays.iter().map(|(a, _)| a.clone()).collect()
    }

    /// Streams the points to `sink` (positions, no payload) in chunks of at most 65 536.
    pub(crate) fn stream_points(
        &self,
        path: &Path,
        sink: &mut super::RecordSink<'_>,
    ) -> Result<()> {
        self.stream_block(path, self.points, 3, true, sink)
    }

    /// Streams the values of attribute `k` (of [`Layout::attributes`]) to `sink` as payload
    /// rows (no positions), in chunks of at most 65 536 points.
    pub(crate) fn stream_attribute(
        &self,
        path: &Path,
        k: usize,
        sink: &mut super::RecordSink<'_>,
    ) -> Result<()> {
        let (a, block) = &self.arrays[k];
        self.stream_block(path, *block, a.components, false, sink)
    }

    fn stream_block(
        &self,
        path: &Path,
        block: Block,
        fields: usize,
        position: bool,
        sink: &mut super::RecordSink<'_>,
    ) -> Result<()> {
        use std::io::Seek;
        let mut r = super::open_buffered(path)?;
        r.seek(std::io::SeekFrom::Start(block.offset))
            .map_err(|e| Error::io(path, e))?;
        let (one, many) = if position {
            ("particle", "points")
        } else {
            ("particle", "point data values")
        };
        let all: Vec<usize> = (0..fields).collect();
        if !self.binary {
            return super::stream_ascii_records(
                path,
                &mut r,
                super::AsciiRecords {
                    line: block.line,
                    count: self.count,
                    fields,
                    xyz: position.then_some([0, 1, 2]),
                    payload: if position { &[] } else { &all },
                    one,
                    many,
                },
                sink,
            );
        }
        let size = block.scalar.size();
        let scalar = block.scalar;
        let value =
            |record: &[u8], k: usize| scalar.decode(&record[size * k..size * (k + 1)], true) as f32;
        super::stream_records(
            path,
            &mut r,
            super::Records {
                offset: block.offset,
                count: self.count,
                stride: size * fields,
                one,
                many,
            },
            &|record, payload| {
                if position {
                    Some(Vec3::new(
                        value(record, 0),
                        value(record, 1),
                        value(record, 2),
                    ))
                } else {
                    payload.extend((0..fields).map(|k| value(record, k)));
                    None
                }
            },
            sink,
        )
    }
}
