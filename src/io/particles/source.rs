//! Where a run reads particles from: positions (and their payload: the selected
//! attributes) in memory, or a raw `.xyz` file mapped window by window, so that a scene
//! larger than memory is never held whole.
//!
//! A [`ParticleSource`] is visited front to back, in input order, a chunk at a time; the
//! tile engine visits it at most twice (bounds and tile histogram, then binning into a
//! spill file).

use super::{Attribute, Particles};
use crate::attributes::{payload_width, AttributeLayout, AttributeSelection};
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

/// Particles of a file that cannot be mapped as it is (gzip BGEO, binary VTK and PLY),
/// streamed once into temporary files and then read window by window like [`MappedXyz`]:
/// the positions into a raw `.xyz` (12 bytes per particle) and, when the run carries
/// attributes, their values into a payload file (little-endian f32). Memory stays one
/// chunk while converting and one window while reading, whatever the input size. The
/// temporary files are removed when this is dropped (also on errors and Ctrl-C, as the
/// error unwinds).
///
/// The payload file is a sequence of blocks, each `particles × width` floats, row-major:
/// one block holding every selected attribute for formats whose records interleave them
/// (BGEO, PLY), one per attribute for VTK, whose arrays follow each other. Reading
/// gathers each chunk's rows in the selection's order.
pub struct SpooledParticles {
    mapped: MappedXyz,
    layout: Vec<AttributeLayout>,
    payload: Option<MappedPayload>,
    _files: Vec<tempfile::TempPath>,
}

/// A payload file of blocks (see [`SpooledParticles`]), mapped a window at a time.
struct MappedPayload {
    path: PathBuf,
    file: std::fs::File,
    /// Byte offset and floats per row of each block.
    blocks: Vec<(u64, usize)>,
    /// For each attribute of the layout in order: its block and first column there.
    columns: Vec<(usize, usize)>,
    /// Floats per gathered row.
    width: usize,
}

impl MappedPayload {
    /// Writes to `rows` the payload rows of particles `first..first + count`.
    fn gather(
        &self,
        layout: &[AttributeLayout],
        first: usize,
        count: usize,
        rows: &mut Vec<f32>,
    ) -> Result<()> {
        rows.clear();
        rows.resize(count * self.width, 0.0);
        let len = self
            .file
            .metadata()
            .map_err(|e| Error::io(&self.path, e))?
            .len();
        let mut at = 0;
        for (a, &(block, column)) in layout.iter().zip(&self.columns) {
            let (offset, block_width) = self.blocks[block];
            let start = offset + (first * block_width * 4) as u64;
            let bytes = count * block_width * 4;
            // Checked before mapping, as for the positions: a map past the end faults.
            if len < start + bytes as u64 {
                return Err(Error::parse(
                    &self.path,
                    format!("byte offset {len}"),
                    "the payload file was truncated while being read",
                ));
            }
            // SAFETY: a read-only map of a range checked above to lie within the file
            // (this process's own temporary file), dropped before the next one.
            let map = unsafe {
                memmap2::MmapOptions::new()
                    .offset(start)
                    .len(bytes)
                    .map(&self.file)
            }
            .map_err(|e| Error::io(&self.path, e))?;
            for (row, record) in rows
                .chunks_exact_mut(self.width)
                .zip(map.chunks_exact(block_width * 4))
            {
                let values = &record[column * 4..(column + a.components) * 4];
                for (out, b) in row[at..at + a.components]
                    .iter_mut()
                    .zip(values.chunks_exact(4))
                {
                    *out = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
                }
            }
            at += a.components;
        }
        Ok(())
    }
}

/// The temporary files being written by [`SpooledParticles::from_file`]: created once the
/// selection is resolved, so that a bad selection leaves nothing behind.
struct Spool<'a> {
    path: &'a Path,
    cancel: &'a CancelToken,
    positions: TempWriter,
    payload: Option<TempWriter>,
    /// Particles written to the positions file.
    count: usize,
    /// Particles the header announced: no more are spooled.
    announced: usize,
    bytes: Vec<u8>,
}

