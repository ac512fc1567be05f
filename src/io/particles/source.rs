//! Where a run reads particles from: positions (and their payload: the selected
//! attributes) in memory, or a raw `.xyz` file mapped window by window, so that a scene
//! larger than memory is never held whole.
//!
//! A [`ParticleSource`] is visited front to back, in input order, a chunk at a time; the
//! tile engine visits it at most twice (bounds and tile histogram, then binning into a
//! spill file).

use super::{Attribute, Particles};
use crate::attributes::AttributeLayout;
use crate::cancel::CancelToken;
use crate::error::{Error, Result};
use glam::Vec3;
use std::path::{Path, PathBuf};

/// Consecutive particles of a source: input index of the first, positions, and their
/// payload, row-major (`width` floats per particle, the source's
/// [`ParticleSource::attribute_layout`] in order).
#[derive(Clone, Copy, Debug)]
pub struct ParticleChunk<'a> {
    /// Input index of the first particle.
    pub first: usize,
    /// Positions, world units.
    pub positions: &'a [Vec3],
    /// Payload rows, `width × positions.len()` floats (empty without attributes).
    pub payload: &'a [f32],
}

/// Particles read in input order, a chunk at a time, with their payload.
pub trait ParticleSource {
    /// Number of particles.
    fn particle_count(&self) -> usize;
    /// The attributes every particle carries as payload, in row order (empty: positions
    /// only).
    fn attribute_layout(&self) -> Vec<AttributeLayout> {
        Vec::new()
    }
    /// Calls `visit` for consecutive chunks covering every particle in input order; stops
    /// at the first error.
    fn visit_chunks(&self, visit: &mut dyn FnMut(ParticleChunk<'_>) -> Result<()>) -> Result<()>;
    /// All positions and payload rows when they already are in memory (lets an untiled
    /// run skip a copy).
    fn as_slices(&self) -> Option<(&[Vec3], &[f32])> {
        None
    }
}

/// Positions in memory (`&[Vec3]`, `Vec<Vec3>`, `&Vec<Vec3>`), no payload.
impl<T: AsRef<[Vec3]>> ParticleSource for T {
    fn particle_count(&self) -> usize {
        self.as_ref().len()
    }
    fn visit_chunks(&self, visit: &mut dyn FnMut(ParticleChunk<'_>) -> Result<()>) -> Result<()> {
        for (n, chunk) in self.as_ref().chunks(CHUNK_PARTICLES).enumerate() {
            visit(ParticleChunk {
                first: n * CHUNK_PARTICLES,
                positions: chunk,
                payload: &[],
            })?;
        }
        Ok(())
    }
    fn as_slices(&self) -> Option<(&[Vec3], &[f32])> {
        Some((self.as_ref(), &[]))
    }
}

/// Positions with every attribute of the [`Particles`] as payload (select first with
/// [`crate::attributes::select_attributes`] to carry fewer).
impl ParticleSource for Particles {
    fn particle_count(&self) -> usize {
        self.positions.len()
    }
    fn attribute_layout(&self) -> Vec<AttributeLayout> {
        self.attributes.iter().map(AttributeLayout::of).collect()
    }
    fn visit_chunks(&self, visit: &mut dyn FnMut(ParticleChunk<'_>) -> Result<()>) -> Result<()> {
        let mut rows = Vec::new();
        for (n, chunk) in self.positions.chunks(CHUNK_PARTICLES).enumerate() {
            let first = n * CHUNK_PARTICLES;
            rows.clear();
            interleave(&self.attributes, first..first + chunk.len(), &mut rows);
            visit(ParticleChunk {
                first,
                positions: chunk,
                payload: &rows,
            })?;
        }
        Ok(())
    }
    fn as_slices(&self) -> Option<(&[Vec3], &[f32])> {
        self.attributes
            .is_empty()
            .then_some((self.positions.as_slice(), &[][..]))
    }
}

/// Appends the rows of `items` of `columns` (item-major attributes) to `rows`.
fn interleave(columns: &[Attribute], items: std::ops::Range<usize>, rows: &mut Vec<f32>) {
    if columns.is_empty() {
        return;
    }
    for i in items {
        for a in columns {
            rows.extend_from_slice(a.item(i));
        }
    }
}

/// Particles per visited chunk.
const CHUNK_PARTICLES: usize = 1 << 20;

/// A raw `.xyz` file (little-endian f32 triples), memory-mapped one window of
/// 2^20 records (12 MiB) at a time: resident memory stays one window, whatever the
/// file size.
pub struct MappedXyz {
    path: PathBuf,
    file: std::fs::File,
    particles: usize,
}

impl MappedXyz {
    /// Opens `path` and checks its size (a whole number of 12-byte records, not empty).
    pub fn open(path: &Path) -> Result<Self> {
        let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
        let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
        if len == 0 {
            return Err(Error::EmptyInput {
                path: path.to_path_buf(),
            });
        }
        if len % 12 != 0 {
            return Err(Error::parse(
                path,
                format!("byte offset {}", len - len % 12),
                format!(
                    "file size {len} is not a multiple of 12 (x, y, z as f32): truncated or not .xyz"
                ),
            ));
        }
        Ok(MappedXyz {
            path: path.to_path_buf(),
            file,
            particles: (len / 12) as usize,
        })
    }
}

impl ParticleSource for MappedXyz {
    fn particle_count(&self) -> usize {
        self.particles
    }
    fn visit_chunks(&self, visit: &mut dyn FnMut(ParticleChunk<'_>) -> Result<()>) -> Result<()> {
        let mut decoded = Vec::with_capacity(CHUNK_PARTICLES.min(self.particles));
        let mut first = 0;
        while first < self.particles {
            let count = CHUNK_PARTICLES.min(self.particles - first);
            // The file may have shrunk since it was opened: mapping past its end would
            // fault on access, so check before every window.
            let len = self
                .file
                .metadata()
                .map_err(|e| Error::io(&self.path, e))?
                .len();
            if len < ((first + count) * 12) as u64 {
                return Err(Error::parse(
                    &self.path,
                    format!("byte offset {len}"),
                    format!(
                        "the file was truncated while being read (expected {} bytes)",
                        self.particles * 12
                    ),
                ));
            }
            // SAFETY: a read-only map of a range checked above to lie within the file,
            // dropped before the next window; a concurrent truncation between the check
            // and the read is outside what any reader can defend against.
            let map = unsafe {
                memmap2::MmapOptions::new()
                    .offset((first * 12) as u64)
                    .len(count * 12)
                    .map(&self.file)
            }
            .map_err(|e| Error::io(&self.path, e))?;
            decoded.clear();
            decoded.extend(map.chunks_exact(12).map(|c| {
                let f = |k: usize| f32::from_le_bytes([c[k], c[k + 1], c[k + 2], c[k + 3]]);
                Vec3::new(f(0), f(4), f(8))
            }));
            drop(map);
            if let Some(k) = decoded.iter().position(|p| !p.is_finite()) {
                return Err(Error::parse(
                    &self.path,
                    format!("byte offset {}", (first + k) * 12),
                    format!("particle {} has a non-finite coordinate", first + k),
                ));
            }
            visit(ParticleChunk {
                first,
                positions: &decoded,
                payload: &[],
            })?;
            first += count;
        }
        Ok(())
    }
}

/// Particles of a file that cannot be mapped as it is (gzip BGEO, binary VTK and PLY),
/// streamed once into a raw `.xyz` temporary file (positions only, 12 bytes per particle) and then read like
/// [`MappedXyz`]: memory stays one chunk while converting and one window while reading,
/// whatever the input size. The temporary file is removed when this is dropped (also on
/// errors and Ctrl-C, as the error unwinds).
pub struct SpooledXyz {
    mapped: MappedXyz,
    _file: tempfile::TempPath,
}

impl SpooledXyz {
    /// Streams the positions of `path` (in `format`) into a temporary file in `temp_dir`
    /// (`None`: the system's temporary directory). Gzip or plain BGEO always streams;
    /// VTK and PLY, binary or ASCII, when their points come first
    /// ([`crate::io::particles::stream_vtk_positions`],
    /// [`crate::io::particles::stream_ply_positions`]); `Ok(None)` otherwise (and for
    /// `.xyz`, which is mapped as it is).
    pub fn from_file(
        path: &Path,
        format: crate::io::particles::ParticleFormat,
        temp_dir: Option<&Path>,
        cancel: &CancelToken,
    ) -> Result<Option<SpooledXyz>> {
        use crate::io::particles::{self as p, ParticleFormat};
        match format {
            ParticleFormat::Xyz => Ok(None),
            ParticleFormat::Bgeo => Self::spool(path, temp_dir, cancel, &mut |sink| {
                p::stream_bgeo_positions(path, sink).map(Some)
            }),
            ParticleFormat::Vtk => Self::spool(path, temp_dir, cancel, &mut |sink| {
                p::stream_vtk_positions(path, sink)
            }),
            ParticleFormat::Ply => Self::spool(path, temp_dir, cancel, &mut |sink| {
                p::stream_ply_positions(path, sink)
            }),
        }
    }

    /// Runs `stream` with a sink that appends to a new temporary `.xyz`, then maps it.
    #[allow(clippy::type_complexity)]
    fn spool(
        path: &Path,
        temp_dir: Option<&Path>,
        cancel: &CancelToken,
        stream: &mut dyn FnMut(&mut dyn FnMut(&[Vec3]) -> Result<()>) -> Result<Option<usize>>,
    ) -> Result<Option<SpooledXyz>> {
        if std::fs::metadata(path)
            .map_err(|e| Error::io(path, e))?
            .len()
            == 0
        {
            return Err(Error::EmptyInput {
                path: path.to_path_buf(),
            });
        }
        let dir = temp_dir
            .map(Path::to_path_buf)
            .unwrap_or_else(std::env::temp_dir);
        let file = tempfile::Builder::new()
            .prefix("meniscus-input-")
            .suffix(".xyz")
            .tempfile_in(&dir)
            .map_err(|e| Error::io(&dir, e))?;
        let spool_path = file.path().to_path_buf();
        let mut writer = std::io::BufWriter::with_capacity(1 << 20, file);
        let mut bytes = Vec::new();
        let count = stream(&mut |chunk| {
            cancel.check()?;
            bytes.clear();
            for p in chunk {
                for c in p.to_array() {
                    bytes.extend_from_slice(&c.to_le_bytes());
                }
            }
            std::io::Write::write_all(&mut writer, &bytes).map_err(|e| Error::io(&spool_path, e))
        })?;
        let Some(count) = count else {
            return Ok(None);
        };
        if count == 0 {
            return Err(Error::EmptyInput {
                path: path.to_path_buf(),
            });
        }
        let file = writer
            .into_inner()
            .map_err(|e| Error::io(&spool_path, e.into_error()))?;
        let temp_path = file.into_temp_path();
        let mapped = MappedXyz::open(&temp_path)?;
        Ok(Some(SpooledXyz {
            mapped,
            _file: temp_path,
        }))
    }
}

impl ParticleSource for SpooledXyz {
    fn particle_count(&self) -> usize {
        self.mapped.particle_count()
    }
    fn visit_chunks(&self, visit: &mut dyn FnMut(ParticleChunk<'_>) -> Result<()>) -> Result<()> {
        self.mapped.visit_chunks(visit)
    }
}
