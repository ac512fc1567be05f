//! `archive merge`: several archives joined into one without re-encoding.

use super::container::{
    archive_error, file_header, index_bytes, repair_advice, RecordHeader, HEADER_LEN,
    RECORD_HEADER_LEN, VERSION,
};
use super::reader::ArchiveReader;
use crate::error::{Error, Result};
use std::fs::File;
use std::io::{BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// What [`merge`] wrote.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct MergeStats {
    /// Archives read.
    pub inputs: usize,
    /// Frames written.
    pub frames: usize,
    /// Bytes of the merged archive.
    pub bytes: u64,
}

/// One frame of an input: where its record is.
struct Entry {
    number: i64,
    input: usize,
    offset: u64,
    len: usize,
}

/// Removes the temporary file unless it was renamed into place.
struct TempFile(Option<PathBuf>);

impl Drop for TempFile {
    fn drop(&mut self) {
        if let Some(path) = self.0.take() {
            let _ = std::fs::remove_file(path);
        }
    }
}

/// Joins the archives `inputs` into a new archive `output`, frames in increasing frame
/// order across all inputs. Frame records are copied byte for byte (each record's
/// header and payload checksums verified on the way), so the result is byte-identical to
/// the archive one run writes when it appends the same frames in that order.
///
/// Refused, naming the files: a damaged or unfinished input (`archive verify` says
/// what), a frame number in two inputs, inputs with different error bounds, a version-1
/// archive (one plain mesh per frame) together with later versions, and an `output`
/// that exists and is none of the inputs. The output is written to a temporary file next
/// to it and renamed into place when complete: on any error it is not created (nor an
/// existing one changed). The archive's version is the highest of the inputs' (a
/// version-4 input, whose frames carry attributes, makes it version 4, a version-5 one,
/// with sphere scales, version 5, as appending such a frame would). Inputs are opened one at a time (each read whole, as
/// [`ArchiveReader::open`] does), then their records are read one by one.
pub fn merge(inputs: &[PathBuf], output: &Path) -> Result<MergeStats> {
    check_output(inputs, output)?;
    let (entries, version) = plan(inputs)?;
    let bytes = write_merged(inputs, &entries, version, output)?;
    Ok(MergeStats {
        inputs: inputs.len(),
        frames: entries.len(),
        bytes,
    })
}

/// Refuses no inputs, and an `output` that exists and is none of them.
pub(super) fn check_output(inputs: &[PathBuf], output: &Path) -> Result<()> {
    if inputs.is_empty() {
        return Err(Error::io(
            output,
            std::io::Error::new(std::io::ErrorKind::InvalidInput, "no archive to merge"),
        ));
    }
    if output.exists() {
        let same = |a: &Path| match (a.canonicalize(), output.canonicalize()) {
            (Ok(a), Ok(b)) => a == b,
            _ => false,
        };
        if !inputs.iter().any(|i| same(i)) {
            return Err(Error::io(
                output,
                std::io::Error::new(
                    std::io::ErrorKind::AlreadyExists,
                    "exists; a merge writes a new archive (name it among the inputs to merge into it)",
                ),
            ));
        }
    }
    Ok(())
}

