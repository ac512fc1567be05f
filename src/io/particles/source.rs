//! Where a run reads particles from: positions (and their payload: the selected
//! attributes) in memory, or a raw `.xyz` file mapped window by window, so that a scene
//! larger than memory is never held whole (other formats are spooled into such a file
//! first: `spool.rs`).
//!
//! A [`ParticleSource`] is visited front to back, in input order, a chunk at a time; the
//! tile engine visits it at most twice (bounds and tile histogram, then binning into a
//! spill file).

use super::{Attribute, Particles};
use crate::attributes::AttributeLayout;
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

/// Positions and attributes held by the caller (a [`Particles`], or arrays borrowed from
/// elsewhere: the Python package's numpy arrays), every attribute as payload.
#[derive(Clone, Copy, Debug)]
pub struct ParticleSlices<'a> {
    /// Positions, world units.
    pub positions: &'a [Vec3],
    /// Attributes, one item per position each.
    pub attributes: &'a [Attribute],
}

impl ParticleSource for ParticleSlices<'_> {
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
            interleave(self.attributes, first..first + chunk.len(), &mut rows);
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
            .then_some((self.positions, &[][..]))
    }
}

/// Positions with every attribute of the [`Particles`] as payload (select first with
/// [`Particles::select`] to carry fewer).
impl ParticleSource for Particles {
    fn particle_count(&self) -> usize {
        self.positions.len()
    }
    fn attribute_layout(&self) -> Vec<AttributeLayout> {
        self.slices().attribute_layout()
    }
    fn visit_chunks(&self, visit: &mut dyn FnMut(ParticleChunk<'_>) -> Result<()>) -> Result<()> {
        self.slices().visit_chunks(visit)
    }
    fn as_slices(&self) -> Option<(&[Vec3], &[f32])> {
        self.attributes
            .is_empty()
            .then_some((self.positions.as_slice(), &[][..]))
    }
}

impl Particles {
    /// The positions and attributes as a [`ParticleSlices`].
    pub fn slices(&self) -> ParticleSlices<'_> {
        ParticleSlices {
            positions: &self.positions,
            attributes: &self.attributes,
        }
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
pub(super) const CHUNK_PARTICLES: usize = 1 << 20;

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
        let metadata = file.metadata().map_err(|e| Error::io(path, e))?;
        if metadata.is_dir() {
            return Err(Error::io(
                path,
                std::io::Error::new(
                    std::io::ErrorKind::IsADirectory,
                    "is a directory, not a particle file",
                ),
            ));
        }
        let len = metadata.len();
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
        // A text file renamed .xyz: its first bytes (up to 64) are all digits, blanks,
        // signs, dots and exponents, which raw floats practically never are.
        let mut head = Vec::with_capacity(64);
        std::io::Read::read_to_end(&mut std::io::Read::take(&file, 64), &mut head)
            .map_err(|e| Error::io(path, e))?;
        if head.iter().all(|b| b" \t\r\n+-.eE0123456789".contains(b)) {
            return Err(Error::parse(
                path,
                "byte offset 0",
                "looks like text, not raw little-endian f32 triples (.xyz is binary)",
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