/// A temporary file being written, with its path for errors.
struct TempWriter {
    path: PathBuf,
    writer: std::io::BufWriter<tempfile::NamedTempFile>,
    /// Bytes written so far.
    len: u64,
}

impl TempWriter {
    fn create(dir: &Path, prefix: &str, suffix: &str) -> Result<Self> {
        let file = tempfile::Builder::new()
            .prefix(&crate::io::tempfiles::owned_prefix(prefix))
            .rand_bytes(crate::io::tempfiles::RANDOM_CHARS)
            .suffix(suffix)
            .tempfile_in(dir)
            .map_err(|e| Error::io(dir, e))?;
        Ok(TempWriter {
            path: file.path().to_path_buf(),
            writer: std::io::BufWriter::with_capacity(1 << 20, file),
            len: 0,
        })
    }

    fn write(&mut self, bytes: &[u8]) -> Result<()> {
        std::io::Write::write_all(&mut self.writer, bytes).map_err(|e| Error::io(&self.path, e))?;
        self.len += bytes.len() as u64;
        Ok(())
    }

    fn finish(self) -> Result<(tempfile::TempPath, u64)> {
        let file = self
            .writer
            .into_inner()
            .map_err(|e| Error::io(&self.path, e.into_error()))?;
        Ok((file.into_temp_path(), self.len))
    }
}

impl<'a> Spool<'a> {
    /// The files for `announced` particles with `width` payload floats each, once `dir`
    /// is found to have room for them.
    fn new(
        path: &'a Path,
        dir: &Path,
        cancel: &'a CancelToken,
        announced: usize,
        width: usize,
    ) -> Result<Self> {
        let needed = (announced as u64).saturating_mul(12 + 4 * width as u64);
        crate::io::tempfiles::ensure_room(
            dir,
            &format!(
                "the particles of {} (its header announces {announced})",
                path.display()
            ),
            needed,
        )?;
        let positions = TempWriter::create(dir, crate::io::tempfiles::INPUT_PREFIX, ".xyz")?;
        let payload = if width > 0 {
            Some(TempWriter::create(
                dir,
                crate::io::tempfiles::PAYLOAD_PREFIX,
                ".f32",
            )?)
        } else {
            None
        };
        Ok(Spool {
            path,
            cancel,
            positions,
            payload,
            count: 0,
            announced,
            bytes: Vec::new(),
        })
    }

    /// Appends positions.
    fn positions(&mut self, chunk: &[Vec3]) -> Result<()> {
        self.cancel.check()?;
        if self.count + chunk.len() > self.announced {
            return Err(Error::parse(
                self.path,
                format!("particle {}", self.announced),
                format!(
                    "more particles than the {} the header announces",
                    self.announced
                ),
            ));
        }
        self.bytes.clear();
        for p in chunk {
            for c in p.to_array() {
                self.bytes.extend_from_slice(&c.to_le_bytes());
            }
        }
        self.count += chunk.len();
        self.positions.write(&self.bytes)
    }

    /// Appends payload rows of `attributes` (their components in row order), for the
    /// particles from `first` on, after checking every value is finite.
    fn payload(
        &mut self,
        attributes: &[AttributeLayout],
        first: usize,
        rows: &[f32],
    ) -> Result<()> {
        self.cancel.check()?;
        let width = payload_width(attributes);
        if let Some(k) = rows.iter().position(|v| !v.is_finite()) {
            let mut column = k % width;
            let attribute = attributes
                .iter()
                .find(|a| {
                    let here = column < a.components;
                    if !here {
                        column -= a.components;
                    }
                    here
                })
                .map_or("", |a| a.name.as_str());
            return Err(crate::attributes::non_finite_attribute(
                self.path,
                attribute,
                first + k / width,
                rows[k],
            ));
        }
        self.bytes.clear();
        for v in rows {
            self.bytes.extend_from_slice(&v.to_le_bytes());
        }
        match self.payload.as_mut() {
            Some(w) => w.write(&self.bytes),
            None => Ok(()),
        }
    }
}

