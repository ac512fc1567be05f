//! Houdini "classic" BGEO, version 5, as partio and SPlisHSPlasH write it; gzip-compressed
//! (detected by the gzip magic bytes) or plain. After decompression all values are
//! big-endian:
//!
//! `"Bgeo" 'V'`, 9 × i32 (version, points, primitives, point groups, primitive groups,
//! point attributes, vertex attributes, primitive attributes, detail attributes), the point
//! attribute definitions (u16 name length, name, u16 size, i32 type, `size` default
//! values), then per point `P[4]` (x, y, z, w) as f32 followed by every attribute's values.
//! Attribute types kept: 0 float, 1 int (as f32), 5 vector. Others are rejected.

use super::records::{non_finite, open_buffered};
use super::{read_bytes, Attribute, ParticleCodec, Particles, StreamSink};
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

/// Most bytes a BGEO stream may hold after its point records (primitives, detail
/// attributes, the two-byte extra block partio writes) before it counts as data the
/// header did not announce.
const MAX_TRAILER_BYTES: u64 = 1 << 20;

/// The BGEO format.
pub(super) struct Bgeo;

impl ParticleCodec for Bgeo {
    /// Reads a whole BGEO file (gzip-compressed or plain) into memory first.
    fn read(&self, path: &Path) -> Result<Particles> {
        let raw = read_bytes(path)?;
        let mut all = Collect::default();
        parse(path, &raw[..], &mut all)?;
        Ok(all.particles)
    }

    /// Every BGEO file streams, decompressing as it goes.
    fn stream(&self, path: &Path, sink: &mut dyn StreamSink) -> Result<Option<usize>> {
        parse(path, open_buffered(path)?, sink).map(Some)
    }

    fn write(&self, path: &Path, _particles: &Particles) -> Result<()> {
        Err(Error::UnsupportedFormat {
            path: path.to_path_buf(),
            message: "writing BGEO is not supported; write .xyz, .vtk or .ply".into(),
        })
    }
}

/// The whole-file reader's sink: every attribute, values gathered as the records come
/// (no reservation from the header's count).
#[derive(Default)]
struct Collect {
    particles: Particles,
}

impl StreamSink for Collect {
    fn select(&mut self, _: usize, declared: &[AttributeLayout]) -> Result<Vec<usize>> {
        self.particles.attributes = declared
            .iter()
            .map(|l| Attribute {
                name: l.name.clone(),
                components: l.components,
                values: Vec::new(),
            })
            .collect();
        Ok((0..declared.len()).collect())
    }
    fn records(&mut self, positions: &[Vec3], rows: &[f32]) -> Result<()> {
        self.particles.positions.extend_from_slice(positions);
        let attributes = &mut self.particles.attributes;
        let width: usize = attributes.iter().map(|a| a.components).sum();
        for row in rows.chunks_exact(width.max(1)).take(positions.len()) {
            let mut o = 0;
            for a in attributes.iter_mut() {
                a.values.extend_from_slice(&row[o..o + a.components]);
                o += a.components;
            }
        }
        Ok(())
    }
    fn array(&mut self, _: usize, _: &[f32]) -> Result<()> {
        Ok(())
    }
}

/// A point attribute as the header defines it.
struct Definition {
    name: String,
    /// Components (4-byte values).
    size: usize,
    /// 0 float, 1 int, 5 vector.
    ty: i32,
}

/// Parses a BGEO stream (gzip detected by its magic bytes) chunk by chunk: once the
/// header is read, [`StreamSink::select`] picks the attributes to carry; then positions
/// and the selected attributes' payload rows (in the selection's order) go to `sink` in
/// chunks of at most [`CHUNK_POINTS`]. Returns the point count. Memory: one chunk of
/// records.
fn parse<'a, R: BufRead + 'a>(
    path: &'a Path,
    source: R,
    sink: &mut dyn StreamSink,
) -> Result<usize> {
    let mut r = open(path, source)?;
    let (npoints, defs) = read_header(&mut r)?;
    let declared: Vec<AttributeLayout> = defs
        .iter()
        .map(|d| AttributeLayout {
            name: d.name.clone(),
            components: d.size,
        })
        .collect();
    let chosen = sink.select(npoints, &declared)?;
    // Byte offset in the record, components and int-ness of each selected attribute.
    let mut at = Vec::with_capacity(defs.len());
    let mut stride = 16;
    for d in &defs {
        at.push((stride, d.size, d.ty == 1));
        stride += 4 * d.size;
    }
    let fields: Vec<(usize, usize, bool)> = chosen.iter().map(|&k| at[k]).collect();
    read_points(&mut r, npoints, stride, &fields, sink)?;
    check_trailer(&mut r, npoints)?;
    Ok(npoints)
}

