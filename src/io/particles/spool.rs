//! Particles of a file that cannot be mapped as it is, spooled into temporary files that
//! can ([`SpooledParticles`]), through the formats' streaming readers
//! ([`super::ParticleCodec::stream`]).

use super::source::MappedXyz;
use super::{ParticleChunk, ParticleFormat, ParticleSource, StreamSink};
use crate::attributes::{non_finite_attribute, payload_width, AttributeLayout, AttributeSelection};
use crate::cancel::CancelToken;
use crate::error::{Error, Result};
use glam::Vec3;
use std::path::{Path, PathBuf};

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
            return Err(non_finite_attribute(
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
    /// created, by the rules and with the errors of [`super::Particles::select`]; every
    /// value is checked finite. Gzip or plain BGEO always streams; PLY, binary or ASCII,
    /// when `vertex` is its first element; VTK when a scan of its sections finds the points
    /// and the `POINT_DATA` arrays (one more pass over the file); VTK XML of one piece. A
    /// file that streams is one [`super::read_particles`] takes
    /// ([`super::stream_positions`]). `Ok(None)` otherwise (and for `.xyz`, which is mapped
    /// as it is): the caller parses the file.
    pub fn from_file(
        path: &Path,
        format: ParticleFormat,
        selection: &AttributeSelection,
        temp_dir: Option<&Path>,
        cancel: &CancelToken,
    ) -> Result<Option<SpooledParticles>> {
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
        let mut sink = SpoolSink {
            path,
            selection,
            dir: &dir,
            cancel,
            spool: None,
            layout: Vec::new(),
            arrays: Vec::new(),
        };
        match format.codec().stream(path, &mut sink)? {
            Some(count) => sink.finish(count),
            None => Ok(None),
        }
    }
}

/// The [`StreamSink`] of [`SpooledParticles::from_file`]: resolves the selection once the
/// header is read, then creates the files and appends to them.
struct SpoolSink<'a> {
    path: &'a Path,
    selection: &'a AttributeSelection,
    dir: &'a Path,
    cancel: &'a CancelToken,
    /// Created by the selection.
    spool: Option<Spool<'a>>,
    /// The selected attributes, in payload order.
    layout: Vec<AttributeLayout>,
    /// The payload blocks of attributes streamed as arrays (VTK), in file order: byte
    /// offset, the attribute (an index into `layout`) and the rows written so far.
    arrays: Vec<(u64, usize, usize)>,
}

impl StreamSink for SpoolSink<'_> {
    fn select(&mut self, count: usize, declared: &[AttributeLayout]) -> Result<Vec<usize>> {
        let names: Vec<&str> = declared.iter().map(|a| a.name.as_str()).collect();
        let chosen = self.selection.resolve(self.path, &names)?;
        self.layout = chosen.iter().map(|&k| declared[k].clone()).collect();
        let width = payload_width(&self.layout);
        self.spool = Some(Spool::new(self.path, self.dir, self.cancel, count, width)?);
        Ok(chosen)
    }

    fn records(&mut self, positions: &[Vec3], rows: &[f32]) -> Result<()> {
        let spool = self.spool.as_mut().expect("created by the selection");
        let first = spool.count;
        spool.positions(positions)?;
        if !rows.is_empty() {
            spool.payload(&self.layout, first, rows)?;
        }
        Ok(())
    }

    fn array(&mut self, k: usize, rows: &[f32]) -> Result<()> {
        let spool = self.spool.as_mut().expect("created by the selection");
        if self.arrays.last().is_none_or(|&(_, last, _)| last != k) {
            let offset = spool.payload.as_ref().map_or(0, |w| w.len);
            self.arrays.push((offset, k, 0));
        }
        let (_, _, first) = self.arrays.last_mut().expect("pushed above");
        let attribute = &self.layout[k];
        spool.payload(std::slice::from_ref(attribute), *first, rows)?;
        *first += rows.len() / attribute.components;
        Ok(())
    }
}

impl SpoolSink<'_> {
    /// Closes the spool's files (`count` particles streamed) and maps them.
    fn finish(self, count: usize) -> Result<Option<SpooledParticles>> {
        let SpoolSink {
            path,
            spool,
            layout,
            arrays,
            ..
        } = self;
        let spool = spool.expect("created by the selection");
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
        // One block of interleaved rows, or one per array, in file order.
        let (blocks, columns) = if arrays.is_empty() {
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
            (blocks, columns)
        } else {
            let blocks = arrays
                .iter()
                .map(|&(offset, k, _)| (offset, layout[k].components))
                .collect();
            let columns = (0..layout.len())
                .map(|k| {
                    let block = arrays.iter().position(|a| a.1 == k);
                    (block.expect("every selected array streamed"), 0)
                })
                .collect();
            (blocks, columns)
        };
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
