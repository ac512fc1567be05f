//! The structure of a VTK XML file (`.vtu`, `.vtp`), found without decoding a value: the
//! file's byte order, header size and compressor, and per piece the point count and where
//! the points and each point-data array are (inline text, or an offset into the appended
//! data). One pass over the markup; inline data is skipped a buffer at a time, and the
//! scan stops at the start of the appended data.

use crate::error::{Error, Result};
use crate::io::text::Scalar;
use std::io::BufRead;
use std::path::{Path, PathBuf};

/// Longest tag the scan reads (markup, not data).
const MAX_TAG: usize = 1 << 16;
/// Most `DataArray` elements kept, over all pieces.
const MAX_ARRAYS: usize = 1 << 16;
/// Deepest element nesting followed.
const MAX_DEPTH: usize = 64;

/// How the blocks of binary data are compressed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Compressor {
    None,
    Zlib,
    Lz4,
}

/// Where an array's values are.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Location {
    /// `format="ascii"`: whitespace-separated numbers in the element's text, which starts
    /// at byte `offset` on line `line` and is `len` bytes long.
    Ascii { offset: u64, line: usize, len: u64 },
    /// `format="binary"`: base64 text (header, then data) of `len` bytes from `offset`.
    Binary { offset: u64, len: u64 },
    /// `format="appended"`: `offset` bytes into the appended data.
    Appended { offset: u64 },
}

/// One `DataArray` of the points or the point data.
#[derive(Clone, Debug)]
pub(super) struct Array {
    pub(super) name: String,
    pub(super) scalar: Scalar,
    pub(super) components: usize,
    pub(super) location: Location,
    /// Line of the `DataArray` tag, for errors.
    pub(super) line: usize,
}

/// One `<Piece>`: its point count, its points and its point data (in file order).
#[derive(Clone, Debug, Default)]
pub(super) struct Piece {
    pub(super) count: usize,
    pub(super) points: Option<Array>,
    pub(super) point_data: Vec<Array>,
    pub(super) line: usize,
}

/// The appended data block: where its first byte (after the `_`) is, and whether it is
/// base64 text or raw bytes.
#[derive(Clone, Copy, Debug)]
pub(super) struct Appended {
    pub(super) offset: u64,
    pub(super) base64: bool,
}

/// What [`scan`] found.
#[derive(Clone, Debug)]
pub(super) struct Layout {
    pub(super) path: PathBuf,
    pub(super) file_len: u64,
    pub(super) big_endian: bool,
    /// UInt64 block headers, else UInt32.
    pub(super) header64: bool,
    pub(super) compressor: Compressor,
    pub(super) pieces: Vec<Piece>,
    pub(super) appended: Option<Appended>,
}

/// A tag of the markup.
pub(super) enum Tag {
    Start {
        name: String,
        attributes: Vec<(String, String)>,
        empty: bool,
    },
    End(String),
    /// `<?xml ...?>`, a comment, a declaration.
    Other,
}

/// A start tag as [`Scanner::next_start`] gives it: line, name, attributes, empty.
pub(super) type StartTag = (usize, String, Vec<(String, String)>, bool);

/// A byte reader over the file that keeps the offset and line.
pub(super) struct Scanner {
    path: PathBuf,
    r: std::io::BufReader<std::fs::File>,
    pos: u64,
    line: usize,
}

impl Scanner {
    /// A scanner at the start of `path`; an empty file is [`Error::EmptyInput`].
    pub(super) fn open(path: &Path) -> Result<(Scanner, u64)> {
        let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
        let file_len = file.metadata().map_err(|e| Error::io(path, e))?.len();
        if file_len == 0 {
            return Err(Error::EmptyInput {
                path: path.to_path_buf(),
            });
        }
        let scanner = Scanner {
            path: path.to_path_buf(),
            r: std::io::BufReader::with_capacity(1 << 16, file),
            pos: 0,
            line: 1,
        };
        Ok((scanner, file_len))
    }

    /// True at the end of the file.
    pub(super) fn at_end(&mut self) -> Result<bool> {
        Ok(self.peek()?.is_none())
    }

    /// The next start tag (its line, name, attributes and whether it is empty), past text,
    /// comments and end tags, each of which must close the innermost element of `open`;
    /// `None` at the end of the file.
    pub(super) fn next_start(&mut self, open: &mut Vec<String>) -> Result<Option<StartTag>> {
        loop {
            self.skip_text()?;
            if self.at_end()? {
                return Ok(None);
            }
            let line = self.line;
            match self.tag()? {
                Tag::Other => {}
                Tag::End(name) => {
                    if open.pop().as_deref() != Some(name.as_str()) {
                        let name = shown(&name);
                        return Err(self.error(format!("</{name}> closes no open <{name}>")));
                    }
                }
                Tag::Start {
                    name,
                    attributes,
                    empty,
                } => return Ok(Some((line, name, attributes, empty))),
            }
        }
    }