/// The decompressed stream of `source` (gzip detected by its magic bytes).
fn open<'a, R: BufRead + 'a>(path: &'a Path, mut source: R) -> Result<Stream<'a>> {
    let gzip = source
        .fill_buf()
        .map_err(|e| Error::io(path, e))?
        .starts_with(&[0x1f, 0x8b]);
    let inner: Box<dyn Read + 'a> = if gzip {
        Box::new(flate2::bufread::MultiGzDecoder::new(source))
    } else {
        Box::new(source)
    };
    Ok(Stream {
        path,
        inner,
        pos: 0,
    })
}

/// The magic, version, counts and point attribute definitions; returns the point count
/// and the definitions, once the records they describe are known to be addressable.
fn read_header(r: &mut Stream) -> Result<(usize, Vec<Definition>)> {
    let path = r.path;
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
    let mut defs = Vec::new();
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
        defs.push(Definition { name, size, ty });
    }
    let npoints = npoints as usize;
    let stride = 16 + defs.iter().map(|d| 4 * d.size).sum::<usize>();
    npoints
        .checked_mul(stride)
        .ok_or_else(|| Error::parse(path, "header", "point count overflows"))?;
    Ok((npoints, defs))
}

/// Reads the `npoints` records of `stride` bytes and hands each chunk's positions and the
/// payload rows of `fields` (byte offset, components, int-ness) to `sink`.
fn read_points(
    r: &mut Stream,
    npoints: usize,
    stride: usize,
    fields: &[(usize, usize, bool)],
    sink: &mut dyn StreamSink,
) -> Result<()> {
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
        chunk.clear();
        payload.clear();
        for (k, rec) in records.chunks_exact(stride).enumerate() {
            let p = Vec3::new(f(&rec[0..4]), f(&rec[4..8]), f(&rec[8..12]));
            if !p.is_finite() {
                return Err(non_finite(
                    r.path,
                    format!(
                        "byte offset {} (decompressed), particle {}",
                        start + (k * stride) as u64,
                        first + k
                    ),
                    p,
                ));
            }
            chunk.push(p);
            for &(o, size, int) in fields {
                for b in rec[o..o + 4 * size].chunks_exact(4) {
                    payload.push(if int {
                        i32::from_be_bytes(b.try_into().expect("4 bytes")) as f32
                    } else {
                        f(b)
                    });
                }
            }
        }
        sink.records(&chunk, &payload)?;
        first += count;
    }
    Ok(())
}

/// The stream ends soon after the announced points: a header that undercounts (a gzip of
/// a few KiB can decompress to gigabytes) is an error, found after reading at most
/// [`MAX_TRAILER_BYTES`] more.
fn check_trailer(r: &mut Stream, npoints: usize) -> Result<()> {
    let end = r.pos;
    let trailer = std::io::copy(
        &mut (&mut r.inner).take(MAX_TRAILER_BYTES + 1),
        &mut std::io::sink(),
    )
    .map_err(|e| {
        Error::parse(
            r.path,
            format!("byte offset {end} (decompressed)"),
            format!("cannot read past the points: {e}"),
        )
    })?;
    if trailer > MAX_TRAILER_BYTES {
        return Err(Error::parse(
            r.path,
            format!("byte offset {end} (decompressed)"),
            format!(
                "the data goes on past the {npoints} points the header announces (more than {MAX_TRAILER_BYTES} bytes follow the last point)"
            ),
        ));
    }
    Ok(())
}
