//! The container: the file header, the self-delimiting frame records, the index and
//! trailer (byte layout in `docs/archive-format.md`), and the walk over the records that
//! the reader and the writer share.
//!
//! Two views say where the records end: the index's offset ([`read_index`]: the index
//! is written right after the last record) and a walk of the records themselves
//! ([`scan_records`], whose last complete [`Span::Record`] ends there in an intact
//! archive). The reader checks the index's entries against the records the walk finds
//! before the index, and walks the whole file when there is no valid index.

use crate::error::Error;
use std::path::Path;

/// The file's first 8 bytes.
pub(crate) const MAGIC: &[u8; 8] = b"MNSCMSEQ";
/// The version new archives get. Versions 1 (one plain mesh per frame) and 2 (no parts)
/// are still read and appended to in their own format.
pub(crate) const VERSION: u32 = 3;
/// The version of an archive with a frame that stores attributes (records flagged
/// [`super::attributes::HAS_ATTRIBUTES`]): a version-2 or -3 archive becomes version 4
/// when such a frame is appended (its header's version field is rewritten, nothing
/// else), so that readers that know no attributes refuse it instead of calling those
/// frames damaged.
pub(crate) const ATTRIBUTES_VERSION: u32 = 4;
/// The version of an archive with a frame whose sphere instances carry scales (records
/// flagged [`super::frame::HAS_SCALES`]): version 4 with that flag; any version from 2
/// becomes version 5 when such a frame is appended, as for attributes.
pub(crate) const SCALES_VERSION: u32 = 5;
/// Bytes of the file header: magic, version, a reserved word.
pub(crate) const HEADER_LEN: u64 = 16;
/// Offset of the version field in the file header.
pub(crate) const VERSION_OFFSET: u64 = 8;
const RECORD_MAGIC: &[u8; 4] = b"FRAM";
/// Bytes of a record header ([`RecordHeader`]); the payload follows it.
pub(crate) const RECORD_HEADER_LEN: usize = 48;
pub(crate) const INDEX_MAGIC: &[u8; 4] = b"INDX";
const TRAILER_MAGIC: &[u8; 8] = b"MSEQEND!";
/// Bytes of the trailer: the index offset and [`TRAILER_MAGIC`].
const TRAILER_LEN: usize = 16;
/// The most Loop steps a frame may ask its reader to run (each multiplies the triangles
/// by 4): more is refused before anything is subdivided.
pub const MAX_SUBDIVISION_LEVELS: u32 = 4;
/// The largest quantization step (of positions or attributes): twice the error bound
/// must be finite and decode lattice coordinates to finite `f32`s.
pub(crate) const MAX_STEP: f64 = f32::MAX as f64;

/// An error about the archive at `path`, located at frame `frame` or at the archive.
pub(crate) fn archive_error(path: &Path, frame: Option<i64>, message: impl Into<String>) -> Error {
    let location = match frame {
        Some(n) => format!("frame {n}"),
        None => "archive".to_string(),
    };
    Error::parse(path, location, message)
}

/// What to do with a damaged or unfinished archive at `path` (appending, merging and
/// verifying it say so).
pub fn repair_advice(path: &Path) -> String {
    format!(
        "`meniscus archive repair {}` keeps every readable frame and rebuilds the index",
        path.display()
    )
}

/// The file header of an archive of format `version`.
pub(crate) fn file_header(version: u32) -> [u8; HEADER_LEN as usize] {
    let mut header = [0u8; HEADER_LEN as usize];
    header[0..8].copy_from_slice(MAGIC);
    header[8..12].copy_from_slice(&version.to_le_bytes());
    header
}

/// A record header: what the frame decodes to and its payload's length and checksum.
#[derive(Clone)]
pub(crate) struct RecordHeader {
    pub(crate) number: i64,
    pub(crate) vertices: u32,
    pub(crate) triangles: u32,
    pub(crate) step: f64,
    pub(crate) payload_len: u64,
    pub(crate) payload_crc: u32,
    /// Bytes 40..44, zero before attributes: [`super::attributes::HAS_ATTRIBUTES`].
    pub(crate) flags: u32,
}

