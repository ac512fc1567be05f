//! Spill file: the particles of a tiled run binned on disk by spill cell, so that a tile
//! reads back only the particles near it and the whole scene is never in memory.
//!
//! One file in a private temporary directory (removed when the [`SpillFile`] is dropped:
//! on success, on error, and on Ctrl-C, which the CLI turns into an error between
//! tiles). Records are `16 + 4·w` bytes: `x, y, z` (f32, little-endian), the particle's
//! input index (u32) and its `w` payload floats (the selected attributes, f32). The first pass over the input counts particles per cell, so every cell
//! gets one contiguous region of the file; the second pass fills the regions through
//! small per-cell buffers. Records are stored raw: zstd level 1 shrinks the records of
//! `dambreak_small` frame 25 by 12 % only (670 592 → 588 016 bytes; the low bits of
//! particle coordinates are noise), not worth a compression pass on every write and
//! every ghost read.

use crate::error::{Error, Result};
use crate::grid::BlockKey;
use glam::Vec3;
use hashbrown::HashMap;
use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

/// Bytes of a record without payload.
pub const RECORD_BYTES: usize = 16;
/// Memory all per-cell write buffers may take together.
const BUFFER_BYTES: usize = 32 << 20;

/// Particles binned by cell in one temporary file.
pub struct SpillFile {
    // Field order matters: the file is closed before its directory is removed.
    file: File,
    path: PathBuf,
    /// Cell → (first record, record count).
    regions: HashMap<BlockKey, (u64, u64)>,
    /// Bytes of one record (with its payload).
    record_bytes: usize,
    _dir: tempfile::TempDir,
}

impl SpillFile {
    /// Creates the file in a new directory under `parent`, with one region per cell of
    /// `counts` (cell → particles), for records with `payload_width` floats of payload.
    pub fn create(
        parent: &Path,
        counts: &HashMap<BlockKey, u64>,
        payload_width: usize,
    ) -> Result<Self> {
        let record_bytes = RECORD_BYTES + 4 * payload_width;
        // The file's size is known before anything is written: a directory without room
        // for it fails now, not after minutes of binning (the file is sparse until then).
        let records: u64 = counts.values().sum();
        crate::io::tempfiles::ensure_room(
            parent,
            &format!("the spill file of {records} particles"),
            records.saturating_mul(record_bytes as u64),
        )?;
        let dir = tempfile::Builder::new()
            .prefix(&crate::io::tempfiles::owned_prefix(
                crate::io::tempfiles::SPILL_PREFIX,
            ))
            .rand_bytes(crate::io::tempfiles::RANDOM_CHARS)
            .tempdir_in(parent)
            .map_err(|e| spill_error(parent, e))?;
        let path = dir.path().join("particles.bin");
        let file = File::options()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&path)
            .map_err(|e| spill_error(&path, e))?;
        let mut cells: Vec<(&BlockKey, &u64)> = counts.iter().collect();
        cells.sort_unstable_by_key(|(k, _)| [k[2], k[1], k[0]]);
        let mut regions = HashMap::with_capacity(cells.len());
        let mut first = 0u64;
        for (key, &count) in cells {
            regions.insert(*key, (first, count));
            first += count;
        }
        file.set_len(first * record_bytes as u64)
            .map_err(|e| spill_error(&path, e))?;
        Ok(SpillFile {
            file,
            path,
            regions,
            record_bytes,
            _dir: dir,
        })
    }

    /// The populated cells, in (z, y, x) order.
    pub fn cells(&self) -> Vec<BlockKey> {
        let mut cells: Vec<BlockKey> = self.regions.keys().copied().collect();
        cells.sort_unstable_by_key(|k| [k[2], k[1], k[0]]);
        cells
    }

    /// Bytes of particle records in the file.
    pub fn bytes(&self) -> u64 {
        self.regions.values().map(|r| r.1).sum::<u64>() * self.record_bytes as u64
    }

    /// A writer that fills the regions; every particle counted at creation must be
    /// pushed exactly once.
    pub fn writer(&self) -> SpillWriter<'_> {
        let per_cell =
            (BUFFER_BYTES / self.regions.len().max(1)).clamp(256, 64 << 10) / self.record_bytes;
        SpillWriter {
            spill: self,
            pending: HashMap::new(),
            per_cell,
        }
    }

    /// The records of every cell from `lo` to `hi` (inclusive, per axis), cell by cell,
    /// and their payload rows into `payload` when given. Visits the box's cells, or the
    /// populated cells when those are fewer (a tile much larger than the scene).
    pub fn read_cells(
        &self,
        lo: BlockKey,
        hi: BlockKey,
        out: &mut Vec<(Vec3, u32)>,
        mut payload: Option<&mut Vec<f32>>,
    ) -> Result<()> {
        let volume: u64 = (0..3).map(|a| (hi[a] - lo[a] + 1).max(0) as u64).product();
        let mut wanted: Vec<BlockKey> = Vec::new();
        if volume <= self.regions.len() as u64 {
            for z in lo[2]..=hi[2] {
                for y in lo[1]..=hi[1] {
                    for x in lo[0]..=hi[0] {
                        wanted.push([x, y, z]);
                    }
                }
            }
        } else {
            wanted.extend(
                self.regions
                    .keys()
                    .filter(|c| (0..3).all(|a| (lo[a]..=hi[a]).contains(&c[a]))),
            );
        }
        for cell in wanted {
            self.read_cell(cell, out, payload.as_deref_mut())?;
        }
        Ok(())
    }

    /// The records of one cell (empty when the cell holds no particle), and their payload
    /// rows into `payload` when given.
    pub fn read_cell(
        &self,
        cell: BlockKey,
        out: &mut Vec<(Vec3, u32)>,
        payload: Option<&mut Vec<f32>>,
    ) -> Result<()> {
        let Some(&(first, count)) = self.regions.get(&cell) else {
            return Ok(());
        };
        let stride = self.record_bytes;
        let mut bytes = vec![0u8; count as usize * stride];
        self.file
            .read_exact_at(&mut bytes, first * stride as u64)
            .map_err(|e| spill_error(&self.path, e))?;
        let f = |c: &[u8], k: usize| f32::from_le_bytes([c[k], c[k + 1], c[k + 2], c[k + 3]]);
        out.extend(bytes.chunks_exact(stride).map(|c| {
            (
                Vec3::new(f(c, 0), f(c, 4), f(c, 8)),
                u32::from_le_bytes([c[12], c[13], c[14], c[15]]),
            )
        }));
        if let Some(rows) = payload {
            for c in bytes.chunks_exact(stride) {
                rows.extend((RECORD_BYTES..stride).step_by(4).map(|k| f(c, k)));
            }
        }
        Ok(())
    }
}