    pub(super) fn error(&self, message: impl Into<String>) -> Error {
        Error::parse(
            &self.path,
            format!("line {} (byte offset {})", self.line, self.pos),
            message,
        )
    }

    fn peek(&mut self) -> Result<Option<u8>> {
        let buf = self.r.fill_buf().map_err(|e| Error::io(&self.path, e))?;
        Ok(buf.first().copied())
    }

    fn bump(&mut self) -> Result<Option<u8>> {
        let b = self.peek()?;
        if let Some(b) = b {
            self.r.consume(1);
            self.pos += 1;
            if b == b'\n' {
                self.line += 1;
            }
        }
        Ok(b)
    }

    /// Skips text up to the next `<` (or the end); returns its length.
    pub(super) fn skip_text(&mut self) -> Result<u64> {
        let mut len = 0u64;
        loop {
            let buf = self.r.fill_buf().map_err(|e| Error::io(&self.path, e))?;
            if buf.is_empty() {
                return Ok(len);
            }
            let (n, found) = match buf.iter().position(|&b| b == b'<') {
                Some(k) => (k, true),
                None => (buf.len(), false),
            };
            self.line += buf[..n].iter().filter(|&&b| b == b'\n').count();
            self.r.consume(n);
            self.pos += n as u64;
            len += n as u64;
            if found {
                return Ok(len);
            }
        }
    }

    /// Reads up to and including `end` (a tag's last bytes); `what` names it in errors.
    fn until(&mut self, end: &[u8], what: &str) -> Result<Vec<u8>> {
        let mut t = Vec::new();
        while !t.ends_with(end) {
            if t.len() > MAX_TAG {
                return Err(self.error(format!("{what} longer than {MAX_TAG} bytes")));
            }
            match self.bump()? {
                Some(b) => t.push(b),
                None => return Err(self.error(format!("the file ends inside {what}"))),
            }
        }
        Ok(t)
    }

    /// The tag at `<`.
    pub(super) fn tag(&mut self) -> Result<Tag> {
        let (line, pos) = (self.line, self.pos);
        let head = self.until(b"<", "a tag")?;
        debug_assert_eq!(head, b"<");
        match self.peek()? {
            Some(b'?') => self
                .until(b"?>", "a processing instruction")
                .map(|_| Tag::Other),
            Some(b'!') => {
                let start = self.until(b"!", "a declaration")?;
                debug_assert_eq!(start, b"!");
                if self.peek()? == Some(b'-') {
                    self.until(b"-->", "a comment").map(|_| Tag::Other)
                } else {
                    self.until(b">", "a declaration").map(|_| Tag::Other)
                }
            }
            _ => {
                let body = self.until(b">", "a tag")?;
                let text = String::from_utf8(body[..body.len() - 1].to_vec()).map_err(|_| {
                    Error::parse(
                        &self.path,
                        format!("line {line} (byte offset {pos})"),
                        "a tag that is not text",
                    )
                })?;
                parse_tag(&text).ok_or_else(|| {
                    Error::parse(
                        &self.path,
                        format!("line {line} (byte offset {pos})"),
                        format!("malformed tag <{}>", shown(&text)),
                    )
                })
            }
        }
    }
}

/// The first 60 characters of `text`.
/// [`shorten`]ed `text` with its control characters escaped (`\u{1b}`), for a message
/// that shows it unquoted: an input's terminal escapes never reach the terminal. (Inside
/// `{:?}` use [`shorten`]: Debug escapes them.)
pub(super) fn shown(text: &str) -> String {
    shorten(text)
        .chars()
        .map(|c| {
            if c.is_control() {
                c.escape_debug().to_string()
            } else {
                c.to_string()
            }
        })
        .collect()
}

pub(super) fn shorten(text: &str) -> String {
    let mut s: String = text.chars().take(60).collect();
    if s.len() < text.len() {
        s.push('…');
    }
    s
}

/// A start or end tag's text between `<` and `>`.
fn parse_tag(text: &str) -> Option<Tag> {
    if let Some(name) = text.strip_prefix('/') {
        return Some(Tag::End(name.trim().to_string()));
    }
    let (text, empty) = match text.strip_suffix('/') {
        Some(t) => (t, true),
        None => (text, false),
    };
    let text = text.trim_end();
    let name_end = text
        .find(|c: char| c.is_ascii_whitespace())
        .unwrap_or(text.len());
    let name = &text[..name_end];
    if name.is_empty() {
        return None;
    }
    let mut rest = &text[name_end..];
    let mut attributes = Vec::new();
    loop {
        rest = rest.trim_start();
        if rest.is_empty() {
            break;
        }
        let eq = rest.find('=')?;
        let key = rest[..eq].trim();
        let after = rest[eq + 1..].trim_start();
        let quote = after.chars().next().filter(|&c| c == '"' || c == '\'')?;
        let close = after[1..].find(quote)?;
        attributes.push((key.to_string(), unescape(&after[1..1 + close])));
        rest = &after[close + 2..];
    }
    Some(Tag::Start {
        name: name.to_string(),
        attributes,
        empty,
    })
}