impl RecordHeader {
    pub(crate) fn to_bytes(&self) -> [u8; RECORD_HEADER_LEN] {
        let mut b = [0u8; RECORD_HEADER_LEN];
        b[0..4].copy_from_slice(RECORD_MAGIC);
        b[4..12].copy_from_slice(&self.number.to_le_bytes());
        b[12..16].copy_from_slice(&self.vertices.to_le_bytes());
        b[16..20].copy_from_slice(&self.triangles.to_le_bytes());
        b[20..28].copy_from_slice(&self.step.to_le_bytes());
        b[28..36].copy_from_slice(&self.payload_len.to_le_bytes());
        b[36..40].copy_from_slice(&self.payload_crc.to_le_bytes());
        b[40..44].copy_from_slice(&self.flags.to_le_bytes());
        let crc = crc32fast::hash(&b[0..44]);
        b[44..48].copy_from_slice(&crc.to_le_bytes());
        b
    }

    /// The header at the start of `b`, when its magic and checksum hold.
    pub(crate) fn parse(b: &[u8]) -> Option<RecordHeader> {
        if b.len() < RECORD_HEADER_LEN || &b[0..4] != RECORD_MAGIC {
            return None;
        }
        let crc = u32::from_le_bytes(b[44..48].try_into().ok()?);
        if crc != crc32fast::hash(&b[0..44]) {
            return None;
        }
        Some(RecordHeader {
            number: i64::from_le_bytes(b[4..12].try_into().ok()?),
            vertices: u32::from_le_bytes(b[12..16].try_into().ok()?),
            triangles: u32::from_le_bytes(b[16..20].try_into().ok()?),
            step: f64::from_le_bytes(b[20..28].try_into().ok()?),
            payload_len: u64::from_le_bytes(b[28..36].try_into().ok()?),
            payload_crc: u32::from_le_bytes(b[36..40].try_into().ok()?),
            flags: u32::from_le_bytes(b[40..44].try_into().ok()?),
        })
    }
}

/// A complete record (valid header, payload within `limit`) at `pos`: its header and end.
pub(crate) fn record_at(bytes: &[u8], pos: usize, limit: usize) -> Option<(RecordHeader, usize)> {
    let header_end = pos.checked_add(RECORD_HEADER_LEN)?;
    if header_end > limit {
        return None;
    }
    let h = RecordHeader::parse(bytes.get(pos..header_end)?)?;
    let end = header_end.checked_add(usize::try_from(h.payload_len).ok()?)?;
    (end <= limit).then_some((h, end))
}

/// True when a record may end at `pos` of `bytes[..limit]`: the end itself, a record
/// header whose checksum holds (its payload complete or not), or the start of a record or
/// an index that a write cut off.
fn is_boundary(bytes: &[u8], pos: usize, limit: usize) -> bool {
    let Some(rest) = bytes.get(pos..limit) else {
        return false;
    };
    rest.is_empty()
        || rest
            .get(..RECORD_HEADER_LEN)
            .and_then(RecordHeader::parse)
            .is_some()
        || is_cut_off_record_or_index(rest)
}

/// True when the payload `bytes[pos + RECORD_HEADER_LEN..end]` of the record at `pos`
/// has the checksum its header `h` gives.
fn payload_holds(bytes: &[u8], pos: usize, h: &RecordHeader, end: usize) -> bool {
    crc32fast::hash(&bytes[pos + RECORD_HEADER_LEN..end]) == h.payload_crc
}

