//! The layout of a legacy VTK file, found without decoding a value: where its points and
//! each `POINT_DATA` array are, so that [`super::vtk::Vtk`] can stream them one after the
//! other (the arrays follow the points in the file, not beside them).

use super::records::{open_buffered, stream_ascii_records, stream_records};
use super::records::{AsciiRecords, RecordSink, Records};
use super::StreamSink;
use crate::attributes::AttributeLayout;
use crate::error::{Error, Result};
use crate::io::text::Scalar;
use crate::io::vtk_legacy::{self, Tokens};
use glam::Vec3;
use std::path::Path;

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
pub(super) struct Layout {
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
    /// ASCII token by token, each parsed as the whole-file reader parses a value
    /// (`Cursor::values`, which refuses the same tokens).
    fn skip_values(&mut self, count: usize, scalar: Scalar, binary: bool) -> Scan<()> {
        self.skip(count, scalar, binary, true)
    }

    /// [`Scanner::skip_values`]; `parse`: ASCII tokens must be numbers (cell lists are
    /// skipped unparsed, as the whole-file reader skips them).
    fn skip(&mut self, count: usize, scalar: Scalar, binary: bool, parse: bool) -> Scan<()> {
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
                match self.token()? {
                    None => {
                        return Err(self
                            .error("truncated: the file ends before the values do".into())
                            .into())
                    }
                    Some(t) if parse && t.parse::<f64>().is_err() => {
                        return Err(self.error(format!("expected a number, found {t:?}")).into())
                    }
                    Some(_) => {}
                }
            }
        }
        Ok(())
    }
}

impl Tokens for Scanner {
    type Error = ScanError;

    fn next_word(&mut self, _expected: &str) -> Scan<String> {
        self.word()
    }

    fn next_number<T: std::str::FromStr>(&mut self, _expected: &str) -> Scan<T> {
        self.number()
    }

    fn next_line(&mut self) -> Scan<String> {
        self.line()
    }

    fn is_eof(&mut self) -> Scan<bool> {
        Ok(self.peek()?.is_none())
    }

    fn block_start(&mut self, binary: bool) -> Scan<()> {
        if binary {
            self.finish_line()?;
        }
        Ok(())
    }

    fn skip_block(&mut self, count: usize, scalar: Scalar, binary: bool) -> Scan<()> {
        self.skip(count, scalar, binary, false)
    }

    fn fail(&self, _message: String) -> ScanError {
        ScanError::Unstreamable
    }

    fn not_vtk(&self, _first_line: &str) -> ScanError {
        ScanError::Unstreamable
    }
}

/// Finds where the points and the `POINT_DATA` arrays of a legacy VTK file are, following
/// the grammar of the whole-file reader but reading no value: binary blocks are seeked
/// over, ASCII ones skipped token by token. `Ok(None)` for what it does not follow (an
/// unknown section, `CELL_DATA` arrays, a count that disagrees, ...), which the whole-file
/// reader then reports on; a truncated block is an error. Memory: one buffer.
pub(super) fn scan(path: &Path) -> Result<Option<Layout>> {
    match scan_layout(path) {
        Ok(layout) => Ok(Some(layout)),
        Err(ScanError::Unstreamable) => Ok(None),
        Err(ScanError::Error(e)) => Err(e),
    }
}

fn scan_layout(path: &Path) -> Scan<Layout> {
    let r = open_buffered(path)?;
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
    let header = vtk_legacy::header(&mut s)?;
    let (new_cells, binary) = (header.new_cells, header.binary);
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
                let (n, scalar) = vtk_legacy::points(&mut s, "the point type")?;
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
                vtk_legacy::skip_cells(&mut s, new_cells, binary)?;
            }
            "CELL_TYPES" => {
                vtk_legacy::skip_cell_types(&mut s, binary)?;
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
            k if vtk_legacy::is_attribute(k) => {
                let (name, components, scalar) = vtk_legacy::attribute(&mut s, &keyword)?;
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
                let n = vtk_legacy::field(&mut s)?;
                for _ in 0..n {
                    let (name, components, tuples, scalar) =
                        vtk_legacy::field_array(&mut s, binary, "an array type", "type")?;
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
            "METADATA" => vtk_legacy::skip_metadata(&mut s)?,
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
    pub(super) fn count(&self) -> usize {
        self.count
    }

    /// Tells `sink` the count and the point attributes (in file order), then streams the
    /// points and each selected array, in file order, in chunks of at most 65 536 points.
    pub(super) fn stream(&self, path: &Path, sink: &mut dyn StreamSink) -> Result<()> {
        let declared: Vec<AttributeLayout> = self.arrays.iter().map(|(a, _)| a.clone()).collect();
        let chosen = sink.select(self.count, &declared)?;
        self.stream_points(path, &mut |chunk, _| sink.records(chunk, &[]))?;
        let mut in_file: Vec<usize> = (0..chosen.len()).collect();
        in_file.sort_unstable_by_key(|&j| chosen[j]);
        for j in in_file {
            self.stream_attribute(path, chosen[j], &mut |_, rows| sink.array(j, rows))?;
        }
        Ok(())
    }

    /// Streams the points to `sink` (positions, no payload) in chunks of at most 65 536.
    fn stream_points(&self, path: &Path, sink: &mut RecordSink<'_>) -> Result<()> {
        self.stream_block(path, self.points, 3, true, sink)
    }

    /// Streams the values of attribute `k` (of [`Layout::attributes`]) to `sink` as payload
    /// rows (no positions), in chunks of at most 65 536 points.
    fn stream_attribute(&self, path: &Path, k: usize, sink: &mut RecordSink<'_>) -> Result<()> {
        let (a, block) = &self.arrays[k];
        self.stream_block(path, *block, a.components, false, sink)
    }

    fn stream_block(
        &self,
        path: &Path,
        block: Block,
        fields: usize,
        position: bool,
        sink: &mut RecordSink<'_>,
    ) -> Result<()> {
        use std::io::Seek;
        let mut r = open_buffered(path)?;
        r.seek(std::io::SeekFrom::Start(block.offset))
            .map_err(|e| Error::io(path, e))?;
        let (one, many) = if position {
            ("particle", "points")
        } else {
            ("particle", "point data values")
        };
        let all: Vec<usize> = (0..fields).collect();
        if !self.binary {
            return stream_ascii_records(
                path,
                &mut r,
                AsciiRecords {
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
        stream_records(
            path,
            &mut r,
            Records {
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
