//! Houdini "classic" BGEO, version 5, as partio and SPlisHSPlasH write it; gzip-compressed
//! (detected by the gzip magic bytes) or plain. After decompression all values are
//! big-endian:
//!
//! `"Bgeo" 'V'`, 9 × i32 (version, points, primitives, point groups, primitive groups,
//! point attributes, vertex attributes, primitive attributes, detail attributes), the point
//! attribute definitions (u16 name length, name, u16 size, i32 type, `size` default
//! values), then per point `P[4]` (x, y, z, w) as f32 followed by every attribute's values.
//! Attribute types kept: 0 float, 1 int (as f32), 5 vector. Others are rejected.

use super::{Attribute, Particles, RecordSink};
use crate::attributes::AttributeLayout;
use crate::error::{Error, Result};
use glam::Vec3;
use std::io::{BufRead, Read};
use std::path::Path;

/// Points decoded per chunk by the streaming parser.
const CHUNK_POINTS: usize = 1 << 16;

/// Most bytes of records buffered per chunk.
const CHUNK_BYTES: usize = 1 << 24;

/// The decompressed byte stream with its offset, for error locations.
struct Stream<'a> {
    path: &'a Path,
    inner: Box<dyn Read + 'a>,
    pos: u64,
}

impl Stream<'_> {
    fn fill(&mut self, buf: &mut [u8], what: &str) -> Result<()> {
        let at = self.pos;
        self.inner.read_exact(buf).map_err(|e| {
            let message = if e.kind() == std::io::ErrorKind::UnexpectedEof {
                format!(
                    "truncated while reading {what}: need {} bytes, the stream ends first",
                    buf.len()
                )
            } else {
                format!("cannot read {what}: {e}")
            };
            Error::parse(
                self.path,
                format!("byte offset {at} (decompressed)"),
                message,
            )
        })?;
        self.pos += buf.len() as u64;
        Ok(())
    }
    /// Appends `n` bytes to `buf`, which grows only as the bytes arrive (a count from a
    /// header reserves nothing).
    fn fill_growing(&mut self, buf: &mut Vec<u8>, n: usize, what: &str) -> Result<()> {
        let at = self.pos;
        let got = (&mut self.inner)
            .take(n as u64)
            .read_to_end(buf)
            .map_err(|e| {
                Error::parse(
                    self.path,
                    format!("byte offset {at} (decompressed)"),
                    format!("cannot read {what}: {e}"),
                )
            })?;
        if got < n {
            return Err(Error::parse(
                self.path,
                format!("byte offset {at} (decompressed)"),
                format!("truncated while reading {what}: need {n} bytes, the stream ends first"),
            ));
        }
        self.pos += n as u64;
        Ok(())
    }
    fn bytes(&mut self, n: usize, what: &str) -> Result<Vec<u8>> {
        let mut b = vec![0u8; n];
        self.fill(&mut b, what)?;
        Ok(b)
    }
    fn i32(&mut self, what: &str) -> Result<i32> {
        let mut b = [0u8; 4];
        self.fill(&mut b, what)?;
        Ok(i32::from_be_bytes(b))
    }
    fn u16(&mut self, what: &str) -> Result<u16> {
        let mut b = [0u8; 2];
        self.fill(&mut b, what)?;
        Ok(u16::from_be_bytes(b))
    }
}

/// Chooses, from the attributes a header declares (in file order), the indices of those
/// to stream, in payload order; told first the point count the header announces.
pub(super) type Select<'a> = dyn FnMut(usize, &[AttributeLayout]) -> Result<Vec<usize>> + 'a;

/// Most bytes a BGEO stream may hold after its point records (primitives, detail
/// attributes, the two-byte extra block partio writes) before it counts as data the
/// header did not announce.
const MAX_TRAILER_BYTES: u64 = 1 << 20;

