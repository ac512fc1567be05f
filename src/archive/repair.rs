//! `archive repair`: a damaged or unfinished archive rewritten with every frame that can
//! be read, its records copied byte for byte and the index rebuilt.

use super::container::{
    index_bytes, read_index, scan_records, true_payload_end, RecordHeader, Span, HEADER_LEN,
    RECORD_HEADER_LEN,
};
use super::reader::{ArchiveReader, FrameInfo};
use crate::error::Result;
use std::io::Write;
use std::path::Path;

/// What [`repair`] kept and dropped.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct RepairReport {
    /// The frames kept, in file order.
    pub kept: Vec<i64>,
    /// Frames whose record header gave a wrong payload length although the payload is
    /// intact (it has its checksum): kept, their header rewritten with the true length.
    pub relengthed: Vec<i64>,
    /// What was dropped and why: damaged records (by the frame number the index or their
    /// header gives, when one does), bytes that hold no record, a cut-off tail, frames
    /// that do not decode, second records of a frame number.
    pub dropped: Vec<String>,
    /// True when the archive had no valid index (it was not finished).
    pub index_was_missing: bool,
    /// What was wrong with the file header when its magic number or version was damaged
    /// and the records and index after it were sound: the header was rebuilt.
    pub header_rebuilt: Option<String>,
    /// Bytes of the repaired archive.
    pub bytes: u64,
}

/// A record the walk found: its header (with the true payload length), where it starts
/// and whether its length field was wrong.
struct Found {
    header: RecordHeader,
    offset: usize,
    relengthed: bool,
}

/// Rewrites the archive `input` as `output` (which may be `input` itself) with every frame
/// that decodes: the records are walked from the file header on (the index, when there is
/// one, is not trusted for where they are); damaged records and bytes that hold no record
/// are skipped, a cut-off record at the end is cut, a record whose length field lies but
/// whose payload is intact is kept with its length corrected, of a frame number held by
/// several records the one the archive reads now is kept when it decodes (else the first
/// that does), and a new index is written. The
/// kept records are copied byte for byte, in file order, so every readable frame decodes
/// exactly as before. `output` is written whole under a temporary name and renamed into
/// place: on any error nothing is changed. An `output` that exists and is not `input` is
/// refused, as [`super::merge`] refuses it.
pub fn repair(input: &Path, output: &Path) -> Result<RepairReport> {
    let name = input.display().to_string();
    crate::error::guard(move || name, || repair_unguarded(input, output))
}

fn repair_unguarded(input: &Path, output: &Path) -> Result<RepairReport> {
    super::merge::check_output(&[input.to_path_buf()], output)?;
    let (reader, header_rebuilt) = ArchiveReader::open_rebuilding_header(input)?;
    let bytes = &reader.bytes;
    let index = read_index(bytes);
    let mut report = RepairReport {
        index_was_missing: index.is_none(),
        header_rebuilt,
        ..Default::default()
    };
    let limit = index.as_ref().map_or(bytes.len(), |i| i.offset);
    let indexed: std::collections::HashMap<u64, i64> = index
        .iter()
        .flat_map(|i| i.entries.iter().map(|&(n, o)| (o, n)))
        .collect();
    let found = walk(bytes, limit, &indexed, &mut report.dropped);
    let kept = readable(&reader, found, &mut report);
    report.bytes = write(output, &reader, &kept)?;
    Ok(report)
}

/// Every record the walk of `bytes[..limit]` finds, and those whose length field lies
/// recovered from the damaged stretches; what holds no record is described in
/// `dropped` (naming the frame `indexed` lists at a damaged record's offset).
fn walk(
    bytes: &[u8],
    limit: usize,
    indexed: &std::collections::HashMap<u64, i64>,
    dropped: &mut Vec<String>,
) -> Vec<Found> {
    let mut found = Vec::new();
    for span in scan_records(bytes, limit) {
        match span {
            Span::Record(offset, header) => found.push(Found {
                header,
                offset,
                relengthed: false,
            }),
            Span::Damaged(start, end) => {
                recover(bytes, start, end, limit, indexed, &mut found, dropped);
            }
        }
    }
    found
}

