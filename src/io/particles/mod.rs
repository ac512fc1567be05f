//! Particle readers and writers.
//!
//! | format | extension | read | write |
//! |---|---|---|---|
//! | raw positions | `.xyz` | little-endian f32 triples, memory-mapped | yes |
//! | legacy VTK | `.vtk` | ASCII and BINARY (big-endian), POLYDATA / UNSTRUCTURED_GRID / any dataset with `POINTS`, float or double; `POINT_DATA` SCALARS / VECTORS / NORMALS / FIELD kept as attributes | binary POLYDATA |
//! | PLY | `.ply` | ASCII, binary LE / BE; `vertex` x, y, z of any scalar type; other vertex properties kept | binary LE |
//! | Houdini classic BGEO | `.bgeo`, `.bgeo.gz` | version 5 as partio / SPlisHSPlasH write it, plain or gzip (detected by content); float, int and vector point attributes | — |
//! | VTK XML | `.vtu`, `.vtp` | UnstructuredGrid / PolyData; ascii, inline binary, appended raw or base64; zlib or LZ4 blocks; UInt32 / UInt64 headers; point data kept as attributes | appended raw |
//!
//! Positions are world units as stored. Every reader rejects empty files
//! ([`Error::EmptyInput`]), truncated data, non-finite coordinates and malformed headers
//! with a [`Error::Parse`] naming the file and the line or byte offset.
//!
//! One file per format (`xyz.rs`, `vtk.rs`, `ply.rs`, `bgeo.rs`, `vtk_xml/`), each implementing
//! `ParticleCodec`: the whole-file reader, the streaming reader (chunks from disk, for
//! tiled runs: [`SpooledParticles`], [`stream_positions`]) and the writer. A new format is
//! such a file plus its lines in [`ParticleFormat`] (variant, extension, name, codec).
//! `records.rs` holds the chunked decoders the streaming readers share; `source.rs` and
//! `spool.rs` the particle sources a run reads from.

mod bgeo;
mod ply;
mod records;
mod source;
mod spool;
mod vtk;
mod vtk_scan;
mod vtk_xml;
mod xyz;

pub use source::{MappedXyz, ParticleChunk, ParticleSlices, ParticleSource};
pub use spool::SpooledParticles;
pub(crate) use vtk_xml::pvd::{datasets as collection_datasets, DataSetEntry};

use crate::error::{Error, Result};
use glam::Vec3;
use std::path::Path;

pub use crate::attributes::Attribute;
use crate::attributes::{check_attribute, AttributeLayout, AttributeSelection};

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
    /// VTK XML UnstructuredGrid (`.vtu`); the reader takes PolyData too.
    Vtu,
    /// VTK XML PolyData (`.vtp`); the reader takes UnstructuredGrid too.
    Vtp,
}

const SUPPORTED: &str = "supported: .xyz, .vtk, .vtu, .vtp, .ply, .bgeo, .bgeo.gz (or name the format: xyz, vtk, vtu, vtp, ply, bgeo)";

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
        } else if name.ends_with(".vtu") {
            ParticleFormat::Vtu
        } else if name.ends_with(".vtp") {
            ParticleFormat::Vtp
        } else {
            return Err(Error::UnsupportedFormat {
                path: path.to_path_buf(),
                message: format!("unknown particle file extension; {SUPPORTED}"),
            });
        };
        Ok(format)
    }

    /// The reader and writer of the format.
    pub(crate) fn codec(self) -> &'static dyn ParticleCodec {
        match self {
            ParticleFormat::Xyz => &xyz::Xyz,
            ParticleFormat::Vtk => &vtk::Vtk,
            ParticleFormat::Ply => &ply::Ply,
            ParticleFormat::Bgeo => &bgeo::Bgeo,
            ParticleFormat::Vtu => &vtk_xml::VtkXml { polydata: false },
            ParticleFormat::Vtp => &vtk_xml::VtkXml { polydata: true },
        }
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
            "vtu" => Ok(ParticleFormat::Vtu),
            "vtp" => Ok(ParticleFormat::Vtp),
            other => Err(format!("unknown particle format {other:?}; {SUPPORTED}")),
        }
    }
}

