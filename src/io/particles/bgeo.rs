//! Houdini "classic" BGEO, version 5, as partio and SPlisHSPlasH write it; gzip-compressed
//! (detected by the gzip magic bytes) or plain. After decompression all values are
//! big-endian:
//!
//! `"Bgeo" 'V'`, 9 × i32 (version, points, primitives, point groups, primitive groups,
//! point attributes, vertex attributes, primitive attributes, detail attributes), the point
//! attribute definitions (u16 name length, name, u16 size, i32 type, `size` default
//! values), then per point `P[4]` (x, y, z, w) as f32 followed by every attribute's values.
//! Attribute types kept: 0 float, 1 int (as f32), 5 vector. Others are rejected.

use super::{Particles, PointAttribute};
use crate::error::{Error, Result};
use glam::Vec3;
use std::io::Read;
use std::path::Path;

struct Reader<'a> {
    path: &'a Path,
    bytes: &'a [u8],
    pos: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize, what: &str) -> Result<&[u8]> {
        if self.bytes.len() - self.pos < n {
            return Err(Error::parse(
                self.path,
                format!("byte offset {} (decompressed)", self.pos),
                format!(
                    "truncated while reading {what}: need {n} bytes, {} left",
                    self.bytes.len() - self.pos
                ),
            ));
        }
        let s = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn i32(&mut self, what: &str) -> Result<i32> {
        Ok(i32::from_be_bytes(
            self.take(4, what)?.try_into().expect("4 bytes"),
        ))
    }
    fn u16(&mut self, what: &str) -> Result<u16> {
        Ok(u16::from_be_bytes(
            self.take(2, what)?.try_into().expect("2 bytes"),
        ))
    }
}

pub(super) fn read(path: &Path, raw: &[u8]) -> Result<Particles> {
    let decompressed;
    let bytes: &[u8] = if raw.starts_with(&[0x1f, 0x8b]) {
        let mut out = Vec::new();
        flate2::read::MultiGzDecoder::new(raw)
            .read_to_end(&mut out)
            .map_err(|e| Error::parse(path, "gzip stream", format!("cannot decompress: {e}")))?;
        decompressed = out;
        &decompressed
    } else {
        raw
    };
    let mut r = Reader {
        path,
        bytes,
        pos: 0,
    };
    let magic = r.take(5, "the magic number")?;
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
        let name = String::from_utf8_lossy(r.take(len, "an attribute name")?).into_owned();
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
        r.take(4 * size, "attribute defaults")?;
        defs.push((name, size, ty));
    }
    let npoints = npoints as usize;
    let stride = 16 + defs.iter().map(|d| 4 * d.1).sum::<usize>();
    let need = npoints
        .checked_mul(stride)
        .ok_or_else(|| Error::parse(path, "header", "point count overflows"))?;
    let start = r.pos;
    let data = r.take(need, &format!("{npoints} points of {stride} bytes"))?;
    let f = |b: &[u8]| f32::from_be_bytes(b.try_into().expect("4 bytes"));
    let mut positions = Vec::with_capacity(npoints);
    let mut attributes: Vec<PointAttribute> = defs
        .iter()
        .map(|(name, size, _)| PointAttribute {
            name: name.clone(),
            components: *size,
            values: Vec::with_capacity(npoints * size),
        })
        .collect();
    for (i, rec) in data.chunks_exact(stride).enumerate() {
        let p = Vec3::new(f(&rec[0..4]), f(&rec[4..8]), f(&rec[8..12]));
        if !p.is_finite() {
            return Err(Error::parse(
                path,
                format!(
                    "byte offset {} (decompressed), particle {i}",
                    start + i * stride
                ),
                format!("non-finite coordinate {p}"),
            ));
        }
        positions.push(p);
        let mut o = 16;
        for (attr, (_, size, ty)) in attributes.iter_mut().zip(&defs) {
            for k in 0..*size {
                let b = &rec[o + 4 * k..o + 4 * k + 4];
                attr.values.push(if *ty == 1 {
                    i32::from_be_bytes(b.try_into().expect("4 bytes")) as f32
                } else {
                    f(b)
                });
            }
            o += 4 * size;
        }
    }
    Ok(Particles {
        positions,
        attributes,
    })
}
