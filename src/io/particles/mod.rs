//! Particle readers and writers.
//!
//! | format | extension | read | write |
//! |---|---|---|---|
//! | raw positions | `.xyz` | little-endian f32 triples, memory-mapped | yes |
//! | legacy VTK | `.vtk` | ASCII and BINARY (big-endian), POLYDATA / UNSTRUCTURED_GRID / any dataset with `POINTS`, float or double; `POINT_DATA` SCALARS / VECTORS / NORMALS / FIELD kept as attributes | binary POLYDATA |
//! | PLY | `.ply` | ASCII, binary LE / BE; `vertex` x, y, z of any scalar type; other vertex properties kept | binary LE |
//! | Houdini classic BGEO | `.bgeo`, `.bgeo.gz` | version 5 as partio / SPlisHSPlasH write it, plain or gzip (detected by content); float, int and vector point attributes | — |
//!
//! Positions are world units as stored. Every reader rejects empty files
//! ([`Error::EmptyInput`]), truncated data, non-finite coordinates and malformed headers
//! with a [`Error::Parse`] naming the file and the line or byte offset.

pub(crate) mod bgeo;
pub(crate) mod ply;
mod source;
pub(crate) mod vtk;
mod xyz;

pub use source::{MappedXyz, ParticleChunk, ParticleSlices, ParticleSource, SpooledParticles};

pub use bgeo::stream_positions as stream_bgeo_positions;
pub use ply::stream_positions as stream_ply_positions;
pub use vtk::stream_positions as stream_vtk_positions;

use crate::error::{Error, Result};
use glam::Vec3;
use std::path::Path;

pub use crate::attributes::Attribute;
use crate::attributes::{check_attribute, AttributeSelection};

/// The particles of one frame: positions in world units plus optional attributes.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Particles {
    /// Particle centres, world units.
    pub positions: Vec<Vec3>,
    /// Other point attributes found in the file, in file order.
    pub attributes: Vec<Attribute>,
}

impl Particles {
    /// Keeps the attributes that `selection` asks for, in its order, after checking each:
    /// `components × particles` values, all finite. `path` names the input in errors. A
    /// name the input lacks (or selected twice) is an [`Error::Attribute`] listing the
    /// names it has; the streaming readers select by the same rule.
    pub fn select(mut self, path: &Path, selection: &AttributeSelection) -> Result<Particles> {
        let available: Vec<&str> = self.attributes.iter().map(|a| a.name.as_str()).collect();
        let wanted = selection.resolve(path, &available)?;
        let count = self.positions.len();
        let mut columns: Vec<Option<Attribute>> = std::mem::take(&mut self.attributes)
            .into_iter()
            .map(Some)
            .collect();
        for k in wanted {
            let a = columns[k].take().expect("each selected once");
            check_attribute(path, &a, count)?;
            self.attributes.push(a);
        }
        Ok(self)
    }
}

/// Particle file formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum ParticleFormat {
    /// Raw little-endian f32 triples.
    Xyz,
    /// Legacy VTK.
    Vtk,
    /// Stanford PLY.
    Ply,
    /// Houdini classic BGEO (plain or gzip).
    Bgeo,
}

const SUPPORTED: &str =
    "supported: .xyz, .vtk, .ply, .bgeo, .bgeo.gz (or name the format: xyz, vtk, ply, bgeo)";

impl ParticleFormat {
    /// The format named by a file's extension.
    pub fn from_path(path: &Path) -> Result<Self> {
        let name = path
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or_default()
            .to_ascii_lowercase();
        let format = if name.ends_with(".xyz") {
            ParticleFormat::Xyz
        } else if name.ends_with(".vtk") {
            ParticleFormat::Vtk
        } else if name.ends_with(".ply") {
            ParticleFormat::Ply
        } else if name.ends_with(".bgeo") || name.ends_with(".bgeo.gz") {
            ParticleFormat::Bgeo
        } else {
            return Err(Error::UnsupportedFormat {
                path: path.to_path_buf(),
                message: format!("unknown particle file extension; {SUPPORTED}"),
            });
        };
        Ok(format)
    }
}

impl std::str::FromStr for ParticleFormat {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "xyz" => Ok(ParticleFormat::Xyz),
            "vtk" => Ok(ParticleFormat::Vtk),
            "ply" => Ok(ParticleFormat::Ply),
            "bgeo" | "bgeo.gz" => Ok(ParticleFormat::Bgeo),
            other => Err(format!("unknown particle format {other:?}; {SUPPORTED}")),
        }
    }
}

