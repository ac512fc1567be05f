//! `.mseq`: one file for a whole sequence of meshes — quantized, compressed, randomly
//! accessible, checked. Byte layout in `docs/archive-format.md`.
//!
//! **Write:** [`ArchiveWriter::create`] or [`ArchiveWriter::open_append`], then
//! [`ArchiveWriter::append`] per frame and [`ArchiveWriter::finish`] (writes the index).
//! Frames are self-delimiting records with CRC-32 checksums, appended after the earlier
//! ones, which are never rewritten; a writer dropped without `finish` (an error, an
//! interruption, a panic) writes the index of the complete frames itself, so a failed
//! run leaves a consistent archive ([`ArchiveWriter`]). **Read:** [`ArchiveReader::open`]
//! uses the index, or — after an interrupted append — scans the records and keeps every
//! complete frame; [`ArchiveReader::read_frame`] is O(1) by frame number;
//! [`ArchiveReader::verify`] decodes everything and names damaged frames.
//!
//! **Frames** ([`ArchiveFrame`]): the pipeline's fluid surface is stored as its Loop
//! control mesh (the decimated mesh, a quarter of the triangles) and subdivided again on
//! decoding, a big one in parts that decode in parallel; isolated-particle spheres as one
//! template and their centres. Meshes from other tools ([`ArchiveWriter::append`]) are
//! stored as they are.
//!
//! Round trip: connectivity exactly, up to a permutation of the triangles (traversal
//! order), a rotation of each triangle's corners (orientation kept) and a renumbering of
//! the vertices (order of first use; unreferenced vertices are dropped); every coordinate
//! within the error bound; normals recomputed (area-weighted) on decoding.
//!
//! **Attributes** (velocity for motion blur, density, ...): the fluid's per-vertex
//! attributes and the spheres' per-instance attributes are stored per frame, each value
//! quantized with [`ArchiveOptions::attribute_error_bound`] (absolute, in the attribute's
//! units; stored in the frame's record, so frames appended with another bound keep
//! theirs: [`FrameInfo::attribute_error_bound`]). Without subdivision every decoded value
//! is within that bound of the original. With `subdivision_levels > 0` the values are
//! stored for the control vertices and each Loop step gives every new vertex the same
//! linear combination of the control values as its position (vertex and edge masks,
//! boundary rules included): the decoded values are the Loop subdivision of the stored
//! control values, as the decoded positions are of the stored control positions, so they
//! are within the bound of the subdivision of the exact control values (the masks are
//! convex); a constant attribute stays constant and a linear function of the positions
//! stays that function of the subdivided positions. Decoded items follow the decoded
//! vertices (and instances) in order. A frame without attributes is stored exactly as
//! before attributes existed; a frame with them makes the archive version 4.

mod attributes;
mod codec;
mod frame;
mod fused;
mod merge;
mod parts;

pub use attributes::{AttributeInfo, AttributeTarget};
pub use frame::ArchiveFrame;
pub use merge::{merge, MergeStats};

use crate::error::{Error, Result};
use crate::mesh::{SphereInstances, Surface, TriMesh};
use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

const MAGIC: &[u8; 8] = b"MNSCMSEQ";
/// The version new archives get. Versions 1 (one plain mesh per frame) and 2 (no parts)
/// are still read and appended to in their own format.
const VERSION: u32 = 3;
/// The version of an archive with a frame that stores attributes (records flagged
/// [`attributes::HAS_ATTRIBUTES`]): a version-2 or -3 archive becomes version 4 when such
/// a frame is appended (its header's version field is rewritten, nothing else), so that
/// readers that know no attributes refuse it instead of calling those frames damaged.
const ATTRIBUTES_VERSION: u32 = 4;
const HEADER_LEN: u64 = 16;
const RECORD_MAGIC: &[u8; 4] = b"FRAM";
const RECORD_HEADER_LEN: usize = 48;
const INDEX_MAGIC: &[u8; 4] = b"INDX";
const TRAILER_MAGIC: &[u8; 8] = b"MSEQEND!";
/// The most Loop steps a frame may ask its reader to run (each multiplies the triangles
/// by 4): more is refused before anything is subdivided.
pub const MAX_SUBDIVISION_LEVELS: u32 = 4;
/// The largest quantization step (of positions or attributes): twice the error bound
/// must be finite and decode lattice coordinates to finite `f32`s.
const MAX_STEP: f64 = f32::MAX as f64;

/// Options of a new archive.
#[derive(Clone, Debug, PartialEq)]
pub struct ArchiveOptions {
    /// Largest error of any coordinate, world units (> 0). Positions are quantized with a
    /// step of twice this bound.
    pub error_bound: f64,
    /// Largest error of any attribute value (> 0), absolute, in the attribute's own units
    /// (m/s for a velocity). Values are quantized with a step of twice this bound. Default
    /// 1e-3 ([`DEFAULT_ATTRIBUTE_ERROR_BOUND`]).
    pub attribute_error_bound: f64,
    /// zstd level. Default 9.
    pub zstd_level: i32,
}

/// The default [`ArchiveOptions::attribute_error_bound`]: 1e-3 in the attribute's units.
///
/// For a velocity in m/s that is 1 mm/s: motion blur moves a vertex by the velocity
/// times the shutter time (1/48 s for a 180° shutter at 24 frames per second), so the
/// error in the blur is at most 2·10⁻⁵ m per component, well below the position bound
/// of a typical archive (0.01 r = 1.2·10⁻⁴ m for r = 12 mm) and invisible next to the
/// sub-frame motion (the `dambreak_small` fluid moves at up to about 3 m/s: 6 cm per
/// frame). It is absolute: an attribute of large magnitude (a density of 1000 kg/m³)
/// is stored far more finely than it needs (and larger) unless the bound is raised, one
/// of magnitude about 1 (or smaller) less finely than it may need.
pub const DEFAULT_ATTRIBUTE_ERROR_BOUND: f64 = 1e-3;

