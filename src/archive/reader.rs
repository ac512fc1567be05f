//! Reading an archive: opening it through its index or, after an interrupted append, by
//! scanning its records (naming what is damaged), then decoding frames by number,
//! extracting them to mesh files and verifying every one.

use super::attributes::{self, AttributeInfo};
use super::codec;
use super::container::{
    archive_error, claimed_frame, is_cut_off_record_or_index, read_index, scan_records,
    true_payload_end, walk_end, RecordHeader, Span, HEADER_LEN, MAGIC, MAX_STEP, RECORD_HEADER_LEN,
    SCALES_VERSION,
};
use super::frame;
use crate::error::{Error, Result};
use crate::mesh::{SphereInstances, Surface, TriMesh};
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

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
    pub(super) fn of(h: &RecordHeader, offset: usize, bytes: &[u8]) -> FrameInfo {
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

    /// Bytes of the frame's record in the file: its header and payload.
    pub fn record_bytes(&self) -> u64 {
        RECORD_HEADER_LEN as u64 + self.payload_bytes
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
/// Something [`ArchiveReader::open`] found that cannot be read ([`ArchiveReader::unreadable`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Unreadable {
    /// The frame, when the index or an intact record header names it.
    pub frame: Option<i64>,
    /// What is wrong, and where.
    pub message: String,
    /// True when this is the mark of an interrupted write or a truncated file (no index,
    /// a cut-off record or index at the end): the frames before it are whole. False for
    /// damage in the middle of the archive, or an index that disagrees with the records,
    /// where frames the archive holds are lost.
    pub truncation: bool,
}

/// What kind of damage [`ArchiveReader::open`] found outside the frames' payloads.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum DamageKind {
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
pub(super) struct Damage {
    pub(super) kind: DamageKind,
    /// The frame, when the index or a complete record header names it.
    pub(super) frame: Option<i64>,
    /// Record offset, for an index entry whose record header is damaged.
    pub(super) offset: Option<u64>,
    pub(super) message: String,
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
    pub(super) path: PathBuf,
    pub(super) version: u32,
    pub(super) bytes: Vec<u8>,
    pub(super) frames: Vec<FrameInfo>,
    /// Payload CRCs and record flags, parallel to `frames`.
    crcs: Vec<u32>,
    flags: Vec<u32>,
    recovered_by_scan: bool,
    /// Where appending starts: the index offset, or the end of the last complete record.
    pub(super) data_end: u64,
    /// Where a walk of the records before `data_end` says they end: equal
    /// to `data_end` unless the last record's header is damaged or its length field lies.
    pub(super) walk_end: u64,
    /// Damage found while opening (records, tail, index).
    pub(super) damage: Vec<Damage>,
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
        let bytes = Self::read_bytes(path)?;
        let version = Self::header_version(path, &bytes)?;
        Ok(Self::with_bytes(path, bytes, version))
    }

    fn read_bytes(path: &Path) -> Result<Vec<u8>> {
        let mut bytes = Vec::new();
        File::open(path)
            .and_then(|mut f| f.read_to_end(&mut bytes))
            .map_err(|e| Error::io(path, e))?;
        Ok(bytes)
    }

    /// The version the file header of `bytes` gives; an error when its magic number or
    /// version is not one of an archive this build reads.
    fn header_version(path: &Path, bytes: &[u8]) -> Result<u32> {
        if bytes.len() < HEADER_LEN as usize || &bytes[0..8] != MAGIC {
            return Err(archive_error(
                path,
                None,
                "not a meniscus .mseq archive (bad magic number)",
            ));
        }
        let version = u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes"));
        if !(1..=SCALES_VERSION).contains(&version) {
            return Err(Error::UnsupportedFormat {
                path: path.to_path_buf(),
                message: format!(
                    ".mseq version {version}; this build reads versions 1 to {SCALES_VERSION}"
                ),
            });
        }
        Ok(version)
    }

    /// For `archive repair`: [`ArchiveReader::open`], and when the file header's magic
    /// number or version is damaged (not an archive's, or a valid version under which not
    /// even the first frame decodes) but the records and the index after it are sound
    /// under another (every record whole, the index agreeing, every frame decoding), the
    /// archive with the header rebuilt: the version the records need (5 with sphere
    /// scales, 4 with attributes, else 3, or 1 when the frames decode only as version 1).
    /// Says what it rebuilt.
    pub(super) fn open_rebuilding_header(path: &Path) -> Result<(ArchiveReader, Option<String>)> {
        let bytes = Self::read_bytes(path)?;
        let (refused, bytes) = match Self::header_version(path, &bytes) {
            Ok(version) => {
                let reader = Self::with_bytes(path, bytes, version);
                let first_fails = !reader.frames.is_empty() && reader.decode(0).is_err();
                if !first_fails {
                    return Ok((reader, None));
                }
                let ArchiveReader { bytes, .. } = reader;
                (None, bytes)
            }
            Err(e) if bytes.len() >= HEADER_LEN as usize => (Some(e), bytes),
            Err(e) => return Err(e),
        };
        let limit = read_index(&bytes).map_or(bytes.len(), |i| i.offset);
        let flags = scan_records(&bytes, limit).iter().fold(0, |f, s| match s {
            Span::Record(_, h) => f | h.flags,
            Span::Damaged(..) => f,
        });
        let needed = if flags & frame::HAS_SCALES != 0 {
            SCALES_VERSION
        } else if flags & attributes::HAS_ATTRIBUTES != 0 {
            super::container::ATTRIBUTES_VERSION
        } else {
            super::container::VERSION
        };
        let what = if &bytes[0..8] != MAGIC {
            "magic number"
        } else {
            "version"
        };
        let original: [u8; HEADER_LEN as usize] =
            bytes[..HEADER_LEN as usize].try_into().expect("16 bytes");
        let mut bytes = bytes;
        for version in [needed, 1] {
            bytes[..HEADER_LEN as usize].copy_from_slice(&super::container::file_header(version));
            let reader = Self::with_bytes(path, bytes, version);
            let sound =
                reader.damage.is_empty() && !reader.frames.is_empty() && reader.verify().is_clean();
            if sound {
                let message = format!(
                    "the file header's {what} is damaged; the {} frame(s) and the index after it are sound: header rebuilt as version {version}",
                    reader.frames.len()
                );
                return Ok((reader, Some(message)));
            }
            bytes = reader.bytes;
        }
        match refused {
            Some(e) => Err(e),
            None => {
                // The header as it was: the frames are damaged, not the header.
                bytes[..HEADER_LEN as usize].copy_from_slice(&original);
                let version = Self::header_version(path, &bytes)?;
                Ok((Self::with_bytes(path, bytes, version), None))
            }
        }
    }

    fn with_bytes(path: &Path, bytes: Vec<u8>, version: u32) -> ArchiveReader {
        let mut reader = ArchiveReader {
            path: path.to_path_buf(),
            version,
            bytes,
            frames: Vec::new(),
            crcs: Vec::new(),
            flags: Vec::new(),
            recovered_by_scan: false,
            data_end: HEADER_LEN,
            walk_end: HEADER_LEN,
            damage: Vec::new(),
        };
        match read_index(&reader.bytes) {
            Some(index) => reader.use_index(index.offset, &index.entries),
            None => reader.scan(),
        }
        reader
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
        let at: std::collections::HashMap<u64, &Span> =
            spans.iter().map(|s| (s.start() as u64, s)).collect();
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
                            message: self.damaged_record_message(offset as usize),
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
        self.walk_end = walk_end(&spans) as u64;
    }

    /// What is wrong with the record the index lists at `offset`, where the walk of the
    /// records found no complete record.
    fn damaged_record_message(&self, offset: usize) -> String {
        let header = self
            .bytes
            .get(offset..offset + RECORD_HEADER_LEN)
            .and_then(RecordHeader::parse);
        match header {
            Some(h) => format!(
                "the record header at offset {offset} claims a payload of {} bytes, which does not end where the next record or the index starts (its length field is damaged)",
                h.payload_len
            ),
            None => {
                format!("record header at offset {offset} is damaged (checksum mismatch or cut off)")
            }
        }
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
                    self.walk_end = self.data_end;
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
                    let (kind, frame, message) = if let Some(h) = header
                        .as_ref()
                        .filter(|h| true_payload_end(&self.bytes, p, h, limit).is_some())
                    {
                        // Not cut off: the payload is all there, its length field lies.
                        (
                            DamageKind::Tail,
                            Some(h.number),
                            format!(
                                "the record header at offset {p} claims a payload of {} bytes, but the {} bytes after it hold the payload its checksum gives (its length field is damaged)",
                                h.payload_len,
                                tail.len() - RECORD_HEADER_LEN
                            ),
                        )
                    } else if let Some(h) = header {
                        (
                            DamageKind::CutTail,
                            Some(h.number),
                            format!(
                                "record at offset {p} cut off: its payload needs {} bytes, {} are present (truncated archive)",
                                h.payload_len,
                                tail.len() - RECORD_HEADER_LEN
                            ),
                        )
                    } else if is_cut_off_record_or_index(tail) {
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

    /// What opening the archive found that cannot be read, in file order: frames the
    /// index or a record header names but whose record is damaged, stretches of bytes
    /// that hold no complete record, an index that disagrees with the records, a missing
    /// index or a cut-off end. Empty for a sound archive. Reading commands report these
    /// (their listings and extractions leave those frames out).
    pub fn unreadable(&self) -> Vec<Unreadable> {
        self.damage
            .iter()
            .map(|d| Unreadable {
                frame: d.frame,
                message: d.message.clone(),
                truncation: matches!(d.kind, DamageKind::NoIndex | DamageKind::CutTail),
            })
            .collect()
    }

    /// The frames, in file order.
    pub fn frames(&self) -> &[FrameInfo] {
        &self.frames
    }

    /// True when the index was missing or damaged and the frames come from a scan.
    pub fn recovered_by_scan(&self) -> bool {
        self.recovered_by_scan
    }

    /// Format version of the file (1 to 5; 4 when a frame stores attributes, 5 when a
    /// frame stores sphere scales).
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
                    .map_or_else(|| self.absent_frame_message(), |d| d.message.clone());
                archive_error(&self.path, Some(number), why)
            })?;
        self.decode(k)
    }

    /// Why a frame number is not in the archive: which frames are.
    pub fn absent_frame_message(&self) -> String {
        let mut held: Vec<i64> = self.frames.iter().map(|f| f.number).collect();
        held.sort_unstable();
        held.dedup();
        match held.len() {
            0 => "no such frame: the archive holds no frames".to_string(),
            n => format!(
                "no such frame in the archive; it holds {n} frame(s): {}",
                crate::sequence::number_ranges(&held)
            ),
        }
    }

    fn decode(&self, k: usize) -> Result<Surface> {
        self.decode_record(&self.frames[k], self.crcs[k], self.flags[k])
    }

    /// Decodes the record `f` describes, whose header gives the payload checksum `crc`
    /// and `flags`.
    pub(super) fn decode_record(&self, f: &FrameInfo, crc: u32, flags: u32) -> Result<Surface> {
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
        if crc32fast::hash(payload) != crc {
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
        let scaled = flags & frame::HAS_SCALES != 0;
        let known = attributes::HAS_ATTRIBUTES
            | if self.version >= SCALES_VERSION {
                frame::HAS_SCALES
            } else {
                0
            };
        match (self.version, flags) {
            (1, 0) => codec::decode_v1(payload, vertices, triangles, f.step).map(|fluid| Surface {
                fluid,
                spheres: SphereInstances::default(),
            }),
            (2.., _) if flags & !known == 0 && flags & attributes::HAS_ATTRIBUTES == 0 => {
                frame::decode_frame(payload, vertices, triangles, f.step, None, scaled)
            }
            (2.., _) if flags & !known == 0 => attributes::split(payload).and_then(|s| {
                frame::decode_frame(
                    s.geometry,
                    vertices,
                    triangles,
                    f.step,
                    Some((&s.descriptor, s.streams)),
                    scaled,
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
        // A frame number held by several records reads as the first of them: damage,
        // never listed as good.
        let mut records: std::collections::HashMap<i64, usize> = Default::default();
        for f in &self.frames {
            *records.entry(f.number).or_default() += 1;
        }
        for (f, outcome) in self.frames.iter().zip(outcomes) {
            match (outcome, records.get_mut(&f.number)) {
                (_, Some(0)) => {}
                (_, Some(n)) if *n > 1 => {
                    report.damaged.push((
                        f.number,
                        format!(
                            "{n} records of this frame number (the first at offset {}): the archive is damaged",
                            f.offset
                        ),
                    ));
                    *n = 0;
                }
                (None, _) => report.good.push(f.number),
                (Some(e), _) => report.damaged.push((f.number, e)),
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