impl SpooledParticles {
    /// Streams the positions of `path` (in `format`), and the attributes `selection` asks
    /// for, into temporary files in `temp_dir` (`None`: the system's temporary directory).
    /// The selection is resolved against the file's attribute names before any file is
    /// created, by the rules and with the errors of
    /// [`Particles::select`]; every value is checked finite. Gzip or
    /// plain BGEO always streams; PLY, binary or ASCII, when its first element is `vertex`
    /// ([`crate::io::particles::stream_ply_positions`]); VTK, binary or ASCII, positions
    /// only when its points come first ([`crate::io::particles::stream_vtk_positions`]),
    /// with attributes when a scan of its sections finds the points and the
    /// `POINT_DATA` arrays (one more pass over the file, no value decoded). `Ok(None)`
    /// otherwise (and for `.xyz`, which is mapped as it is): the caller parses the file.
    pub fn from_file(
        path: &Path,
        format: crate::io::particles::ParticleFormat,
        selection: &AttributeSelection,
        temp_dir: Option<&Path>,
        cancel: &CancelToken,
    ) -> Result<Option<SpooledParticles>> {
        use crate::io::particles::{self as p, ParticleFormat};
        if format == ParticleFormat::Xyz {
            return Ok(None);
        }
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
        if format == ParticleFormat::Vtk && !selection.is_none() {
            return Self::spool_vtk(path, selection, &dir, cancel);
        }
        // BGEO, PLY and positions-only VTK: records read front to back, the selection
        // resolved once the header is read, the files created then.
        let spool: std::cell::RefCell<Option<Spool>> = std::cell::RefCell::new(None);
        let layout: std::cell::RefCell<Vec<AttributeLayout>> = Default::default();
        let select = &mut |count: usize, declared: &[AttributeLayout]| -> Result<Vec<usize>> {
            let names: Vec<&str> = declared.iter().map(|a| a.name.as_str()).collect();
            let chosen = selection.resolve(path, &names)?;
            let chosen_layout: Vec<AttributeLayout> =
                chosen.iter().map(|&k| declared[k].clone()).collect();
            let width = payload_width(&chosen_layout);
            *layout.borrow_mut() = chosen_layout;
            *spool.borrow_mut() = Some(Spool::new(path, &dir, cancel, count, width)?);
            Ok(chosen)
        };
        let sink = &mut |chunk: &[Vec3], rows: &[f32]| -> Result<()> {
            let mut spool = spool.borrow_mut();
            let spool = spool.as_mut().expect("created by the selection");
            let first = spool.count;
            spool.positions(chunk)?;
            if !rows.is_empty() {
                spool.payload(&layout.borrow(), first, rows)?;
            }
            Ok(())
        };
        let count = match format {
            ParticleFormat::Bgeo => Some(p::bgeo::stream(path, select, sink)?.0),
            ParticleFormat::Ply => p::ply::stream(path, select, sink)?.map(|(n, _)| n),
            ParticleFormat::Vtk => p::vtk::stream_positions_counted(
                path,
                &mut |count| select(count, &[]).map(|_| ()),
                &mut |chunk| sink(chunk, &[]),
            )?,
            ParticleFormat::Xyz => unreachable!("mapped as it is"),
        };
        let Some(count) = count else {
            return Ok(None);
        };
        let spool = spool.into_inner().expect("created by the selection");
        let layout = layout.into_inner();
        let blocks = if layout.is_empty() {
            Vec::new()
        } else {
            vec![(0, payload_width(&layout))]
        };
        let mut columns = Vec::with_capacity(layout.len());
        let mut at = 0;
        for a in &layout {
            columns.push((0, at));
            at += a.components;
        }
        Self::finish(path, spool, count, layout, blocks, columns)
    }