/// The default [`ArchiveOptions::error_bound`] of an archive of surfaces reconstructed
/// from particles, multiples of the particle radius `r` ([`default_error_bound`]).
pub const DEFAULT_ERROR_BOUND_RADII: f64 = 0.01;

/// The default [`ArchiveOptions::error_bound`] for particles of radius `particle_radius`
/// (world units): 0.01 r, with `r` taken as it is written (`0.012`, not the `f32`'s
/// 0.0120000001…). Every writer given the same radius (the CLI, the Python package, each
/// task of a farm) then uses the same bound, which archives must share to be merged, and
/// `archive info` prints the round number.
pub fn default_error_bound(particle_radius: f32) -> f64 {
    // An f32's Display is the shortest decimal that reads back as the same f32.
    let r: f64 = particle_radius
        .to_string()
        .parse()
        .unwrap_or(particle_radius as f64);
    DEFAULT_ERROR_BOUND_RADII * r
}

impl ArchiveOptions {
    /// Options with an error bound in world units, the default attribute error bound and
    /// the default zstd level.
    pub fn new(error_bound: f64) -> Self {
        ArchiveOptions {
            error_bound,
            attribute_error_bound: DEFAULT_ATTRIBUTE_ERROR_BOUND,
            zstd_level: 9,
        }
    }

    fn check(&self) -> Result<()> {
        for (option, value) in [
            ("error_bound", self.error_bound),
            ("attribute_error_bound", self.attribute_error_bound),
        ] {
            if !(value.is_finite() && value > 0.0 && 2.0 * value <= MAX_STEP) {
                return Err(Error::InvalidOption {
                    option,
                    message: format!("must be > 0 and at most {}, got {value}", MAX_STEP / 2.0),
                });
            }
        }
        Ok(())
    }
}

/// One frame as the archive lists it.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct FrameInfo {
    /// Frame number.
    pub number: i64,
    /// Vertices stored.
    pub vertices: u32,
    /// Triangles stored.
    pub triangles: u32,
    /// Quantization step, world units (error bound = step / 2 per coordinate).
    pub step: f64,
    /// Byte offset of the record.
    pub offset: u64,
    /// Bytes of the compressed payload.
    pub payload_bytes: u64,
    /// The attributes the frame stores (empty when none, or when their descriptor is
    /// damaged: decoding the frame says so).
    pub attributes: Vec<AttributeInfo>,
    /// Error bound of the frame's attribute values, in their own units (`None` without
    /// attributes).
    pub attribute_error_bound: Option<f64>,
}

impl FrameInfo {
    fn of(h: &RecordHeader, offset: usize, bytes: &[u8]) -> FrameInfo {
        let descriptor = (h.flags & attributes::HAS_ATTRIBUTES != 0)
            .then(|| bytes.get(offset + RECORD_HEADER_LEN..))
            .flatten()
            .and_then(|payload| attributes::read_descriptor(payload, &mut 0).ok());
        FrameInfo {
            number: h.number,
            vertices: h.vertices,
            triangles: h.triangles,
            step: h.step,
            offset: offset as u64,
            payload_bytes: h.payload_len,
            attribute_error_bound: descriptor.as_ref().map(|d| d.error_bound),
            attributes: descriptor.map(|d| d.attributes).unwrap_or_default(),
        }
    }
}

/// What [`ArchiveReader::verify`] found.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct VerifyReport {
    /// Frames that decode and match their checksums.
    pub good: Vec<i64>,
    /// Damaged frames with what is wrong.
    pub damaged: Vec<(i64, String)>,
    /// True when the index was missing or unreadable and the records were scanned.
    pub recovered_by_scan: bool,
    /// Bytes after the last complete record that belong to no frame.
    pub trailing_bytes: u64,
    /// Damage that no frame number can be given to: bytes between records that are no
    /// complete record, a missing index, an index that disagrees with the records.
    pub damage: Vec<String>,
}

impl VerifyReport {
    /// True when every frame decodes and nothing else in the file is damaged or missing.
    pub fn is_clean(&self) -> bool {
        self.damaged.is_empty() && self.damage.is_empty() && self.trailing_bytes == 0
    }
}

fn archive_error(path: &Path, frame: Option<i64>, message: impl Into<String>) -> Error {
    let location = match frame {
        Some(n) => format!("frame {n}"),
        None => "archive".to_string(),
    };
    Error::parse(path, location, message)
}

#[derive(Clone)]
struct RecordHeader {
    number: i64,
    vertices: u32,
    triangles: u32,
    step: f64,
    payload_len: u64,
    payload_crc: u32,
    /// Bytes 40..44, zero before attributes: [`attributes::HAS_ATTRIBUTES`].
    flags: u32,
}

