//! The streaming readers' common decoders: fixed-size binary records and whitespace-
//! separated ASCII records, read front to back in chunks of at most [`CHUNK_RECORDS`] and
//! handed to a [`RecordSink`] (positions, checked finite, and payload rows). Memory: one
//! chunk (and, for ASCII, one line), whatever the file size.

use crate::error::{Error, Result};
use glam::Vec3;
use std::path::Path;

/// Records decoded per chunk by the streaming readers.
pub(super) const CHUNK_RECORDS: usize = 1 << 16;

/// Where the fixed-size records of a binary file are, and what they are called in error
/// messages ("particle"/"points").
pub(super) struct Records {
    /// Byte offset of the first record in the file.
    pub(super) offset: u64,
    pub(super) count: usize,
    /// Bytes per record.
    pub(super) stride: usize,
    pub(super) one: &'static str,
    pub(super) many: &'static str,
}

/// Opens `path` for the streaming readers, with a 1 MiB buffer.
pub(super) fn open_buffered(path: &Path) -> Result<std::io::BufReader<std::fs::File>> {
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    Ok(std::io::BufReader::with_capacity(1 << 20, file))
}

/// The error of a stream that ends before its `count` `many` (e.g. "points").
pub(super) fn truncated(count: usize, many: &str) -> String {
    format!("truncated while reading the {count} {many}: the file ends first")
}

/// The error for a non-finite position at `location` of `path`.
pub(super) fn non_finite(path: &Path, location: String, p: Vec3) -> Error {
    Error::parse(path, location, format!("non-finite coordinate {p}"))
}

/// Takes a record's position (when it holds one) and appends its payload values to the
/// row buffer: the decoder of [`stream_records`].
type Decode<'a> = &'a dyn Fn(&[u8], &mut Vec<f32>) -> Option<Vec3>;

/// Receives consecutive records: their positions (empty when the records hold none) and
/// their payload rows, row-major.
pub(super) type RecordSink<'a> = dyn FnMut(&[Vec3], &[f32]) -> Result<()> + 'a;

/// Reads the records from `reader` (positioned at the first one) in chunks of at most
/// 65 536, decodes each with `decode` (its position, checked finite, and its payload
/// values) and hands the chunks to `sink`. Memory: one chunk.
pub(super) fn stream_records(
    path: &Path,
    reader: &mut dyn std::io::Read,
    records: Records,
    decode: Decode<'_>,
    sink: &mut RecordSink<'_>,
) -> Result<()> {
    let Records {
        mut offset,
        count,
        stride,
        one,
        many,
    } = records;
    let mut bytes = vec![0u8; CHUNK_RECORDS.min(count) * stride];
    let mut chunk: Vec<Vec3> = Vec::with_capacity(CHUNK_RECORDS.min(count));
    let mut payload: Vec<f32> = Vec::new();
    let mut first = 0;
    while first < count {
        let n = CHUNK_RECORDS.min(count - first);
        let data = &mut bytes[..n * stride];
        reader.read_exact(data).map_err(|e| {
            Error::parse(
                path,
                format!("byte offset {offset}, {one} {first}"),
                if e.kind() == std::io::ErrorKind::UnexpectedEof {
                    truncated(count, many)
                } else {
                    format!("cannot read the {many}: {e}")
                },
            )
        })?;
        chunk.clear();
        payload.clear();
        for (k, record) in data.chunks_exact(stride).enumerate() {
            if let Some(p) = decode(record, &mut payload) {
                if !p.is_finite() {
                    return Err(non_finite(path, format!("{one} {}", first + k), p));
                }
                chunk.push(p);
            }
        }
        sink(&chunk, &payload)?;
        offset += data.len() as u64;
        first += n;
    }
    Ok(())
}

/// Where the records of an ASCII file are: `count` records of `fields` whitespace-separated
/// numbers each (a record may span lines or share one), the position taken from the fields
/// `xyz` (none: the records hold no position) and the payload row from the fields
/// `payload`, in that order; `line` is the 1-based line number at the reader's position
/// (for errors).
pub(super) struct AsciiRecords<'a> {
    pub(super) line: usize,
    pub(super) count: usize,
    pub(super) fields: usize,
    pub(super) xyz: Option<[usize; 3]>,
    pub(super) payload: &'a [usize],
    pub(super) one: &'static str,
    pub(super) many: &'static str,
}

/// [`stream_records`] for ASCII files: reads line by line from `reader` (positioned at the
/// first record), parses numbers like the whole-file readers (as f64, then rounded to
/// f32) and hands chunks of at most 65 536 records to `sink`. Memory: one line and one
/// chunk. What follows the last record is not read.
pub(super) fn stream_ascii_records(
    path: &Path,
    reader: &mut dyn std::io::BufRead,
    records: AsciiRecords,
    sink: &mut RecordSink<'_>,
) -> Result<()> {
    let AsciiRecords {
        mut line,
        count,
        fields,
        xyz,
        payload: columns,
        one,
        many,
    } = records;
    let mut chunk: Vec<Vec3> = Vec::with_capacity(CHUNK_RECORDS.min(count));
    let mut payload: Vec<f32> = Vec::new();
    let mut text = Vec::new();
    // `fields` comes from a header line, so the record is no larger than what was read.
    let (mut done, mut field, mut record) = (0, 0, vec![0.0f32; fields]);
    let mut rows = 0;
    let at = |line: usize, done: usize| format!("line {line}, {one} {done}");
    while done < count {
        text.clear();
        if reader
            .read_until(b'\n', &mut text)
            .map_err(|e| Error::io(path, e))?
            == 0
        {
            return Err(Error::parse(path, at(line, done), truncated(count, many)));
        }
        let words = std::str::from_utf8(&text).map_err(|_| {
            Error::parse(
                path,
                at(line, done),
                "expected numbers, found non-text bytes",
            )
        })?;
        for word in words.split_ascii_whitespace() {
            if done == count {
                break;
            }
            let value: f64 = word.parse().map_err(|_| {
                Error::parse(
                    path,
                    at(line, done),
                    format!("expected a number, found {word:?}"),
                )
            })?;
            record[field] = value as f32;
            field += 1;
            if field == fields {
                if let Some([x, y, z]) = xyz {
                    let p = Vec3::new(record[x], record[y], record[z]);
                    if !p.is_finite() {
                        return Err(non_finite(path, at(line, done), p));
                    }
                    chunk.push(p);
                }
                payload.extend(columns.iter().map(|&k| record[k]));
                field = 0;
                done += 1;
                rows += 1;
                if rows == CHUNK_RECORDS {
                    sink(&chunk, &payload)?;
                    chunk.clear();
                    payload.clear();
                    rows = 0;
                }
            }
        }
        line += 1;
    }
    if rows > 0 {
        sink(&chunk, &payload)?;
    }
    Ok(())
}