/// The records to copy, in increasing frame order, and the merged archive's version;
/// refuses damaged inputs, mixed version classes, error bounds and frame numbers.
fn plan(inputs: &[PathBuf]) -> Result<(Vec<Entry>, u32)> {
    let mut entries: Vec<Entry> = Vec::new();
    // The first input (and frame) that set the version class and the step.
    let mut version: Option<(u32, usize)> = None;
    let mut step: Option<(f64, usize, i64)> = None;
    for (k, path) in inputs.iter().enumerate() {
        let reader = ArchiveReader::open(path)?;
        if let Some(d) = reader.damage.first() {
            return Err(archive_error(
                path,
                d.frame,
                format!(
                    "refusing to merge a damaged or unfinished archive: {}; {}",
                    d.message,
                    repair_advice(path)
                ),
            ));
        }
        match version {
            Some((v, first)) if (v == 1) != (reader.version == 1) => {
                return Err(archive_error(
                    path,
                    None,
                    format!(
                        "a version-{} archive cannot be merged with the version-{v} archive {} (version 1 stores one plain mesh per frame)",
                        reader.version,
                        inputs[first].display()
                    ),
                ))
            }
            Some((v, first)) => version = Some((v.max(reader.version), first)),
            None => version = Some((reader.version, k)),
        }
        for info in &reader.frames {
            match step {
                Some((s, first, number)) if s != info.step => {
                    return Err(archive_error(
                        path,
                        Some(info.number),
                        format!(
                            "error bound {} differs from the error bound {} of {} (frame {number}); merged frames must share one",
                            info.step / 2.0,
                            s / 2.0,
                            inputs[first].display()
                        ),
                    ))
                }
                Some(_) => {}
                None => step = Some((info.step, k, info.number)),
            }
            entries.push(Entry {
                number: info.number,
                input: k,
                offset: info.offset,
                len: RECORD_HEADER_LEN
                    + usize::try_from(info.payload_bytes)
                        .map_err(|_| archive_error(path, Some(info.number), "record too large"))?,
            });
        }
    }
    // Stable: frames of one input keep their order among equals (equals are refused).
    entries.sort_by_key(|e| e.number);
    if let Some(w) = entries.windows(2).find(|w| w[0].number == w[1].number) {
        let (a, b) = (&inputs[w[0].input], &inputs[w[1].input]);
        let message = if a == b {
            "given twice: the archive is named twice among the inputs".to_string()
        } else {
            format!(
                "also in {}; a frame may come from one input only",
                a.display()
            )
        };
        return Err(archive_error(b, Some(w[1].number), message));
    }
    Ok((entries, version.map_or(VERSION, |(v, _)| v)))
}

/// Writes the merged archive to a temporary file beside `output`, copying and checking
/// each record of `entries`, then renames it into place; returns its bytes.
fn write_merged(inputs: &[PathBuf], entries: &[Entry], version: u32, output: &Path) -> Result<u64> {
    if let Some(dir) = output.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    let mut name = output.file_name().unwrap_or_default().to_os_string();
    name.push(format!(".merging-{}", std::process::id()));
    let temp_path = output.with_file_name(name);
    let file = File::options()
        .write(true)
        .create_new(true)
        .open(&temp_path)
        .map_err(|e| Error::io(&temp_path, e))?;
    let mut temp = TempFile(Some(temp_path.clone()));
    let mut out = BufWriter::new(file);
    let write_err = |e| Error::io(&temp_path, e);
    out.write_all(&file_header(version)).map_err(write_err)?;
    let mut files: Vec<Option<File>> = inputs.iter().map(|_| None).collect();
    let mut index: Vec<(i64, u64)> = Vec::with_capacity(entries.len());
    let mut end = HEADER_LEN;
    let mut record = Vec::new();
    for e in entries {
        let path = &inputs[e.input];
        let file = match &mut files[e.input] {
            Some(f) => f,
            slot => slot.insert(File::open(path).map_err(|err| Error::io(path, err))?),
        };
        record.resize(e.len, 0);
        file.seek(SeekFrom::Start(e.offset))
            .and_then(|_| file.read_exact(&mut record))
            .map_err(|err| Error::io(path, err))?;
        // Checked again as copied: the file may have changed since it was opened.
        let intact = RecordHeader::parse(&record).is_some_and(|h| {
            h.number == e.number
                && RECORD_HEADER_LEN as u64 + h.payload_len == e.len as u64
                && crc32fast::hash(&record[RECORD_HEADER_LEN..]) == h.payload_crc
        });
        if !intact {
            return Err(archive_error(
                path,
                Some(e.number),
                "checksum mismatch while copying: the frame is damaged (or the file changed)",
            ));
        }
        out.write_all(&record).map_err(write_err)?;
        index.push((e.number, end));
        end += e.len as u64;
    }
    let tail = index_bytes(&index, end);
    out.write_all(&tail).map_err(write_err)?;
    let file = out.into_inner().map_err(|e| write_err(e.into_error()))?;
    file.sync_all().map_err(write_err)?;
    drop(file);
    std::fs::rename(&temp_path, output).map_err(|e| Error::io(output, e))?;
    temp.0 = None;
    Ok(end + tail.len() as u64)
}