/// What each particle format provides: one implementation per file of this module.
pub(crate) trait ParticleCodec: Sync {
    /// Reads the whole file: positions and every point attribute, in file order. The
    /// caller checks the positions (some, all finite).
    fn read(&self, path: &Path) -> Result<Particles>;

    /// Streams the file from disk front to back: once the header is read,
    /// [`StreamSink::select`] picks among the attributes it declares; the positions and the
    /// selected attributes' values then go to `sink` in chunks of at most 65 536 particles.
    /// Returns the particle count, or `Ok(None)` when this file's layout does not stream
    /// (before anything reaches `sink`): the whole-file reader then reads it and reports
    /// on it. Memory: one chunk (and, for ASCII, one line), whatever the file size.
    fn stream(&self, path: &Path, sink: &mut dyn StreamSink) -> Result<Option<usize>>;

    /// Writes positions and the attributes the format holds, atomically.
    fn write(&self, path: &Path, particles: &Particles) -> Result<()>;
}

/// Receives what a streaming reader ([`ParticleCodec::stream`]) decodes, in file order.
pub(crate) trait StreamSink {
    /// The header is read: it announces `count` particles and declares the attributes
    /// `declared`, in file order. Returns the indices of those to stream, in payload order.
    fn select(&mut self, count: usize, declared: &[AttributeLayout]) -> Result<Vec<usize>>;

    /// Consecutive particles: positions (checked finite) and their payload rows, the
    /// selected attributes interleaved in selection order (empty without a selection, or
    /// when the format sends the attributes as arrays after the positions).
    fn records(&mut self, positions: &[Vec3], rows: &[f32]) -> Result<()>;

    /// Consecutive values of selected attribute `k` (an index into the selection), from
    /// the first particle on: for formats whose arrays follow the positions (VTK), each
    /// attribute whole before the next.
    fn array(&mut self, k: usize, rows: &[f32]) -> Result<()>;
}

/// A [`StreamSink`] of positions alone.
struct PositionsOnly<'a>(&'a mut dyn FnMut(&[Vec3]) -> Result<()>);

impl StreamSink for PositionsOnly<'_> {
    fn select(&mut self, _: usize, _: &[AttributeLayout]) -> Result<Vec<usize>> {
        Ok(Vec::new())
    }
    fn records(&mut self, positions: &[Vec3], _: &[f32]) -> Result<()> {
        (self.0)(positions)
    }
    fn array(&mut self, _: usize, _: &[f32]) -> Result<()> {
        Ok(())
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
    let particles = format.codec().read(path)?;
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
    format.codec().write(path, particles)
}

/// Streams the positions of a particle file from disk in chunks of at most 65 536
/// particles, decompressing as it goes; attributes are skipped. The format comes from
/// `format` or the extension. Streams: BGEO (plain or gzip); PLY, binary or ASCII, whose
/// first element is `vertex` of scalar properties (the rows of any later element are
/// walked and checked); legacy VTK, binary or ASCII, whose sections the reader knows (a
/// first pass finds the points, seeking over binary blocks and parsing ASCII values); VTK
/// XML (`.vtu`, `.vtp`) of one piece, in any encoding (every array is decoded, the points
/// kept). A file the stream takes is one [`read_particles`] takes, with the same
/// positions: damage anywhere, also in what a run does not use, and a file of no particle
/// are errors for both. Returns the particle count, or `Ok(None)` for any other layout,
/// which [`read_particles`] handles and reports on (and for `.xyz`, which [`MappedXyz`]
/// maps as it is). Memory: one chunk (and, for ASCII, one line), whatever the file size.
pub fn stream_positions(
    path: &Path,
    format: Option<ParticleFormat>,
    positions: &mut dyn FnMut(&[Vec3]) -> Result<()>,
) -> Result<Option<usize>> {
    let format = match format {
        Some(f) => f,
        None => ParticleFormat::from_path(path)?,
    };
    let count = format.codec().stream(path, &mut PositionsOnly(positions))?;
    if count == Some(0) {
        return Err(Error::EmptyInput {
            path: path.to_path_buf(),
        });
    }
    Ok(count)
}

/// The bytes of a whole particle file; an empty file is [`Error::EmptyInput`].
fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    if bytes.is_empty() {
        return Err(Error::EmptyInput {
            path: path.to_path_buf(),
        });
    }
    Ok(bytes)
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