    /// VTK with attributes: scan the sections, resolve the selection, then stream the
    /// points and each selected array (in file order, one payload block each).
    fn spool_vtk(
        path: &Path,
        selection: &AttributeSelection,
        dir: &Path,
        cancel: &CancelToken,
    ) -> Result<Option<SpooledParticles>> {
        let Some(scan) = crate::io::particles::vtk::scan(path)? else {
            return Ok(None);
        };
        let declared = scan.attributes();
        let names: Vec<&str> = declared.iter().map(|a| a.name.as_str()).collect();
        let chosen = selection.resolve(path, &names)?;
        let layout: Vec<AttributeLayout> = chosen.iter().map(|&k| declared[k].clone()).collect();
        let mut spool = Spool::new(path, dir, cancel, scan.count(), payload_width(&layout))?;
        scan.stream_points(path, &mut |chunk, _| spool.positions(chunk))?;
        // Arrays in file order, each its own block.
        let mut in_file = chosen.clone();
        in_file.sort_unstable();
        let mut blocks = Vec::with_capacity(in_file.len());
        for &k in &in_file {
            let offset = spool.payload.as_ref().map_or(0, |w| w.len);
            let attribute = std::slice::from_ref(&declared[k]);
            let mut first = 0;
            scan.stream_attribute(path, k, &mut |_, rows| {
                spool.payload(attribute, first, rows)?;
                first += rows.len() / declared[k].components;
                Ok(())
            })?;
            blocks.push((offset, declared[k].components));
        }
        let columns = chosen
            .iter()
            .map(|k| (in_file.binary_search(k).expect("selected"), 0))
            .collect();
        Self::finish(path, spool, scan.count(), layout, blocks, columns)
    }

    /// Closes the spool's files and maps them.
    fn finish(
        path: &Path,
        spool: Spool,
        count: usize,
        layout: Vec<AttributeLayout>,
        blocks: Vec<(u64, usize)>,
        columns: Vec<(usize, usize)>,
    ) -> Result<Option<SpooledParticles>> {
        if count == 0 {
            return Err(Error::EmptyInput {
                path: path.to_path_buf(),
            });
        }
        if let Some(a) = layout.iter().find(|a| a.components == 0) {
            // As [`crate::attributes::check_attribute`] reports it.
            return Err(Error::Attribute {
                path: path.to_path_buf(),
                attribute: a.name.clone(),
                message: format!("0 values of 0 components for {count} particles"),
            });
        }
        let Spool {
            positions, payload, ..
        } = spool;
        let (positions, _) = positions.finish()?;
        let mapped = MappedXyz::open(&positions)?;
        let mut files = vec![positions];
        let payload = match payload {
            Some(writer) => {
                let (temp, len) = writer.finish()?;
                let file = std::fs::File::open(&temp).map_err(|e| Error::io(&temp, e))?;
                let width = payload_width(&layout);
                debug_assert_eq!(len, (count * width * 4) as u64);
                let mapped = MappedPayload {
                    path: temp.to_path_buf(),
                    file,
                    blocks,
                    columns,
                    width,
                };
                files.push(temp);
                Some(mapped)
            }
            None => None,
        };
        Ok(Some(SpooledParticles {
            mapped,
            layout,
            payload,
            _files: files,
        }))
    }
}

impl ParticleSource for SpooledParticles {
    fn particle_count(&self) -> usize {
        self.mapped.particle_count()
    }
    fn attribute_layout(&self) -> Vec<AttributeLayout> {
        self.layout.clone()
    }
    fn visit_chunks(&self, visit: &mut dyn FnMut(ParticleChunk<'_>) -> Result<()>) -> Result<()> {
        let Some(payload) = &self.payload else {
            return self.mapped.visit_chunks(visit);
        };
        let mut rows = Vec::new();
        self.mapped.visit_chunks(&mut |chunk| {
            payload.gather(&self.layout, chunk.first, chunk.positions.len(), &mut rows)?;
            visit(ParticleChunk {
                payload: &rows,
                ..chunk
            })
        })
    }
}
