//! A byte cursor for formats that mix text headers and binary blocks (VTK, PLY), keeping
//! line numbers and byte offsets for error messages.

use crate::error::{Error, Result};
use std::path::Path;

/// Scalar types found in VTK and PLY files.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
}

impl Scalar {
    pub fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::I64 | Scalar::U64 | Scalar::F64 => 8,
        }
    }

    /// Decodes one value from exactly `size()` bytes.
    pub fn decode(self, b: &[u8], big_endian: bool) -> f64 {
        macro_rules! get {
            ($t:ty, $n:expr) => {{
                let mut a = [0u8; $n];
                a.copy_from_slice(&b[..$n]);
                (if big_endian {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }) as f64
            }};
        }
        match self {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => get!(i16, 2),
            Scalar::U16 => get!(u16, 2),
            Scalar::I32 => get!(i32, 4),
            Scalar::U32 => get!(u32, 4),
            Scalar::I64 => get!(i64, 8),
            Scalar::U64 => get!(u64, 8),
            Scalar::F32 => get!(f32, 4),
            Scalar::F64 => get!(f64, 8),
        }
    }
}

pub(crate) struct Cursor<'a> {
    pub path: &'a Path,
    pub bytes: &'a [u8],
    pub pos: usize,
    pub line: usize,
}

impl<'a> Cursor<'a> {
    pub fn new(path: &'a Path, bytes: &'a [u8]) -> Self {
        Cursor {
            path,
            bytes,
            pos: 0,
            line: 1,
        }
    }

    pub fn error(&self, message: impl Into<String>) -> Error {
        Error::parse(
            self.path,
            format!("line {} (byte offset {})", self.line, self.pos),
            message,
        )
    }

    pub fn at_end(&mut self) -> bool {
        self.skip_whitespace();
        self.pos >= self.bytes.len()
    }

    pub fn skip_whitespace(&mut self) {
        while let Some(&b) = self.bytes.get(self.pos) {
            if b == b'\n' {
                self.line += 1;
            } else if !b.is_ascii_whitespace() {
                break;
            }
            self.pos += 1;
        }
    }