/// Parses a BGEO stream (gzip detected by its magic bytes) chunk by chunk: once the
/// header is read, `select` picks the attributes to carry; then positions and the
/// selected attributes' payload rows (in `select`'s order) go to `sink` in chunks of at
/// most [`CHUNK_POINTS`]. Returns the point count and the selected layout. Memory: one
/// chunk of records.
fn parse<'a, R: BufRead + 'a>(
    path: &'a Path,
    mut source: R,
    select: &mut Select<'_>,
    sink: &mut RecordSink<'_>,
) -> Result<(usize, Vec<AttributeLayout>)> {
    let gzip = source
        .fill_buf()
        .map_err(|e| Error::io(path, e))?
        .starts_with(&[0x1f, 0x8b]);
    let inner: Box<dyn Read + 'a> = if gzip {
        Box::new(flate2::bufread::MultiGzDecoder::new(source))
    } else {
        Box::new(source)
    };
    let mut r = Stream {
        path,
        inner,
        pos: 0,
    };
    let magic = r.bytes(5, "the magic number")?;
    if magic != b"BgeoV" {
        return Err(Error::parse(
            path,
            "byte offset 0",
            "not a classic BGEO file (magic \"BgeoV\" missing)",
        ));
    }
    let version = r.i32("the version")?;
    if version != 5 {
        return Err(Error::UnsupportedFormat {
            path: path.to_path_buf(),
            message: format!("BGEO version {version}; only classic version 5 is supported"),
        });
    }
    let header: Vec<i32> = (0..8).map(|_| r.i32("the header")).collect::<Result<_>>()?;
    let (npoints, nprims, nattr) = (header[0], header[1], header[4]);
    if npoints < 0 || nattr < 0 || nprims < 0 {
        return Err(Error::parse(
            path,
            "byte offset 9",
            "negative count in the header",
        ));
    }
    if header[2] != 0 || header[3] != 0 {
        return Err(Error::UnsupportedFormat {
            path: path.to_path_buf(),
            message: "BGEO point or primitive groups are not supported".into(),
        });
    }
    let mut defs: Vec<(String, usize, i32)> = Vec::new();
    for _ in 0..nattr {
        let len = r.u16("an attribute name length")? as usize;
        let name = String::from_utf8_lossy(&r.bytes(len, "an attribute name")?).into_owned();
        let size = r.u16("an attribute size")? as usize;
        let ty = r.i32("an attribute type")?;
        if !matches!(ty, 0 | 1 | 5) {
            return Err(Error::UnsupportedFormat {
                path: path.to_path_buf(),
                message: format!(
                    "BGEO attribute {name:?} has type {ty}; supported: float, int, vector"
                ),
            });
        }
        r.bytes(4 * size, "attribute defaults")?;
        defs.push((name, size, ty));
    }
    let npoints = npoints as usize;
    let stride = 16 + defs.iter().map(|d| 4 * d.1).sum::<usize>();
    npoints
        .checked_mul(stride)
        .ok_or_else(|| Error::parse(path, "header", "point count overflows"))?;
    let declared: Vec<AttributeLayout> = defs
        .iter()
        .map(|(name, size, _)| AttributeLayout {
            name: name.clone(),
            components: *size,
        })
        .collect();
    let chosen = select(npoints, &declared)?;
    // Byte offset in the record, components and int-ness of each selected attribute.
    let mut at = Vec::with_capacity(defs.len());
    let mut o = 16;
    for (_, size, ty) in &defs {
        at.push((o, *size, *ty == 1));
        o += 4 * size;
    }
    let fields: Vec<(usize, usize, bool)> = chosen.iter().map(|&k| at[k]).collect();
    let layout: Vec<AttributeLayout> = chosen.iter().map(|&k| declared[k].clone()).collect();
    let f = |b: &[u8]| f32::from_be_bytes(b.try_into().expect("4 bytes"));
    // Nothing is reserved from the header's count: a chunk holds at most `CHUNK_BYTES`
    // (or one record), and the buffers grow only as records arrive.
    let per_chunk = CHUNK_POINTS.min((CHUNK_BYTES / stride).max(1));
    let mut records: Vec<u8> = Vec::new();
    let mut chunk: Vec<Vec3> = Vec::new();
    let mut payload: Vec<f32> = Vec::new();
    let mut first = 0;
    while first < npoints {
        let count = per_chunk.min(npoints - first);
        let start = r.pos;
        records.clear();
        r.fill_growing(
            &mut records,
            count * stride,
            &format!("points {first}..{} of {stride} bytes", first + count),
        )?;
        let data = &records[..];
        chunk.clear();
        payload.clear();
        for (k, rec) in data.chunks_exact(stride).enumerate() {
            let p = Vec3::new(f(&rec[0..4]), f(&rec[4..8]), f(&rec[8..12]));
            if !p.is_finite() {
                return Err(super::non_finite(
                    path,
                    format!(
                        "byte offset {} (decompressed), particle {}",
                        start + (k * stride) as u64,
                        first + k
                    ),
                    p,
                ));
            }
            chunk.push(p);
            for &(o, size, int) in &fields {
                for b in rec[o..o + 4 * size].chunks_exact(4) {
                    payload.push(if int {
                        i32::from_be_bytes(b.try_into().expect("4 bytes")) as f32
                    } else {
                        f(b)
                    });
                }
            }
        }
        sink(&chunk, &payload)?;
        first += count;
    }
    // The stream ends soon after the announced points: a header that undercounts (a
    // gzip of a few KiB can decompress to gigabytes) is an error, found after reading at
    // most `MAX_TRAILER_BYTES` more.
    let end = r.pos;
    let trailer = std::io::copy(
        &mut (&mut r.inner).take(MAX_TRAILER_BYTES + 1),
        &mut std::io::sink(),
    )
    .map_err(|e| {
        Error::parse(
            path,
            format!("byte offset {end} (decompressed)"),
            format!("cannot read past the points: {e}"),
        )
    })?;
    if trailer > MAX_TRAILER_BYTES {
        return Err(Error::parse(
            path,
            format!("byte offset {end} (decompressed)"),
            format!(
                "the data goes on past the {npoints} points the header announces (more than {MAX_TRAILER_BYTES} bytes follow the last point)"
            ),
        ));
    }
    Ok((npoints, layout))
}