/// Buffered writes into the regions of a [`SpillFile`].
pub struct SpillWriter<'a> {
    spill: &'a SpillFile,
    /// Per cell written to: the next record of its region and the records not yet
    /// written.
    pending: HashMap<BlockKey, (u64, Vec<u8>)>,
    per_cell: usize,
}

impl SpillWriter<'_> {
    /// Appends one particle, with its payload row, to its cell's region.
    pub fn push(
        &mut self,
        cell: BlockKey,
        position: Vec3,
        index: u32,
        payload: &[f32],
    ) -> Result<()> {
        let (spill, per_cell) = (self.spill, self.per_cell);
        let record_bytes = spill.record_bytes;
        debug_assert_eq!(RECORD_BYTES + 4 * payload.len(), record_bytes);
        let (cursor, buffer) = self.pending.entry(cell).or_insert_with(|| {
            let first = spill.regions.get(&cell).map_or(0, |r| r.0);
            (first, Vec::with_capacity(per_cell * record_bytes))
        });
        for v in position.to_array() {
            buffer.extend_from_slice(&v.to_le_bytes());
        }
        buffer.extend_from_slice(&index.to_le_bytes());
        for v in payload {
            buffer.extend_from_slice(&v.to_le_bytes());
        }
        if buffer.len() >= per_cell * record_bytes {
            spill.write_records(cell, cursor, buffer)?;
        }
        Ok(())
    }

    /// Writes what is still buffered.
    pub fn finish(mut self) -> Result<()> {
        let mut cells: Vec<BlockKey> = self.pending.keys().copied().collect();
        cells.sort_unstable();
        for cell in cells {
            let (cursor, buffer) = self.pending.get_mut(&cell).expect("listed");
            self.spill.write_records(cell, cursor, buffer)?;
        }
        Ok(())
    }
}

impl SpillFile {
    /// Writes the records in `buffer` at `cursor` of `cell`'s region, advances the cursor
    /// and empties the buffer.
    fn write_records(&self, cell: BlockKey, cursor: &mut u64, buffer: &mut Vec<u8>) -> Result<()> {
        let records = (buffer.len() / self.record_bytes) as u64;
        let fits = self
            .regions
            .get(&cell)
            .is_some_and(|&(first, count)| *cursor + records <= first + count);
        if !fits {
            return Err(Error::Spill {
                path: self.path.clone(),
                source: std::io::Error::other(
                    "the input changed between the counting and the binning pass",
                ),
            });
        }
        self.file
            .write_all_at(buffer, *cursor * self.record_bytes as u64)
            .map_err(|e| spill_error(&self.path, e))?;
        *cursor += records;
        buffer.clear();
        Ok(())
    }
}

fn spill_error(path: &Path, source: std::io::Error) -> Error {
    Error::Spill {
        path: path.to_path_buf(),
        source,
    }
}
