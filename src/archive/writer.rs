//! Writing an archive: a new one or an existing one opened for appending, one record per
//! frame after the earlier ones (which are never rewritten), the index at the end; a
//! writer dropped unfinished writes the index itself.

use super::attributes;
use super::codec;
use super::container::{
    archive_error, file_header, index_bytes, repair_advice, RecordHeader, ATTRIBUTES_VERSION,
    HEADER_LEN, MAX_SUBDIVISION_LEVELS, RECORD_HEADER_LEN, SCALES_VERSION, VERSION, VERSION_OFFSET,
};
use super::frame::{self, ArchiveFrame};
use super::options::ArchiveOptions;
use super::reader::{ArchiveReader, DamageKind};
use crate::error::{Error, Result};
use crate::mesh::{SphereInstances, TriMesh};
use std::fs::{File, OpenOptions};
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

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
        check_appendable(path, &reader)?;
        check_error_bound(path, &reader, options)?;
        Self::from_reader(path, reader, options)
    }

    /// Writes the index of the archive at `path` when it has none (a run killed between
    /// its last record and its index, or an archive cut after a record): the index of
    /// every complete frame, as an append would write it. Returns whether it wrote one.
    /// Refused, changing nothing, when appending would be (a damaged archive).
    pub fn finish_unindexed(path: &Path) -> Result<bool> {
        let input = path.display().to_string();
        crate::error::guard(
            move || input,
            || {
                let reader = ArchiveReader::open(path)?;
                if !reader.recovered_by_scan() {
                    return Ok(false);
                }
                check_appendable(path, &reader)?;
                let bound = reader.frames.first().map_or(1.0, |f| f.step / 2.0);
                Self::from_reader(path, reader, &ArchiveOptions::new(bound))?.close()?;
                Ok(true)
            },
        )
    }

    /// The writer appending to the archive `reader` read from `path`.
    fn from_reader(
        path: &Path,
        reader: ArchiveReader,
        options: &ArchiveOptions,
    ) -> Result<ArchiveWriter> {
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
            let header = file_header(self.version);
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
    /// archive cannot store attributes and refuses such a frame. The first frame whose
    /// spheres carry scales makes a version-2 to -4 archive version 5 the same way (a
    /// version-1 archive stores them merged); scales that do not fit the centres (see
    /// [`SphereInstances::scales`]) are refused.
    pub fn append_frame(&mut self, number: i64, frame: &ArchiveFrame) -> Result<u64> {
        let input = format!("{}: frame {number}", self.path.display());
        crate::error::guard(move || input, || self.append_frame_unguarded(number, frame))
    }

    fn append_frame_unguarded(&mut self, number: i64, frame: &ArchiveFrame) -> Result<u64> {
        let with_attributes = self.check_frame(number, frame)?;
        // The archive's version once this frame is in it: the header is rewritten only
        // when the frame is encoded, so that a frame that fails changes nothing. A
        // version-1 archive stores the scaled spheres merged, as they are.
        let mut version = self.version;
        if with_attributes {
            version = version.max(ATTRIBUTES_VERSION);
        }
        if frame::has_scales(frame) && version != 1 {
            version = version.max(SCALES_VERSION);
        }
        let encoded = self
            .encode(frame, version)
            .map_err(|e| Error::io(&self.path, e))?;
        if version != self.version {
            self.set_version(version)?;
        }
        self.write_record(number, encoded)
    }

    /// Refuses a frame the archive cannot take: a number it holds, too many Loop steps,
    /// attributes that do not fit the meshes or that a version-1 archive cannot store.
    /// Returns whether the frame stores attributes.
    fn check_frame(&self, number: i64, frame: &ArchiveFrame) -> Result<bool> {
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
        frame
            .spheres
            .check_scales()
            .map_err(|m| archive_error(&self.path, Some(number), m))?;
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
        Ok(with_attributes)
    }

    /// The frame's record payload in an archive of format `version`.
    fn encode(&self, frame: &ArchiveFrame, version: u32) -> std::io::Result<frame::EncodedFrame> {
        let step = 2.0 * self.options.error_bound;
        let level = self.options.zstd_level;
        if version != 1 {
            return frame::encode_frame(
                frame,
                step,
                self.options.attribute_error_bound,
                level,
                version >= 3,
            );
        }
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
    }

    /// Rewrites the version field of the file header (a file not yet written gets it
    /// when it is).
    fn set_version(&mut self, version: u32) -> Result<()> {
        if self.file.is_none() {
            self.version = version;
        }
        let end = self.end;
        let file = self.file()?;
        let rewritten = file
            .seek(SeekFrom::Start(VERSION_OFFSET))
            .and_then(|_| file.write_all(&version.to_le_bytes()))
            .and_then(|_| file.seek(SeekFrom::Start(end)));
        if let Err(e) = rewritten {
            self.reset = true;
            return Err(Error::io(&self.path, e));
        }
        self.version = version;
        Ok(())
    }

    /// Writes the record of frame `number` at the end; returns its bytes in the archive.
    fn write_record(&mut self, number: i64, encoded: frame::EncodedFrame) -> Result<u64> {
        let payload = encoded.payload;
        let header = RecordHeader {
            number,
            vertices: encoded.vertices,
            triangles: encoded.triangles,
            step: 2.0 * self.options.error_bound,
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

/// Refuses to append to the archive `reader` read from `path` when appending could lose
/// or hide anything.
fn check_appendable(path: &Path, reader: &ArchiveReader) -> Result<()> {
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
            format!(
                "refusing to append to a damaged archive: {why}; {}",
                repair_advice(path)
            ),
        ));
    }
    check_records_end(path, reader)
}