/// Reads a whole BGEO file held in memory (gzip-compressed or plain).
pub(super) fn read(path: &Path, raw: &[u8]) -> Result<Particles> {
    let mut positions = Vec::new();
    let attributes = std::cell::RefCell::new(Vec::<Attribute>::new());
    parse(
        path,
        raw,
        &mut |_, declared| {
            // Every attribute, values gathered as the records come (no reservation from
            // the header's count).
            *attributes.borrow_mut() = declared
                .iter()
                .map(|l| Attribute {
                    name: l.name.clone(),
                    components: l.components,
                    values: Vec::new(),
                })
                .collect();
            Ok((0..declared.len()).collect())
        },
        &mut |chunk, rows| {
            positions.extend_from_slice(chunk);
            let mut attributes = attributes.borrow_mut();
            let width: usize = attributes.iter().map(|a| a.components).sum();
            for row in rows.chunks_exact(width.max(1)).take(chunk.len()) {
                let mut o = 0;
                for a in attributes.iter_mut() {
                    a.values.extend_from_slice(&row[o..o + a.components]);
                    o += a.components;
                }
            }
            Ok(())
        },
    )?;
    Ok(Particles {
        positions,
        attributes: attributes.into_inner(),
    })
}

/// Streams the positions of a BGEO file from disk in chunks of at most 65 536 particles,
/// decompressing as it goes; other attributes are skipped. Returns the particle count.
/// Memory: one chunk, whatever the file size.
pub fn stream_positions(
    path: &Path,
    positions: &mut dyn FnMut(&[Vec3]) -> Result<()>,
) -> Result<usize> {
    let (count, _) = parse(
        path,
        super::open_buffered(path)?,
        &mut |_, _| Ok(Vec::new()),
        &mut |chunk, _| positions(chunk),
    )?;
    Ok(count)
}

/// Streams the positions of a BGEO file and the payload rows of the attributes `select`
/// picks from its header, in chunks of at most 65 536 particles. Returns the particle
/// count and the selected layout. Memory: one chunk, whatever the file size.
pub(crate) fn stream(
    path: &Path,
    select: &mut Select<'_>,
    sink: &mut RecordSink<'_>,
) -> Result<(usize, Vec<AttributeLayout>)> {
    parse(path, super::open_buffered(path)?, select, sink)
}