/// The complete record at `pos` when its length can be trusted: it ends where a record
/// may end ([`is_boundary`]; then a checksum mismatch is damage to the payload, reported
/// by frame), or its payload has its checksum. A record whose length field lies
/// (re-checksummed header) ends inside the bytes of what follows and its payload fails
/// its checksum: not taken, so that the walk finds what follows. `crc_budget` bounds the
/// bytes checksummed for this (a crafted file of many such headers would otherwise take
/// quadratic time); once spent, such a record is not taken.
fn trusted_record_at(
    bytes: &[u8],
    pos: usize,
    limit: usize,
    crc_budget: &mut usize,
) -> Option<(RecordHeader, usize)> {
    let (h, end) = record_at(bytes, pos, limit)?;
    if is_boundary(bytes, end, limit) {
        return Some((h, end));
    }
    let len = end - pos - RECORD_HEADER_LEN;
    if len > *crc_budget {
        return None;
    }
    *crc_budget -= len;
    payload_holds(bytes, pos, &h, end).then_some((h, end))
}

/// The true end of the payload of the record at `pos` whose header `h` parses but whose
/// length field is wrong: the first place after its header where a record or an index
/// may start (a record header whose checksum holds, `INDX`, or `limit`), when the bytes
/// up to there have the payload's checksum and are not empty (a writer's payload never
/// is). `None` otherwise (the payload itself is damaged or cut off). One checksum, over
/// the bytes up to that place.
pub(crate) fn true_payload_end(
    bytes: &[u8],
    pos: usize,
    h: &RecordHeader,
    limit: usize,
) -> Option<usize> {
    let start = pos.checked_add(RECORD_HEADER_LEN)?;
    let region = bytes.get(start..limit)?;
    let end = (0..region.len())
        .find(|&k| {
            let rest = &region[k..];
            rest.starts_with(INDEX_MAGIC)
                || (rest.starts_with(RECORD_MAGIC)
                    && rest
                        .get(..RECORD_HEADER_LEN)
                        .and_then(RecordHeader::parse)
                        .is_some())
        })
        .unwrap_or(region.len());
    (end > 0 && crc32fast::hash(&region[..end]) == h.payload_crc).then_some(start + end)
}

/// A stretch of the records, as [`scan_records`] finds it.
pub(crate) enum Span {
    /// A complete record at this offset.
    Record(usize, RecordHeader),
    /// Bytes `start..end` hold no complete record.
    Damaged(usize, usize),
}

impl Span {
    /// Where the span starts.
    pub(crate) fn start(&self) -> usize {
        match self {
            Span::Record(p, _) | Span::Damaged(p, _) => *p,
        }
    }
}

/// Walks the records in `HEADER_LEN..limit`. Past bytes that are not a complete record
/// it resynchronises at the next record magic whose header checksum holds and whose
/// payload is complete, so one damaged record costs only its own frame. A record whose
/// length does not end where a record may end and whose payload fails its checksum is not
/// followed (its length field is damaged: [`trusted_record_at`]). The position only ever
/// moves forward.
pub(crate) fn scan_records(bytes: &[u8], limit: usize) -> Vec<Span> {
    let mut spans = Vec::new();
    let mut pos = HEADER_LEN as usize;
    let mut crc_budget = 2 * limit + (1 << 20);
    while pos < limit {
        if let Some((h, end)) = trusted_record_at(bytes, pos, limit, &mut crc_budget) {
            spans.push(Span::Record(pos, h));
            pos = end;
            continue;
        }
        let next = (pos + 1..limit)
            .find(|&p| {
                bytes[p..limit].starts_with(RECORD_MAGIC)
                    && trusted_record_at(bytes, p, limit, &mut crc_budget).is_some()
            })
            .unwrap_or(limit);
        spans.push(Span::Damaged(pos, next));
        pos = next;
    }
    spans
}

/// Where a walk of the records ([`scan_records`] up to `limit`) says they end: the end of
/// its last span when that is a complete record; else the start of the damaged span at
/// the end, where the walk cannot tell.
pub(crate) fn walk_end(spans: &[Span]) -> usize {
    match spans.last() {
        None => HEADER_LEN as usize,
        Some(Span::Damaged(p, _)) => *p,
        Some(Span::Record(p, h)) => p + RECORD_HEADER_LEN + h.payload_len as usize,
    }
}