/// Refuses to append frames of another error bound than the archive's frames'.
fn check_error_bound(path: &Path, reader: &ArchiveReader, options: &ArchiveOptions) -> Result<()> {
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
    Ok(())
}

/// Refuses to append when the index and a walk of the records disagree about where the
/// records end (the last record's header is damaged, or its length field claims more or
/// fewer bytes than it has): a record written where the index says would start inside
/// what the walk takes for that record, and readers following the record lengths would
/// miss it and every frame after it.
fn check_records_end(path: &Path, reader: &ArchiveReader) -> Result<()> {
    if reader.walk_end == reader.data_end {
        return Ok(());
    }
    let at = reader.walk_end;
    let why = reader
        .damage
        .iter()
        .find(|d| d.offset == Some(at))
        .map_or_else(
            || format!("the bytes at offset {at} are no complete record"),
            |d| d.message.clone(),
        );
    let frame = reader
        .damage
        .iter()
        .find(|d| d.offset == Some(at))
        .and_then(|d| d.frame);
    Err(archive_error(
        path,
        frame,
        format!(
            "refusing to append: by the index the records end at byte {}, but a walk of the records stops at byte {at} ({why}), so a frame appended there could not be read; {}",
            reader.data_end,
            repair_advice(path)
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::isolated::icosphere;

    /// What a write that fails partway leaves: part of a record after `end`, and the writer
    /// told to cut it (as `write_at_end` does on an error).
    fn fail_partway(w: &mut ArchiveWriter) {
        w.file
            .as_mut()
            .unwrap()
            .write_all(b"FRAM half a record")
            .unwrap();
        w.reset = true;
    }

    #[test]
    fn a_record_cut_by_a_failed_write_is_cut_from_the_archive() {
        let dir = tempfile::tempdir().unwrap();
        let options = ArchiveOptions::new(1e-3);
        let mesh = |k: i64| icosphere(1, 1.0 + k as f32);
        let reference = dir.path().join("reference.mseq");
        let mut w = ArchiveWriter::create(&reference, &options).unwrap();
        for k in 0..3 {
            w.append(k, &mesh(k)).unwrap();
        }
        w.finish().unwrap();
        // The next frame goes where the failed one started, and a writer dropped after a
        // failed write cuts it before writing the index.
        let path = dir.path().join("run.mseq");
        let mut w = ArchiveWriter::create(&path, &options).unwrap();
        w.append(0, &mesh(0)).unwrap();
        w.append(1, &mesh(1)).unwrap();
        fail_partway(&mut w);
        w.append(2, &mesh(2)).unwrap();
        fail_partway(&mut w);
        drop(w);
        let r = ArchiveReader::open(&path).unwrap();
        assert!(r.verify().is_clean() && !r.recovered_by_scan());
        assert_eq!(
            std::fs::read(&path).unwrap(),
            std::fs::read(&reference).unwrap()
        );
        // Appending to an existing archive: the same.
        let mut w = ArchiveWriter::open_append(&path, &options).unwrap();
        w.append(3, &mesh(3)).unwrap();
        fail_partway(&mut w);
        drop(w);
        let r = ArchiveReader::open(&path).unwrap();
        assert!(r.verify().is_clean() && !r.recovered_by_scan());
        assert_eq!(r.verify().good, [0, 1, 2, 3]);
        // A new archive whose first record failed partway is removed.
        let fresh = dir.path().join("fresh.mseq");
        let mut w = ArchiveWriter::create(&fresh, &options).unwrap();
        w.file().unwrap();
        fail_partway(&mut w);
        assert!(fresh.exists());
        drop(w);
        assert!(!fresh.exists());
    }
}