/// The records in the damaged stretch `bytes[start..end]` whose header holds and whose
/// payload, up to the next place a record or the index may start, has its checksum (a
/// length field that lies); the rest is described in `dropped`.
fn recover(
    bytes: &[u8],
    start: usize,
    end: usize,
    limit: usize,
    indexed: &std::collections::HashMap<u64, i64>,
    found: &mut Vec<Found>,
    dropped: &mut Vec<String>,
) {
    let header_at = |p: usize| {
        bytes
            .get(p..(p + RECORD_HEADER_LEN).min(end))
            .and_then(RecordHeader::parse)
    };
    let mut pos = start;
    while pos < end {
        let header = header_at(pos);
        if let Some(h) = &header {
            if let Some(payload_end) = true_payload_end(bytes, pos, h, end) {
                let mut header = h.clone();
                header.payload_len = (payload_end - pos - RECORD_HEADER_LEN) as u64;
                found.push(Found {
                    header,
                    offset: pos,
                    relengthed: true,
                });
                pos = payload_end;
                continue;
            }
        }
        let next = (pos + 1..end)
            .find(|&p| header_at(p).is_some())
            .unwrap_or(end);
        let frame = header
            .as_ref()
            .map(|h| h.number)
            .or_else(|| indexed.get(&(pos as u64)).copied());
        let what = match frame {
            Some(n) => format!("frame {n}: bytes {pos}..{next}"),
            None => format!("bytes {pos}..{next}"),
        };
        let why = match (&header, next == limit) {
            (Some(_), true) => "a record cut off (truncated archive)",
            (Some(_), false) => "a record whose payload does not match its checksum",
            (None, true) => "no complete record at the end (an interrupted write)",
            (None, false) => "no record (a damaged record header)",
        };
        dropped.push(format!("{what}: {why}"));
        pos = next;
    }
}

/// The records of `found` that decode, one per frame number: the record the archive
/// reads for that number now (through its index, or the first the scan found) when it
/// decodes, else the first that decodes. The others are described in `report.dropped`,
/// the kept and relengthed frames listed in `report`.
fn readable(reader: &ArchiveReader, found: Vec<Found>, report: &mut RepairReport) -> Vec<Found> {
    use rayon::prelude::*;
    use std::collections::HashMap;
    let bytes = &reader.bytes;
    let outcomes: Vec<Option<String>> = found
        .par_iter()
        .map(|f| {
            let info = FrameInfo::of(&f.header, f.offset, bytes);
            reader
                .decode_record(&info, f.header.payload_crc, f.header.flags)
                .err()
                .map(|e| e.to_string())
        })
        .collect();
    let mut read_now: HashMap<i64, usize> = HashMap::new();
    for f in reader.frames.iter().rev() {
        read_now.insert(f.number, f.offset as usize);
    }
    let mut chosen: HashMap<i64, usize> = HashMap::new();
    for (f, outcome) in found.iter().zip(&outcomes) {
        if outcome.is_some() {
            continue;
        }
        let n = f.header.number;
        if read_now.get(&n) == Some(&f.offset) {
            chosen.insert(n, f.offset);
        } else {
            chosen.entry(n).or_insert(f.offset);
        }
    }
    let mut kept: Vec<Found> = Vec::with_capacity(chosen.len());
    for (f, outcome) in found.into_iter().zip(outcomes) {
        let n = f.header.number;
        if let Some(why) = outcome {
            report
                .dropped
                .push(format!("frame {n} (record at offset {}): {why}", f.offset));
        } else if chosen.get(&n) != Some(&f.offset) {
            report.dropped.push(format!(
                "frame {n} (record at offset {}): a second record of this frame (the one at offset {} is kept)",
                f.offset, chosen[&n]
            ));
        } else {
            report.kept.push(n);
            if f.relengthed {
                report.relengthed.push(n);
            }
            kept.push(f);
        }
    }
    kept
}

/// Writes the archive of the `kept` records of `reader` to `output`, whole under a
/// temporary name, then renamed; returns its bytes.
fn write(output: &Path, reader: &ArchiveReader, kept: &[Found]) -> Result<u64> {
    let bytes = &reader.bytes;
    crate::io::atomic::write_atomically(output, |w| {
        w.write_all(&bytes[..HEADER_LEN as usize])?;
        let mut index = Vec::with_capacity(kept.len());
        let mut end = HEADER_LEN;
        for f in kept {
            let payload_start = f.offset + RECORD_HEADER_LEN;
            let payload_end = payload_start + f.header.payload_len as usize;
            if f.relengthed {
                w.write_all(&f.header.to_bytes())?;
            } else {
                w.write_all(&bytes[f.offset..payload_start])?;
            }
            w.write_all(&bytes[payload_start..payload_end])?;
            index.push((f.header.number, end));
            end += (payload_end - f.offset) as u64;
        }
        w.write_all(&index_bytes(&index, end))?;
        w.flush()?;
        w.get_ref().sync_all()
    })
}