/// What a damaged record header at `pos` claims, for messages.
pub(crate) fn claimed_frame(bytes: &[u8], pos: usize) -> String {
    match bytes.get(pos..pos + 12) {
        Some(b) if &b[0..4] == RECORD_MAGIC => format!(
            " (its header, unverified, says frame {})",
            i64::from_le_bytes(b[4..12].try_into().expect("8 bytes"))
        ),
        _ => String::new(),
    }
}

/// True when `tail`, bytes after the last complete record that hold no record, may be
/// the start of a record or of an index that an interrupted write cut off.
pub(crate) fn is_cut_off_record_or_index(tail: &[u8]) -> bool {
    tail.starts_with(INDEX_MAGIC)
        || (tail.len() < RECORD_HEADER_LEN && RECORD_MAGIC.starts_with(&tail[..tail.len().min(4)]))
}

/// A valid index read through the trailer.
pub(crate) struct Index {
    /// Where the index starts: where, by the index, the records end.
    pub(crate) offset: usize,
    /// (frame, record offset), in file order.
    pub(crate) entries: Vec<(i64, u64)>,
}

/// The index through the trailer at the end of `b`; `None` when there is none or it is
/// damaged.
pub(crate) fn read_index(b: &[u8]) -> Option<Index> {
    if b.len() < HEADER_LEN as usize + TRAILER_LEN || &b[b.len() - 8..] != TRAILER_MAGIC {
        return None;
    }
    let index_end = b.len() - TRAILER_LEN;
    let index_offset = u64::from_le_bytes(b[index_end..b.len() - 8].try_into().expect("8 bytes"));
    let index_offset = usize::try_from(index_offset).ok()?;
    if index_offset < HEADER_LEN as usize
        || index_offset.checked_add(16)? > index_end
        || &b[index_offset..index_offset + 4] != INDEX_MAGIC
    {
        return None;
    }
    let count = u64::from_le_bytes(
        b[index_offset + 4..index_offset + 12]
            .try_into()
            .expect("8 bytes"),
    );
    let entries_end = usize::try_from(count)
        .ok()?
        .checked_mul(16)?
        .checked_add(index_offset + 12)?;
    if entries_end.checked_add(4)? != index_end {
        return None;
    }
    let crc = u32::from_le_bytes(b[entries_end..entries_end + 4].try_into().expect("4 bytes"));
    if crc != crc32fast::hash(&b[index_offset..entries_end]) {
        return None;
    }
    let entries = b[index_offset + 12..entries_end]
        .chunks_exact(16)
        .map(|e| {
            (
                i64::from_le_bytes(e[0..8].try_into().expect("8 bytes")),
                u64::from_le_bytes(e[8..16].try_into().expect("8 bytes")),
            )
        })
        .collect();
    Some(Index {
        offset: index_offset,
        entries,
    })
}

/// The index of `entries` (frame, record offset) at offset `end`, and the trailer.
pub(crate) fn index_bytes(entries: &[(i64, u64)], end: u64) -> Vec<u8> {
    let mut index = Vec::with_capacity(12 + 16 * entries.len() + 4 + TRAILER_LEN);
    index.extend_from_slice(INDEX_MAGIC);
    index.extend_from_slice(&(entries.len() as u64).to_le_bytes());
    for (n, offset) in entries {
        index.extend_from_slice(&n.to_le_bytes());
        index.extend_from_slice(&offset.to_le_bytes());
    }
    let crc = crc32fast::hash(&index);
    index.extend_from_slice(&crc.to_le_bytes());
    index.extend_from_slice(&end.to_le_bytes());
    index.extend_from_slice(TRAILER_MAGIC);
    index
}