/// Reads the particles of one file; the format comes from `format` or the extension.
pub fn read_particles(path: &Path, format: Option<ParticleFormat>) -> Result<Particles> {
    let input = path.display().to_string();
    crate::error::guard(move || input, || read_particles_unguarded(path, format))
}

fn read_particles_unguarded(path: &Path, format: Option<ParticleFormat>) -> Result<Particles> {
    let format = match format {
        Some(f) => f,
        None => ParticleFormat::from_path(path)?,
    };
    let particles = match format {
        ParticleFormat::Xyz => xyz::read(path)?,
        other => {
            let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
            if bytes.is_empty() {
                return Err(Error::EmptyInput {
                    path: path.to_path_buf(),
                });
            }
            match other {
                ParticleFormat::Vtk => vtk::read(path, &bytes)?,
                ParticleFormat::Ply => ply::read(path, &bytes)?,
                ParticleFormat::Bgeo => bgeo::read(path, &bytes)?,
                ParticleFormat::Xyz => unreachable!(),
            }
        }
    };
    if particles.positions.is_empty() {
        return Err(Error::EmptyInput {
            path: path.to_path_buf(),
        });
    }
    check_finite(path, &particles.positions)?;
    Ok(particles)
}

/// Writes particles (positions and attributes where the format holds them), atomically.
pub fn write_particles(path: &Path, particles: &Particles, format: ParticleFormat) -> Result<()> {
    match format {
        ParticleFormat::Xyz => xyz::write(path, particles),
        ParticleFormat::Vtk => vtk::write(path, particles),
        ParticleFormat::Ply => ply::write(path, particles),
        ParticleFormat::Bgeo => Err(Error::UnsupportedFormat {
            path: path.to_path_buf(),
            message: "writing BGEO is not supported; write .xyz, .vtk or .ply".into(),
        }),
    }
}

/// Records decoded per chunk by the streaming readers.
const CHUNK_RECORDS: usize = 1 << 16;

/// Where the fixed-size records of a binary file are, and what they are called in error
/// messages ("particle"/"points").
struct Records {
    /// Byte offset of the first record in the file.
    offset: u64,
    count: usize,
    /// Bytes per record.
    stride: usize,
    one: &'static str,
    many: &'static str,
}

/// Opens `path` for the streaming readers, with a 1 MiB buffer.
fn open_buffered(path: &Path) -> Result<std::io::BufReader<std::fs::File>> {
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    Ok(std::io::BufReader::with_capacity(1 << 20, file))
}

/// The error of a stream that ends before its `count` `many` (e.g. "points").
fn truncated(count: usize, many: &str) -> String {
    format!("truncated while reading the {count} {many}: the file ends first")
}

/// The error for a non-finite position at `location` of `path`.
fn non_finite(path: &Path, location: String, p: Vec3) -> Error {
    Error::parse(path, location, format!("non-finite coordinate {p}"))
}

/// Takes a record's position (when it holds one) and appends its payload values to the
/// row buffer: the decoder of [`stream_records`].
type Decode<'a> = &'a dyn Fn(&[u8], &mut Vec<f32>) -> Option<Vec3>;

/// Receives consecutive records: their positions (empty when the records hold none) and
/// their payload rows, row-major.
pub(crate) type RecordSink<'a> = dyn FnMut(&[Vec3], &[f32]) -> Result<()> + 'a;

/// Reads the records from `reader` (positioned at the first one) in chunks of at most
/// 65 536, decodes each with `decode` (its position, checked finite, and its payload
/// values) and hands the chunks to `sink`. Memory: one chunk.
fn stream_records(
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
struct AsciiRecords<'a> {
    line: usize,
    count: usize,
    fields: usize,
    xyz: Option<[usize; 3]>,
    payload: &'a [usize],
    one: &'static str,
    many: &'static str,
}

/// [`stream_records`] for ASCII files: reads line by line from `reader` (positioned at the
/// first record), parses numbers like the whole-file readers (as f64, then rounded to
/// f32) and hands chunks of at most 65 536 records to `sink`. Memory: one line and one
/// chunk. What follows the last record is not read.
fn stream_ascii_records(
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

fn check_finite(path: &Path, positions: &[Vec3]) -> Result<()> {
    match positions.iter().position(|p| !p.is_finite()) {
        None => Ok(()),
        Some(i) => Err(Error::parse(
            path,
            format!("particle {i}"),
            format!("non-finite coordinate {}", positions[i]),
        )),
    }
}