    /// The next whitespace-separated token, or an error naming what was expected.
    pub fn token(&mut self, expected: &str) -> Result<&'a str> {
        self.skip_whitespace();
        let start = self.pos;
        while self
            .bytes
            .get(self.pos)
            .is_some_and(|b| !b.is_ascii_whitespace())
        {
            self.pos += 1;
        }
        if start == self.pos {
            return Err(self.error(format!("unexpected end of file, expected {expected}")));
        }
        std::str::from_utf8(&self.bytes[start..self.pos])
            .map_err(|_| self.error(format!("expected {expected}, found non-text bytes")))
    }

    /// The rest of the current line (without the newline), consuming the newline.
    pub fn line(&mut self) -> Result<&'a str> {
        let start = self.pos;
        while self.bytes.get(self.pos).is_some_and(|&b| b != b'\n') {
            self.pos += 1;
        }
        let text = &self.bytes[start..self.pos];
        if self.pos < self.bytes.len() {
            self.pos += 1;
            self.line += 1;
        }
        let text = std::str::from_utf8(text).map_err(|_| self.error("header line is not text"))?;
        Ok(text.trim_end_matches('\r'))
    }

    /// Parses the next token as a number of type `T`.
    pub fn number<T: std::str::FromStr>(&mut self, expected: &str) -> Result<T> {
        let token = self.token(expected)?;
        token
            .parse()
            .map_err(|_| self.error(format!("expected {expected}, found {token:?}")))
    }

    /// Skips the remainder of the current line including its newline (for binary blocks
    /// that start on the next line).
    pub fn finish_line(&mut self) {
        while let Some(&b) = self.bytes.get(self.pos) {
            self.pos += 1;
            if b == b'\n' {
                self.line += 1;
                break;
            }
        }
    }

    /// The next value of type `scalar`, binary or ASCII.
    pub fn value(&mut self, scalar: Scalar, binary: Option<bool>) -> Result<f32> {
        match binary {
            Some(big_endian) => {
                let size = scalar.size();
                if self.bytes.len() - self.pos < size {
                    return Err(self.error(format!(
                        "truncated: a {size}-byte value, {} bytes left",
                        self.bytes.len() - self.pos
                    )));
                }
                let v = scalar.decode(&self.bytes[self.pos..self.pos + size], big_endian);
                self.pos += size;
                Ok(v as f32)
            }
            None => {
                let token = self.token("a number")?;
                token
                    .parse::<f64>()
                    .map(|v| v as f32)
                    .map_err(|_| self.error(format!("expected a number, found {token:?}")))
            }
        }
    }

    /// The next `count` values as exact non-negative integers (indices), binary or ASCII.
    pub fn indices(
        &mut self,
        count: usize,
        scalar: Scalar,
        binary: Option<bool>,
    ) -> Result<Vec<u32>> {
        let mut out = Vec::with_capacity(count.min(1 << 20));
        for _ in 0..count {
            let v = match binary {
                Some(big_endian) => {
                    let size = scalar.size();
                    if self.bytes.len() - self.pos < size {
                        return Err(self.error(format!(
                            "truncated: a {size}-byte index, {} bytes left",
                            self.bytes.len() - self.pos
                        )));
                    }
                    let v = scalar.decode(&self.bytes[self.pos..self.pos + size], big_endian);
                    self.pos += size;
                    v
                }
                None => {
                    let token = self.token("an index")?;
                    token
                        .parse::<f64>()
                        .map_err(|_| self.error(format!("expected an index, found {token:?}")))?
                }
            };
            if !(0.0..=u32::MAX as f64).contains(&v) || v.fract() != 0.0 {
                return Err(self.error(format!("bad vertex index {v}")));
            }
            out.push(v as u32);
        }
        Ok(out)
    }

    /// Skips `count` values of type `scalar`, binary or ASCII.
    pub fn skip_values(
        &mut self,
        count: usize,
        scalar: Scalar,
        binary: Option<bool>,
    ) -> Result<()> {
        match binary {
            Some(_) => {
                let need = count
                    .checked_mul(scalar.size())
                    .ok_or_else(|| self.error("value count overflows"))?;
                if self.bytes.len() - self.pos < need {
                    return Err(self.error(format!(
                        "truncated: a block of {need} bytes, {} left",
                        self.bytes.len() - self.pos
                    )));
                }
                self.pos += need;
            }
            None => {
                for _ in 0..count {
                    self.token("a number")?;
                }
            }
        }
        Ok(())
    }

    /// The next `count` values of type `scalar`, binary (with `big_endian`) or ASCII.
    pub fn values(
        &mut self,
        count: usize,
        scalar: Scalar,
        binary: Option<bool>,
    ) -> Result<Vec<f32>> {
        match binary {
            Some(big_endian) => {
                let size = scalar.size();
                let need = count
                    .checked_mul(size)
                    .ok_or_else(|| self.error("value count overflows"))?;
                if self.bytes.len() - self.pos < need {
                    return Err(self.error(format!(
                        "truncated: {count} values of {size} bytes need {need} bytes, {} left",
                        self.bytes.len() - self.pos
                    )));
                }
                let out = self.bytes[self.pos..self.pos + need]
                    .chunks_exact(size)
                    .map(|c| scalar.decode(c, big_endian) as f32)
                    .collect();
                self.pos += need;
                Ok(out)
            }
            None => {
                // Every ASCII value takes at least one byte: reserve no more than that.
                let left = self.bytes.len().saturating_sub(self.pos);
                let mut out = Vec::with_capacity(count.min(left).min(1 << 24));
                for _ in 0..count {
                    let token = self.token("a number")?;
                    let v: f64 = token
                        .parse()
                        .map_err(|_| self.error(format!("expected a number, found {token:?}")))?;
                    out.push(v as f32);
                }
                Ok(out)
            }
        }
    }
}