/// An attribute value with XML's five entities replaced.
fn unescape(value: &str) -> String {
    if !value.contains('&') {
        return value.to_string();
    }
    value
        .replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&quot;", "\"")
        .replace("&apos;", "'")
        .replace("&amp;", "&")
}

pub(super) fn attribute<'a>(attributes: &'a [(String, String)], key: &str) -> Option<&'a str> {
    attributes
        .iter()
        .find(|(k, _)| k == key)
        .map(|(_, v)| v.as_str())
}

/// A VTK XML type name.
fn scalar_of(name: &str) -> Option<Scalar> {
    Some(match name {
        "Int8" | "Char" => Scalar::I8,
        "UInt8" | "UChar" => Scalar::U8,
        "Int16" => Scalar::I16,
        "UInt16" => Scalar::U16,
        "Int32" => Scalar::I32,
        "UInt32" => Scalar::U32,
        "Int64" => Scalar::I64,
        "UInt64" => Scalar::U64,
        "Float32" => Scalar::F32,
        "Float64" => Scalar::F64,
        _ => return None,
    })
}

/// Reads the structure of the VTK XML file `path` (see the module's documentation).
/// Errors name the file and the line: not a VTK XML file, a dataset type without
/// particle points, an unknown byte order, header type or compressor, malformed markup.
pub(super) fn scan(path: &Path) -> Result<Layout> {
    let (mut s, file_len) = Scanner::open(path)?;
    let mut layout = Layout {
        path: path.to_path_buf(),
        file_len,
        big_endian: false,
        header64: false,
        compressor: Compressor::None,
        pieces: Vec::new(),
        appended: None,
    };
    let mut stack: Vec<String> = Vec::new();
    let mut seen_file = false;
    let mut arrays = 0usize;
    while let Some((line, name, attributes, empty)) = s.next_start(&mut stack)? {
        let parent = stack.last().map(String::as_str);
        match (parent, name.as_str()) {
            (None, "VTKFile") => {
                seen_file = true;
                file_header(&s, &attributes, &mut layout)?;
            }
            (None, other) => {
                return Err(s.error(format!(
                    "not a VTK XML file: the first element is <{}>, not <VTKFile>",
                    shown(other)
                )))
            }
            (Some("UnstructuredGrid" | "PolyData"), "Piece") => {
                let count = attribute(&attributes, "NumberOfPoints")
                    .ok_or_else(|| s.error("<Piece> without NumberOfPoints"))?;
                let count = count.trim().parse().map_err(|_| {
                    s.error(format!("NumberOfPoints {count:?} is not a point count"))
                })?;
                layout.pieces.push(Piece {
                    count,
                    line,
                    ..Piece::default()
                });
            }
            (Some("Points" | "PointData"), "DataArray") => {
                arrays += 1;
                if arrays > MAX_ARRAYS {
                    return Err(s.error(format!("more than {MAX_ARRAYS} data arrays")));
                }
                let Some(array) = data_array(&mut s, &attributes, empty, line)? else {
                    if !empty {
                        stack.push(name);
                    }
                    continue;
                };
                let piece = layout
                    .pieces
                    .last_mut()
                    .ok_or_else(|| s.error("a DataArray outside any <Piece>"))?;
                if parent == Some("Points") {
                    if piece.points.is_some() {
                        return Err(s.error("<Points> holds more than one DataArray"));
                    }
                    piece.points = Some(array);
                } else {
                    piece.point_data.push(array);
                }
            }
            (_, "AppendedData") => {
                layout.appended = Some(appended(&mut s, &attributes)?);
                break;
            }
            _ => {}
        }
        if !empty {
            if stack.len() == MAX_DEPTH {
                return Err(s.error(format!("elements nested deeper than {MAX_DEPTH}")));
            }
            stack.push(name);
        }
    }
    if !seen_file {
        return Err(s.error("not a VTK XML file: no <VTKFile> element"));
    }
    if layout.pieces.is_empty() {
        return Err(s.error("no <Piece> in the file"));
    }
    Ok(layout)
}