impl RecordHeader {
    fn to_bytes(&self) -> [u8; RECORD_HEADER_LEN] {
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

    fn parse(b: &[u8]) -> Option<RecordHeader> {
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

/// What kind of damage [`ArchiveReader::open`] found outside the frames' payloads.
#[derive(Clone, Copy, Debug, PartialEq)]
enum DamageKind {
    /// A record in the middle whose header is damaged; later records were found again.
    /// Appending after the last record loses nothing.
    Record,
    /// Bytes after the last complete record that are the start of a record or of an
    /// index cut off by an interrupted write: appending may cut them.
    CutTail,
    /// Bytes after the last complete record that are not a cut-off record (a damaged
    /// record at the end): appending would cut them, so it is refused.
    Tail,
    /// The index disagrees with the records: appending (which rewrites the index from
    /// what was read) is refused.
    Index,
    /// No index (an unfinished or truncated archive): the records were scanned.
    NoIndex,
}

#[derive(Clone, Debug)]
struct Damage {
    kind: DamageKind,
    /// The frame, when the index or a complete record header names it.
    frame: Option<i64>,
    /// Record offset, for an index entry whose record header is damaged.
    offset: Option<u64>,
    message: String,
}

/// A complete record (valid header, payload within `limit`) at `pos`: its header and end.
fn record_at(bytes: &[u8], pos: usize, limit: usize) -> Option<(RecordHeader, usize)> {
    let header_end = pos.checked_add(RECORD_HEADER_LEN)?;
    if header_end > limit {
        return None;
    }
    let h = RecordHeader::parse(bytes.get(pos..header_end)?)?;
    let end = header_end.checked_add(usize::try_from(h.payload_len).ok()?)?;
    (end <= limit).then_some((h, end))
}

enum Span {
    Record(usize, RecordHeader),
    /// Bytes `start..end` hold no complete record.
    Damaged(usize, usize),
}

/// Walks the records in `HEADER_LEN..limit`. Past bytes that are not a complete record
/// it resynchronises at the next record magic whose header checksum holds and whose
/// payload is complete, so one damaged record costs only its own frame. The position
/// only ever moves forward.
fn scan_records(bytes: &[u8], limit: usize) -> Vec<Span> {
    let mut spans = Vec::new();
    let mut pos = HEADER_LEN as usize;
    while pos < limit {
        if let Some((h, end)) = record_at(bytes, pos, limit) {
            spans.push(Span::Record(pos, h));
            pos = end;
            continue;
        }
        let next = (pos + 1..limit)
            .find(|&p| {
                bytes[p..limit].starts_with(RECORD_MAGIC) && record_at(bytes, p, limit).is_some()
            })
            .unwrap_or(limit);
        spans.push(Span::Damaged(pos, next));
        pos = next;
    }
    spans
}

/// What a damaged record header at `pos` claims, for messages.
fn claimed_frame(bytes: &[u8], pos: usize) -> String {
    match bytes.get(pos..pos + 12) {
        Some(b) if &b[0..4] == RECORD_MAGIC => format!(
            " (its header, unverified, says frame {})",
            i64::from_le_bytes(b[4..12].try_into().expect("8 bytes"))
        ),
        _ => String::new(),
    }
}

/// A decoded frame whose coordinates or attribute values are not all finite f32s: lattice
/// coordinates a writer cannot produce (a crafted record), refused rather than returned.
fn check_decoded(s: Surface) -> std::result::Result<Surface, String> {
    let positions = [
        ("fluid vertex", &s.fluid.positions),
        ("sphere template vertex", &s.spheres.template.positions),
        ("sphere centre", &s.spheres.centers),
    ];
    for (what, list) in positions {
        if let Some(i) = list.iter().position(|p| !p.is_finite()) {
            return Err(format!(
                "{what} {i} decodes to {}: coordinates beyond f32 (damaged record)",
                list[i]
            ));
        }
    }
    for a in s.fluid.attributes.iter().chain(&s.spheres.attributes) {
        if let Some(i) = a.values.iter().position(|v| !v.is_finite()) {
            return Err(format!(
                "attribute {:?}: value {i} decodes to {}: beyond f32 (damaged record)",
                a.name, a.values[i]
            ));
        }
    }
    Ok(s)
}

/// Reads an archive.
pub struct ArchiveReader {
    path: PathBuf,
    version: u32,
    bytes: Vec<u8>,
    frames: Vec<FrameInfo>,
    /// Payload CRCs and record flags, parallel to `frames`.
    crcs: Vec<u32>,
    flags: Vec<u32>,
    recovered_by_scan: bool,
    /// Where appending starts: the index offset, or the end of the last complete record.
    data_end: u64,
    /// Damage found while opening (records, tail, index).
    damage: Vec<Damage>,
}

impl ArchiveReader {
    /// Refuses to add `numbers` when the archive holds any of them:
    /// [`Error::FramesExist`] names those it holds (in the order of `numbers`).
    pub fn check_new_frames(&self, numbers: &[i64]) -> Result<()> {
        let held: Vec<i64> = numbers
            .iter()
            .copied()
            .filter(|n| self.frames.iter().any(|f| f.number == *n))
            .collect();
        if held.is_empty() {
            return Ok(());
        }
        Err(Error::FramesExist {
            path: self.path.clone(),
            frames: held,
            planned: numbers.len(),
        })
    }

    /// Opens an archive: through its index when that is valid (damaged records are then
    /// reported by the frame number the index gives them), else by scanning its records
    /// (an interrupted append), resynchronising past damaged ones.
    pub fn open(path: &Path) -> Result<ArchiveReader> {
        let input = path.display().to_string();
        crate::error::guard(move || input, || Self::open_unguarded(path))
    }

    fn open_unguarded(path: &Path) -> Result<ArchiveReader> {
        let mut bytes = Vec::new();
        File::open(path)
            .and_then(|mut f| f.read_to_end(&mut bytes))
            .map_err(|e| Error::io(path, e))?;
        if bytes.len() < HEADER_LEN as usize || &bytes[0..8] != MAGIC {
            return Err(archive_error(
                path,
                None,
                "not a meniscus .mseq archive (bad magic number)",
            ));
        }
        let version = u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes"));
        if !(1..=ATTRIBUTES_VERSION).contains(&version) {
            return Err(Error::UnsupportedFormat {
                path: path.to_path_buf(),
                message: format!(
                    ".mseq version {version}; this build reads versions 1 to {ATTRIBUTES_VERSION}"
                ),
            });
        }
        let mut reader = ArchiveReader {
            path: path.to_path_buf(),
            version,
            bytes,
            frames: Vec::new(),
            crcs: Vec::new(),
            flags: Vec::new(),
            recovered_by_scan: false,
            data_end: HEADER_LEN,
            damage: Vec::new(),
        };
        match reader.read_index() {
            Some((index_offset, entries)) => reader.use_index(index_offset, &entries),
            None => reader.scan(),
        }
        Ok(reader)
    }

    /// The index through the trailer: its offset and its (frame, record offset) entries;
    /// `None` when there is none or it is damaged.
    fn read_index(&self) -> Option<(usize, Vec<(i64, u64)>)> {
        let b = &self.bytes;
        if b.len() < HEADER_LEN as usize + 16 || &b[b.len() - 8..] != TRAILER_MAGIC {
            return None;
        }
        let index_offset =
            u64::from_le_bytes(b[b.len() - 16..b.len() - 8].try_into().expect("8 bytes"));
        let index_offset = usize::try_from(index_offset).ok()?;
        if index_offset < HEADER_LEN as usize
            || index_offset.checked_add(16)? > b.len() - 16
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
        if entries_end.checked_add(4)? != b.len() - 16 {
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
        Some((index_offset, entries))
    }

    fn push_frame(&mut self, h: &RecordHeader, offset: usize) {
        self.frames.push(FrameInfo::of(h, offset, &self.bytes));
        self.crcs.push(h.payload_crc);
        self.flags.push(h.flags);
    }

    /// Takes the frames from a valid index and checks it against the records before it.
    fn use_index(&mut self, index_offset: usize, entries: &[(i64, u64)]) {
        let spans = scan_records(&self.bytes, index_offset);
        // By start offset (spans start at distinct, increasing offsets): looking each
        // entry up must not walk every span, or an index of many entries over many
        // records takes quadratic time.
        let at: std::collections::HashMap<u64, &Span> = spans
            .iter()
            .map(|s| match s {
                Span::Record(p, _) | Span::Damaged(p, _) => (*p as u64, s),
            })
            .collect();
        let mut indexed = std::collections::HashSet::new();
        for &(number, offset) in entries {
            indexed.insert(offset);
            let found = match at.get(&offset) {
                Some(Span::Record(p, h)) => Some((*p, h)),
                _ => None,
            };
            match found {
                Some((o, h)) if h.number == number => {
                    let h = h.clone();
                    self.push_frame(&h, o);
                }
                Some((_, h)) => self.damage.push(Damage {
                    kind: DamageKind::Index,
                    frame: Some(number),
                    offset: None,
                    message: format!(
                        "the index lists this frame at offset {offset}, where the record is frame {} (index disagrees with records)",
                        h.number
                    ),
                }),
                None => {
                    let at_damaged = matches!(at.get(&offset), Some(Span::Damaged(..)));
                    self.damage.push(if at_damaged {
                        Damage {
                            kind: DamageKind::Record,
                            frame: Some(number),
                            offset: Some(offset),
                            message: format!(
                                "record header at offset {offset} is damaged (checksum mismatch or cut off)"
                            ),
                        }
                    } else {
                        Damage {
                            kind: DamageKind::Index,
                            frame: Some(number),
                            offset: None,
                            message: format!(
                                "the index lists this frame at offset {offset}, where no record starts (index disagrees with records)"
                            ),
                        }
                    });
                }
            }
        }
        for s in &spans {
            match s {
                Span::Record(p, h) if !indexed.contains(&(*p as u64)) => {
                    self.damage.push(Damage {
                        kind: DamageKind::Index,
                        frame: Some(h.number),
                        offset: None,
                        message: format!(
                            "the record at offset {p} is not in the index (index disagrees with records)"
                        ),
                    })
                }
                Span::Damaged(p, end) if !indexed.contains(&(*p as u64)) => {
                    self.damage.push(Damage {
                        kind: DamageKind::Record,
                        frame: None,
                        offset: None,
                        message: format!(
                            "bytes {p}..{end} belong to no frame: a damaged record{}",
                            claimed_frame(&self.bytes, *p)
                        ),
                    })
                }
                _ => {}
            }
        }
        self.data_end = index_offset as u64;
    }

    /// Without an index: keeps every complete record, resynchronising past damaged ones.
    fn scan(&mut self) {
        self.recovered_by_scan = true;
        let limit = self.bytes.len();
        let spans = scan_records(&self.bytes, limit);
        self.data_end = HEADER_LEN;
        self.damage.push(Damage {
            kind: DamageKind::NoIndex,
            frame: None,
            offset: None,
            message: "no valid index: the archive was not finished (interrupted write) or is \
                      truncated; its frames were recovered by scanning"
                .to_string(),
        });
        for s in spans {
            match s {
                Span::Record(p, h) => {
                    self.push_frame(&h, p);
                    self.data_end = (p + RECORD_HEADER_LEN) as u64 + h.payload_len;
                }
                Span::Damaged(p, end) if end < limit => self.damage.push(Damage {
                    kind: DamageKind::Record,
                    frame: None,
                    offset: None,
                    message: format!(
                        "bytes {p}..{end} belong to no frame: a damaged record{}",
                        claimed_frame(&self.bytes, p)
                    ),
                }),
                Span::Damaged(p, _) => {
                    let tail = &self.bytes[p..];
                    let header = tail.get(..RECORD_HEADER_LEN).and_then(RecordHeader::parse);
                    let (kind, frame, message) = if let Some(h) = header {
                        (
                            DamageKind::CutTail,
                            Some(h.number),
                            format!(
                                "record at offset {p} cut off: its payload needs {} bytes, {} are present (truncated archive)",
                                h.payload_len,
                                tail.len() - RECORD_HEADER_LEN
                            ),
                        )
                    } else if tail.starts_with(INDEX_MAGIC)
                        || (tail.len() < RECORD_HEADER_LEN
                            && RECORD_MAGIC.starts_with(&tail[..tail.len().min(4)]))
                    {
                        (
                            DamageKind::CutTail,
                            None,
                            format!(
                                "{} trailing bytes at offset {p}: an incomplete record or index (truncated archive)",
                                tail.len()
                            ),
                        )
                    } else {
                        (
                            DamageKind::Tail,
                            None,
                            format!(
                                "{} trailing bytes at offset {p} belong to no frame: a damaged record{}",
                                tail.len(),
                                claimed_frame(&self.bytes, p)
                            ),
                        )
                    };
                    self.damage.push(Damage {
                        kind,
                        frame,
                        offset: None,
                        message,
                    });
                }
            }
        }
    }

    /// The frames, in file order.
    pub fn frames(&self) -> &[FrameInfo] {
        &self.frames
    }

    /// True when the index was missing or damaged and the frames come from a scan.
    pub fn recovered_by_scan(&self) -> bool {
        self.recovered_by_scan
    }

    /// Format version of the file (1 to 4; 4 when a frame stores attributes).
    pub fn version(&self) -> u32 {
        self.version
    }

    /// Decodes frame `number`: fluid and spheres merged into one mesh, with normals.
    pub fn read_frame(&self, number: i64) -> Result<TriMesh> {
        Ok(self.read_surface(number)?.merged())
    }

    /// Decodes frame `number` as fluid surface plus sphere instances, with normals.
    pub fn read_surface(&self, number: i64) -> Result<Surface> {
        let mut surface = self.read_geometry(number)?;
        surface.fluid.compute_normals();
        if surface.spheres.template.normals.is_empty() {
            surface.spheres.template.compute_normals();
        }
        Ok(surface)
    }

    /// Decodes frame `number` as fluid surface plus sphere instances: positions and
    /// triangles only, no normals (what a renderer that makes its own normals needs).
    pub fn read_geometry(&self, number: i64) -> Result<Surface> {
        let input = format!("{}: frame {number}", self.path.display());
        crate::error::guard(move || input, || self.read_geometry_unguarded(number))
    }

    fn read_geometry_unguarded(&self, number: i64) -> Result<Surface> {
        let k = self
            .frames
            .iter()
            .position(|f| f.number == number)
            .ok_or_else(|| {
                let why = self
                    .damage
                    .iter()
                    .find(|d| d.frame == Some(number))
                    .map_or("no such frame in the archive", |d| d.message.as_str());
                archive_error(&self.path, Some(number), why)
            })?;
        self.decode(k)
    }

    fn decode(&self, k: usize) -> Result<Surface> {
        let f = &self.frames[k];
        let start = f.offset as usize + RECORD_HEADER_LEN;
        let payload = usize::try_from(f.payload_bytes)
            .ok()
            .and_then(|len| start.checked_add(len))
            .and_then(|end| self.bytes.get(start..end))
            .ok_or_else(|| {
                archive_error(
                    &self.path,
                    Some(f.number),
                    "payload cut off (truncated archive)",
                )
            })?;
        if crc32fast::hash(payload) != self.crcs[k] {
            return Err(archive_error(
                &self.path,
                Some(f.number),
                "checksum mismatch: the frame is damaged",
            ));
        }
        if !(f.step.is_finite() && f.step > 0.0 && f.step <= MAX_STEP) {
            return Err(archive_error(
                &self.path,
                Some(f.number),
                format!(
                    "quantization step {} in the record header is not a positive finite step (damaged record)",
                    f.step
                ),
            ));
        }
        let (vertices, triangles) = (f.vertices as usize, f.triangles as usize);
        let flags = self.flags[k];
        match (self.version, flags) {
            (1, 0) => codec::decode_v1(payload, vertices, triangles, f.step).map(|fluid| Surface {
                fluid,
                spheres: SphereInstances::default(),
            }),
            (2.., 0) => frame::decode_frame(payload, vertices, triangles, f.step, None),
            (2.., attributes::HAS_ATTRIBUTES) => attributes::split(payload).and_then(|s| {
                frame::decode_frame(
                    s.geometry,
                    vertices,
                    triangles,
                    f.step,
                    Some((&s.descriptor, s.streams)),
                )
            }),
            (version, _) => Err(format!(
                "record flags {flags:#x} unknown to this build in a version-{version} archive"
            )),
        }
        .and_then(check_decoded)
        .map_err(|m| archive_error(&self.path, Some(f.number), m))
    }

    /// Writes the frames `numbers` (all frames when `None`) to the files `output_pattern`
    /// names, its `{}` replaced by the frame number (one frame may also go to a plain
    /// path), in any format [`crate::io::mesh::write_surface`] writes; missing
    /// directories are made; frames are decoded and written in parallel, each file
    /// complete or absent; `cancel` stops it between frames. Returns the files in frame
    /// order.
    pub fn extract(
        &self,
        numbers: Option<&[i64]>,
        output_pattern: &str,
        options: &crate::io::mesh::MeshWriteOptions,
        cancel: &crate::CancelToken,
    ) -> Result<Vec<PathBuf>> {
        let input = self.path.display().to_string();
        crate::error::guard(
            move || input,
            || self.extract_unguarded(numbers, output_pattern, options, cancel),
        )
    }

    fn extract_unguarded(
        &self,
        numbers: Option<&[i64]>,
        output_pattern: &str,
        options: &crate::io::mesh::MeshWriteOptions,
        cancel: &crate::CancelToken,
    ) -> Result<Vec<PathBuf>> {
        use rayon::prelude::*;
        let single = numbers.is_some_and(|n| n.len() == 1);
        if !single && !crate::sequence::is_pattern(output_pattern) {
            return Err(Error::InvalidOption {
                option: "output",
                message: format!(
                    "{output_pattern:?} needs a {{}} for the frame number to hold several frames"
                ),
            });
        }
        let all: Vec<i64>;
        let numbers = match numbers {
            Some(n) => n,
            None => {
                all = self.frames.iter().map(|f| f.number).collect();
                &all
            }
        };
        let paths: Vec<PathBuf> = numbers
            .iter()
            .map(|n| crate::sequence::substitute(output_pattern, &n.to_string()))
            .collect();
        for dir in paths.iter().filter_map(|p| p.parent()) {
            if !dir.as_os_str().is_empty() {
                std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
            }
        }
        // Temporary files of killed extractions beside the outputs go first.
        crate::io::tempfiles::remove_output_leftovers(paths.iter().map(PathBuf::as_path));
        numbers
            .par_iter()
            .zip(&paths)
            .try_for_each(|(&n, path)| -> Result<()> {
                cancel.check()?;
                let surface = self.read_surface(n)?;
                crate::io::mesh::write_surface(path, &surface, options)?;
                Ok(())
            })?;
        Ok(paths)
    }

    /// Decodes every frame (in parallel; the report is in file order) and reports the
    /// damaged ones.
    pub fn verify(&self) -> VerifyReport {
        use rayon::prelude::*;
        let mut report = VerifyReport {
            recovered_by_scan: self.recovered_by_scan,
            ..Default::default()
        };
        let outcomes: Vec<Option<String>> = (0..self.frames.len())
            .into_par_iter()
            .map(|k| {
                let input = || format!("{}: frame {}", self.path.display(), self.frames[k].number);
                crate::error::guard(input, || self.decode(k))
                    .err()
                    .map(|e| e.to_string())
            })
            .collect();
        for (f, outcome) in self.frames.iter().zip(outcomes) {
            match outcome {
                None => report.good.push(f.number),
                Some(e) => report.damaged.push((f.number, e)),
            }
        }
        for d in &self.damage {
            match d.frame {
                Some(n) => report.damaged.push((n, d.message.clone())),
                None => report.damage.push(d.message.clone()),
            }
        }
        if self.recovered_by_scan {
            report.trailing_bytes = self.bytes.len() as u64 - self.data_end;
        }
        report
    }
}

/// Appends frames to an archive.
///
/// **Failures leave a consistent archive.** An error returned by
/// [`append`](Self::append) or [`append_frame`](Self::append_frame) (a frame refused, an
/// encoding or write error) leaves the writer as it was before that call: the frame is
/// not in the archive, every frame appended before it stays, and appending may go on.
/// A writer dropped without [`finish`](Self::finish) — an error returned by the caller,
/// an interruption ([`Error::Interrupted`]), a panic unwinding — finishes the archive
/// itself: it cuts any partial record at the end and writes the index of every complete
/// frame (those the archive held before and those appended), so the archive verifies
/// clean and a re-run with `--skip-existing` continues after its last frame. Errors
/// there cannot be returned; if the index cannot be written the frames are still
/// recovered by the reader's scan (and the next append writes it). A writer that wrote
/// nothing changes nothing: an archive opened for appending is left byte for byte as it
/// was, and a new archive whose first frame never arrived does not exist. Only a process
/// killed outright (`SIGKILL`, a power cut, a second Ctrl-C) leaves the index missing.
pub struct ArchiveWriter {
    path: PathBuf,
    version: u32,
    /// `None` for a new archive until its first frame is encoded (or `finish`): a run
    /// that fails before then leaves no file.
    file: Option<File>,
    options: ArchiveOptions,
    index: Vec<(i64, u64)>,
    /// End of the last complete record: where the next record (or the index) goes.
    end: u64,
    /// The file must be cut at `end` and its position set there before anything is
    /// written: at first (an appended archive's old index or cut-off record; done lazily,
    /// so that a writer that writes nothing changes nothing) and after a failed write.
    reset: bool,
    /// The file on disk has been changed (created, cut or written), so it needs an index.
    touched: bool,
    /// This writer made the file (a new archive): removed again when it is dropped
    /// before a frame is complete.
    created: bool,
    /// `finish` ran (successfully or not): dropping does nothing more.
    closed: bool,
}

impl ArchiveWriter {
    /// Creates a new archive (replacing any file at `path`). The file is written when
    /// the first frame is ready (or by `finish` for an archive without frames), so an
    /// archive whose first frame fails is never left behind, empty.
    pub fn create(path: &Path, options: &ArchiveOptions) -> Result<ArchiveWriter> {
        let input = path.display().to_string();
        crate::error::guard(move || input, || Self::create_unguarded(path, options))
    }

    fn create_unguarded(path: &Path, options: &ArchiveOptions) -> Result<ArchiveWriter> {
        options.check()?;
        Ok(ArchiveWriter {
            path: path.to_path_buf(),
            version: VERSION,
            file: None,
            options: options.clone(),
            index: Vec::new(),
            end: HEADER_LEN,
            reset: false,
            touched: false,
            created: false,
            closed: false,
        })
    }

    /// Opens an archive for appending. Earlier frames are kept as they are; the old
    /// index, and an incomplete last record left by an interrupted append (that frame
    /// was never complete), are cut off when the first frame is written (or by
    /// `finish`): until then the file is not changed. An archive with a damaged frame is
    /// refused.
    pub fn open_append(path: &Path, options: &ArchiveOptions) -> Result<ArchiveWriter> {
        let input = path.display().to_string();
        crate::error::guard(move || input, || Self::open_append_unguarded(path, options))
    }

    fn open_append_unguarded(path: &Path, options: &ArchiveOptions) -> Result<ArchiveWriter> {
        options.check()?;
        let reader = ArchiveReader::open(path)?;
        let report = reader.verify();
        // A frame whose payload is damaged, an index that disagrees with the records, or
        // bytes at the end that appending would cut and that are not a cut-off record:
        // refused, so that nothing is lost. Damaged record headers in the middle stay
        // where they are (appending goes after the last record) and stay reported.
        // The frames' own damage comes first in the report, the rest after.
        let frame_damage =
            report.damaged.len() - reader.damage.iter().filter(|d| d.frame.is_some()).count();
        let refusal = report.damaged[..frame_damage]
            .first()
            .map(|(n, why)| (Some(*n), why.clone()))
            .or_else(|| {
                reader
                    .damage
                    .iter()
                    .find(|d| matches!(d.kind, DamageKind::Index | DamageKind::Tail))
                    .map(|d| (d.frame, d.message.clone()))
            });
        if let Some((n, why)) = refusal {
            return Err(archive_error(
                path,
                n,
                format!("refusing to append to a damaged archive: {why}"),
            ));
        }
        // One error bound for all frames: the archive lists one, and a frame quantized
        // more coarsely than the others would break what the archive promises.
        // Compared in world units, to a relative 1e-6: a bound given as text (`2.5e-4`)
        // and one computed from an f32 radius (0.01 × 0.025) are the same bound; the
        // archive's own step is then used, so that its frames keep exactly one.
        let step = 2.0 * options.error_bound;
        let same = |s: f64| (s - step).abs() <= 1e-6 * s.abs().max(step.abs());
        if let Some(f) = reader.frames.iter().find(|f| !same(f.step)) {
            return Err(archive_error(
                path,
                Some(f.number),
                format!(
                    "refusing to append frames with error bound {} to an archive whose frames have error bound {}",
                    options.error_bound,
                    f.step / 2.0
                ),
            ));
        }
        let file = OpenOptions::new()
            .write(true)
            .open(path)
            .map_err(|e| Error::io(path, e))?;
        // Records whose header is damaged keep their index entries, so that they stay
        // reported by frame number.
        let mut index: Vec<(i64, u64)> =
            reader.frames.iter().map(|f| (f.number, f.offset)).collect();
        index.extend(
            reader
                .damage
                .iter()
                .filter_map(|d| Some((d.frame?, d.offset?))),
        );
        index.sort_by_key(|e| e.1);
        let mut options = options.clone();
        if let Some(f) = reader.frames.first() {
            options.error_bound = f.step / 2.0;
        }
        // The old index (and any cut-off record) is cut when the first frame is
        // written: everything before it stays.
        Ok(ArchiveWriter {
            path: path.to_path_buf(),
            version: reader.version,
            file: Some(file),
            options,
            index,
            end: reader.data_end,
            reset: true,
            touched: false,
            created: false,
            closed: false,
        })
    }

    /// The open file, positioned at `end` with nothing after it; a new archive's is
    /// created here, with its header.
    fn file(&mut self) -> Result<&mut File> {
        if self.file.is_none() {
            let mut header = [0u8; HEADER_LEN as usize];
            header[0..8].copy_from_slice(MAGIC);
            header[8..12].copy_from_slice(&self.version.to_le_bytes());
            let mut file = File::create(&self.path).map_err(|e| Error::io(&self.path, e))?;
            if let Err(e) = file.write_all(&header) {
                // No archive rather than half a header.
                drop(file);
                let _ = std::fs::remove_file(&self.path);
                return Err(Error::io(&self.path, e));
            }
            self.file = Some(file);
            self.touched = true;
            self.created = true;
        }
        let file = self.file.as_mut().expect("created above");
        if self.reset {
            self.touched = true;
            file.set_len(self.end)
                .and_then(|_| file.seek(SeekFrom::Start(self.end)))
                .map_err(|e| Error::io(&self.path, e))?;
            self.reset = false;
        }
        Ok(file)
    }

    /// Writes `parts` at `end`; on failure the next write (or the index) cuts what was
    /// written of them.
    fn write_at_end(&mut self, parts: &[&[u8]]) -> Result<()> {
        let file = self.file()?;
        let written = parts.iter().try_for_each(|p| file.write_all(p));
        if let Err(e) = written {
            self.reset = true;
            return Err(Error::io(&self.path, e));
        }
        Ok(())
    }

    /// False for a new archive before its first frame (its file is not yet written).
    pub fn is_started(&self) -> bool {
        self.file.is_some()
    }

    /// Frame numbers already in the archive.
    pub fn frame_numbers(&self) -> Vec<i64> {
        self.index.iter().map(|e| e.0).collect()
    }

    /// Appends one mesh as frame `number`; returns its bytes in the archive.
    pub fn append(&mut self, number: i64, mesh: &TriMesh) -> Result<u64> {
        self.append_frame(
            number,
            &ArchiveFrame {
                fluid: mesh,
                subdivision_levels: 0,
                spheres: &SphereInstances::default(),
            },
        )
    }

    /// Appends one frame: a fluid surface (possibly as a Loop control mesh, subdivided
    /// on decoding) and sphere instances, with their attributes (the fluid's one item per
    /// vertex, the spheres' one per centre; values within
    /// [`ArchiveOptions::attribute_error_bound`]). Returns its bytes in the archive.
    ///
    /// The first frame with attributes makes a version-2 or -3 archive version 4 (the
    /// header's version field is rewritten before the record is written); a version-1
    /// archive cannot store attributes and refuses such a frame.
    pub fn append_frame(&mut self, number: i64, frame: &ArchiveFrame) -> Result<u64> {
        let input = format!("{}: frame {number}", self.path.display());
        crate::error::guard(move || input, || self.append_frame_unguarded(number, frame))
    }

    fn append_frame_unguarded(&mut self, number: i64, frame: &ArchiveFrame) -> Result<u64> {
        if self.index.iter().any(|e| e.0 == number) {
            return Err(archive_error(
                &self.path,
                Some(number),
                "the archive already holds this frame",
            ));
        }
        if frame.subdivision_levels > MAX_SUBDIVISION_LEVELS {
            return Err(archive_error(
                &self.path,
                Some(number),
                format!(
                    "{} subdivision levels; an archive stores at most {MAX_SUBDIVISION_LEVELS}",
                    frame.subdivision_levels
                ),
            ));
        }
        let step = 2.0 * self.options.error_bound;
        let level = self.options.zstd_level;
        let with_attributes = frame::has_attributes(frame);
        if with_attributes {
            let attribute_step = 2.0 * self.options.attribute_error_bound;
            let instances = frame::stored_instances(frame.spheres);
            attributes::check(
                &frame.fluid.attributes,
                frame.fluid.vertex_count(),
                "fluid vertices",
                attribute_step,
            )
            .and_then(|_| {
                if instances == 0 {
                    return Ok(());
                }
                attributes::check(
                    &frame.spheres.attributes,
                    instances,
                    "sphere instances",
                    attribute_step,
                )
            })
            .map_err(|m| archive_error(&self.path, Some(number), m))?;
            if self.version == 1 {
                return Err(archive_error(
                    &self.path,
                    Some(number),
                    "a version-1 archive cannot store attributes (write a new archive)",
                ));
            }
        }
        // The archive's version once this frame is in it: the header is rewritten only
        // when the frame is encoded, so that a frame that fails changes nothing.
        let version = if with_attributes {
            self.version.max(ATTRIBUTES_VERSION)
        } else {
            self.version
        };
        let encoded = if version == 1 {
            // An old archive keeps its format: one plain mesh per frame.
            let mut merged = frame.fluid.clone();
            crate::subdivision::subdivide(
                &mut merged,
                &crate::subdivision::SubdivideOptions {
                    levels: frame.subdivision_levels,
                },
            );
            if !frame.spheres.centers.is_empty() {
                merged.append(&frame.spheres.merged());
            }
            codec::encode_v1(&merged, step, level).map(|(payload, vertices, triangles)| {
                frame::EncodedFrame {
                    payload,
                    vertices,
                    triangles,
                    flags: 0,
                }
            })
        } else {
            frame::encode_frame(
                frame,
                step,
                self.options.attribute_error_bound,
                level,
                version >= 3,
            )
        }
        .map_err(|e| Error::io(&self.path, e))?;
        if version != self.version {
            // A file not yet written gets the version in its header when it is.
            if self.file.is_none() {
                self.version = version;
            }
            let end = self.end;
            let file = self.file()?;
            let rewritten = file
                .seek(SeekFrom::Start(8))
                .and_then(|_| file.write_all(&version.to_le_bytes()))
                .and_then(|_| file.seek(SeekFrom::Start(end)));
            if let Err(e) = rewritten {
                self.reset = true;
                return Err(Error::io(&self.path, e));
            }
            self.version = version;
        }
        let payload = encoded.payload;
        let header = RecordHeader {
            number,
            vertices: encoded.vertices,
            triangles: encoded.triangles,
            step,
            payload_len: payload.len() as u64,
            payload_crc: crc32fast::hash(&payload),
            flags: encoded.flags,
        };
        self.write_at_end(&[&header.to_bytes(), &payload])?;
        self.index.push((number, self.end));
        let bytes = (RECORD_HEADER_LEN + payload.len()) as u64;
        self.end += bytes;
        Ok(bytes)
    }

    /// Writes the index and trailer and closes the archive (a new archive without
    /// frames is written too). A writer dropped without `finish` does the same, as far
    /// as it can, but cannot report an error: see [`ArchiveWriter`].
    pub fn finish(mut self) -> Result<()> {
        let input = self.path.display().to_string();
        crate::error::guard(move || input, || self.close())
    }

    /// Cuts anything after the last complete record and writes the index and trailer
    /// there; once only.
    fn close(&mut self) -> Result<()> {
        self.closed = true;
        self.reset = true;
        let index = index_bytes(&self.index, self.end);
        self.write_at_end(&[&index])?;
        self.file()?
            .sync_all()
            .map_err(|e| Error::io(&self.path, e))
    }
}

impl Drop for ArchiveWriter {
    /// Finishes an archive left unfinished by an error, an interruption or a panic: see
    /// [`ArchiveWriter`].
    fn drop(&mut self) {
        if self.closed || !self.touched {
            // Finished, or nothing written: the file is as it was (a new archive does
            // not exist).
            return;
        }
        if self.created && self.index.is_empty() {
            // A new archive whose first frame was never complete: no archive.
            self.file = None;
            let _ = std::fs::remove_file(&self.path);
            return;
        }
        // Errors cannot be reported here; the frames are still found by a scan.
        let _ = self.close();
    }
}

/// The index of `entries` (frame, record offset) at offset `end`, and the trailer.
fn index_bytes(entries: &[(i64, u64)], end: u64) -> Vec<u8> {
    let mut index = Vec::with_capacity(12 + 16 * entries.len() + 20);
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

#[cfg(test)]
mod tests;