/// The attributes of `<VTKFile>`.
fn file_header(s: &Scanner, attributes: &[(String, String)], layout: &mut Layout) -> Result<()> {
    match attribute(attributes, "type") {
        Some("UnstructuredGrid" | "PolyData") => {}
        Some(other) => {
            return Err(s.error(format!(
                "VTKFile type {other:?} holds no particle points (supported: UnstructuredGrid, PolyData)"
            )))
        }
        None => return Err(s.error("<VTKFile> without a type")),
    }
    layout.big_endian = match attribute(attributes, "byte_order") {
        None | Some("LittleEndian") => false,
        Some("BigEndian") => true,
        Some(other) => return Err(s.error(format!("unknown byte_order {other:?}"))),
    };
    layout.header64 = match attribute(attributes, "header_type") {
        None | Some("UInt32") => false,
        Some("UInt64") => true,
        Some(other) => {
            return Err(s.error(format!("unknown header_type {other:?} (UInt32 or UInt64)")))
        }
    };
    layout.compressor = match attribute(attributes, "compressor") {
        None | Some("") => Compressor::None,
        Some("vtkZLibDataCompressor") => Compressor::Zlib,
        Some("vtkLZ4DataCompressor") => Compressor::Lz4,
        Some(other) => {
            return Err(s.error(format!(
            "compressor {other:?} is not supported (vtkZLibDataCompressor, vtkLZ4DataCompressor)"
        )))
        }
    };
    Ok(())
}

/// A `DataArray` of the points or the point data; for inline data, its text is skipped.
/// `None` for an array of a type that holds no numbers (`String`, `Bit`).
fn data_array(
    s: &mut Scanner,
    attributes: &[(String, String)],
    empty: bool,
    line: usize,
) -> Result<Option<Array>> {
    let name = attribute(attributes, "Name").unwrap_or("").to_string();
    let ty = attribute(attributes, "type")
        .ok_or_else(|| s.error(format!("DataArray {name:?} without a type")))?;
    let Some(scalar) = scalar_of(ty) else {
        return Ok(None);
    };
    let components = match attribute(attributes, "NumberOfComponents") {
        None => 1,
        Some(n) => n.trim().parse().ok().filter(|&n| n > 0).ok_or_else(|| {
            s.error(format!(
                "DataArray {name:?}: NumberOfComponents {n:?} is not a count"
            ))
        })?,
    };
    let format = attribute(attributes, "format").unwrap_or("ascii");
    let location = match format {
        "ascii" | "binary" => {
            let (offset, line) = (s.pos, s.line);
            let len = if empty { 0 } else { s.skip_text()? };
            if format == "ascii" {
                Location::Ascii { offset, line, len }
            } else {
                Location::Binary { offset, len }
            }
        }
        "appended" => {
            let offset = attribute(attributes, "offset")
                .ok_or_else(|| s.error(format!("appended DataArray {name:?} without an offset")))?;
            let offset = offset.trim().parse().map_err(|_| {
                s.error(format!(
                    "DataArray {name:?}: offset {offset:?} is not a number"
                ))
            })?;
            Location::Appended { offset }
        }
        other => {
            return Err(s.error(format!(
                "DataArray {name:?}: unknown format {other:?} (ascii, binary, appended)"
            )))
        }
    };
    Ok(Some(Array {
        name,
        scalar,
        components,
        location,
        line,
    }))
}

/// `<AppendedData encoding=...>`: skips to the `_` that starts the data.
fn appended(s: &mut Scanner, attributes: &[(String, String)]) -> Result<Appended> {
    let base64 = match attribute(attributes, "encoding") {
        Some("raw") => false,
        Some("base64") | None => true,
        Some(other) => {
            return Err(s.error(format!(
                "unknown AppendedData encoding {other:?} (raw, base64)"
            )))
        }
    };
    loop {
        match s.bump()? {
            Some(b'_') => break,
            Some(b) if b.is_ascii_whitespace() => continue,
            _ => return Err(s.error("the appended data does not start with '_'")),
        }
    }
    Ok(Appended {
        offset: s.pos,
        base64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tags_and_attributes_parse() {
        let Some(Tag::Start {
            name,
            attributes,
            empty,
        }) = parse_tag("DataArray type=\"Float32\" Name='a &amp; b' offset = \"12\" /")
        else {
            panic!("a start tag");
        };
        assert_eq!(name, "DataArray");
        assert!(empty);
        assert_eq!(attribute(&attributes, "Name"), Some("a & b"));
        assert_eq!(attribute(&attributes, "offset"), Some("12"));
        assert!(matches!(parse_tag("/Piece"), Some(Tag::End(n)) if n == "Piece"));
        assert!(parse_tag("Piece NumberOfPoints=3").is_none());
        assert!(parse_tag("").is_none());
    }
}
