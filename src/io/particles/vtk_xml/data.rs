//! The values of one VTK XML `DataArray`, streamed from the file: base64 decoded (inline
//! `binary` data, base64 appended data) or raw (raw appended data), the block header read
//! and checked against the count the piece announces, and zlib or LZ4 blocks inflated one
//! at a time. Memory: one block (VTK writes 32 KiB blocks) and one chunk of values.

use super::scan::{Array, Compressor, Layout, Location};
use crate::error::{Error, Result};
use std::io::{BufRead, Read, Seek};

/// Largest inflation of one compressed block that is believed, by compressor: zlib's
/// limit is 1032:1, LZ4's 255:1 (a match of `15 + 255·n + 4` bytes costs `n + 3`). A
/// header claiming more is refused before anything is allocated.
fn max_ratio(compressor: Compressor) -> u64 {
    match compressor {
        Compressor::Lz4 => 255,
        _ => 1032,
    }
}

/// The bytes an LZ4 block inflates to, read from its sequences' length fields without
/// inflating it (so that a block is never given a buffer larger than it fills); `None`
/// when the lengths run past the block's end.
fn lz4_inflated_len(block: &[u8]) -> Option<u64> {
    let mut pos = 0usize;
    let mut total = 0u64;
    let length = |pos: &mut usize, nibble: u8| -> Option<u64> {
        let mut n = nibble as u64;
        if nibble == 15 {
            loop {
                let b = *block.get(*pos)?;
                *pos += 1;
                n += b as u64;
                if b != 255 {
                    break;
                }
            }
        }
        Some(n)
    };
    loop {
        let token = *block.get(pos)?;
        pos += 1;
        let literals = length(&mut pos, token >> 4)?;
        pos = pos.checked_add(usize::try_from(literals).ok()?)?;
        if pos > block.len() {
            return None;
        }
        total += literals;
        if pos == block.len() {
            return Some(total);
        }
        // A match: a 2-byte offset and its length (at least 4).
        pos += 2;
        if pos > block.len() {
            return None;
        }
        total += length(&mut pos, token & 15)? + 4;
    }
}

/// An `InvalidData` I/O error carrying `message` (what the value decoders report).
fn invalid(message: String) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidData, message)
}

/// Decodes base64 text read from `inner` (whitespace skipped, `=` padding allowed between
/// units, as VTK writes a compressed array's header and blocks as two units), stopping at
/// `<` or after `len` bytes of text. `offset` is the file offset of the text, for errors.
struct Base64<R> {
    inner: R,
    /// Text bytes left to read.
    left: u64,
    offset: u64,
    out: [u8; 3],
    out_len: usize,
    out_pos: usize,
    done: bool,
}

impl<R: BufRead> Base64<R> {
    fn new(inner: R, offset: u64, len: u64) -> Self {
        Base64 {
            inner,
            left: len,
            offset,
            out: [0; 3],
            out_len: 0,
            out_pos: 0,
            done: false,
        }
    }

    /// The next character that is not whitespace; `None` at the end of the text.
    fn next_char(&mut self) -> std::io::Result<Option<u8>> {
        loop {
            if self.left == 0 {
                return Ok(None);
            }
            let buf = self.inner.fill_buf()?;
            let Some(&b) = buf.first() else {
                return Ok(None);
            };
            if b == b'<' {
                return Ok(None);
            }
            self.inner.consume(1);
            self.left -= 1;
            self.offset += 1;
            if !b.is_ascii_whitespace() {
                return Ok(Some(b));
            }
        }
    }

    /// Decodes the next unit of four characters into `out`.
    fn fill(&mut self) -> std::io::Result<()> {
        let mut quad = [0u8; 4];
        let mut n = 0;
        while n < 4 {
            match self.next_char()? {
                Some(c) => {
                    quad[n] = c;
                    n += 1;
                }
                None if n == 0 => {
                    self.done = true;
                    return Ok(());
                }
                None => {
                    return Err(invalid(format!(
                        "base64 text ends inside a group of four characters (byte offset {})",
                        self.offset
                    )))
                }
            }
        }
        let mut bits = 0u32;
        let mut padding = 0;
        for (k, &c) in quad.iter().enumerate() {
            let v = match c {
                b'A'..=b'Z' => c - b'A',
                b'a'..=b'z' => c - b'a' + 26,
                b'0'..=b'9' => c - b'0' + 52,
                b'+' => 62,
                b'/' => 63,
                b'=' if k >= 2 => {
                    padding += 1;
                    0
                }
                _ => {
                    return Err(invalid(format!(
                        "bad base64 character {:?} at byte offset {}",
                        c as char,
                        self.offset - 4 + k as u64
                    )))
                }
            };
            if padding > 0 && c != b'=' {
                return Err(invalid(format!(
                    "bad base64 padding at byte offset {}",
                    self.offset - 4 + k as u64
                )));
            }
            bits = (bits << 6) | v as u32;
        }
        self.out = [(bits >> 16) as u8, (bits >> 8) as u8, bits as u8];
        self.out_len = 3 - padding;
        self.out_pos = 0;
        Ok(())
    }
}

impl<R: BufRead> Read for Base64<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let mut written = 0;
        while written < buf.len() {
            if self.out_pos == self.out_len {
                if self.done {
                    break;
                }
                self.fill()?;
                continue;
            }
            let n = (self.out_len - self.out_pos).min(buf.len() - written);
            buf[written..written + n].copy_from_slice(&self.out[self.out_pos..self.out_pos + n]);
            self.out_pos += n;
            written += n;
        }
        Ok(written)
    }
}

/// Inflates compressed blocks one at a time.
struct Blocks<R> {
    inner: R,
    compressor: Compressor,
    /// Compressed and uncompressed size of each block.
    sizes: Vec<(u64, u64)>,
    next: usize,
    compressed: Vec<u8>,
    block: Vec<u8>,
    pos: usize,
}

impl<R: Read> Blocks<R> {
    fn load(&mut self) -> std::io::Result<()> {
        let (c, u) = self.sizes[self.next];
        let (k, n) = (self.next, self.sizes.len());
        self.next += 1;
        self.compressed.clear();
        (&mut self.inner)
            .take(c)
            .read_to_end(&mut self.compressed)?;
        if (self.compressed.len() as u64) < c {
            return Err(invalid(format!(
                "truncated: compressed block {k} of {n} needs {c} bytes, the data ends after {}",
                self.compressed.len()
            )));
        }
        self.block.clear();
        let inflated = match self.compressor {
            Compressor::Zlib => flate2::read::ZlibDecoder::new(&self.compressed[..])
                .take(u + 1)
                .read_to_end(&mut self.block)
                .map_err(|e| e.to_string()),
            Compressor::Lz4 if lz4_inflated_len(&self.compressed) != Some(u) => {
                Err(match lz4_inflated_len(&self.compressed) {
                    Some(n) => format!("its sequences make {n} bytes"),
                    None => "its sequences run past its end".to_string(),
                })
            }
            Compressor::Lz4 => {
                self.block.resize(u as usize, 0);
                lz4_flex::block::decompress_into(&self.compressed, &mut self.block)
                    .inspect(|&n| self.block.truncate(n))
                    .map_err(|e| e.to_string())
            }
            Compressor::None => unreachable!("blocks are compressed"),
        };
        let name = match self.compressor {
            Compressor::Lz4 => "lz4",
            _ => "zlib",
        };
        match inflated {
            Err(e) => Err(invalid(format!(
                "compressed block {k} of {n} does not inflate ({name}: {e})"
            ))),
            Ok(_) if self.block.len() as u64 != u => Err(invalid(format!(
                "compressed block {k} of {n} inflates to {} bytes, its header says {u}",
                self.block.len()
            ))),
            Ok(_) => {
                self.pos = 0;
                Ok(())
            }
        }
    }
}

impl<R: Read> Read for Blocks<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        while self.pos == self.block.len() {
            if self.next == self.sizes.len() {
                return Ok(0);
            }
            self.load()?;
        }
        let n = (self.block.len() - self.pos).min(buf.len());
        buf[..n].copy_from_slice(&self.block[self.pos..self.pos + n]);
        self.pos += n;
        Ok(n)
    }
}

/// A byte stream of an array's values with the error location of the array.
pub(super) type Values = Box<dyn Read>;

impl Layout {
    /// Where `array` is, for errors.
    pub(super) fn location(&self, array: &Array) -> String {
        format!("DataArray {:?} (line {})", array.name, array.line)
    }

    /// An error at `array`.
    pub(super) fn error(&self, array: &Array, message: impl Into<String>) -> Error {
        Error::parse(&self.path, self.location(array), message)
    }

    fn open_at(&self, offset: u64) -> Result<std::io::BufReader<std::fs::File>> {
        let mut file = std::fs::File::open(&self.path).map_err(|e| Error::io(&self.path, e))?;
        file.seek(std::io::SeekFrom::Start(offset))
            .map_err(|e| Error::io(&self.path, e))?;
        Ok(std::io::BufReader::with_capacity(1 << 16, file))
    }

    /// The encoded bytes of a binary array (header, then data), and how many bytes of the
    /// file they may take at most.
    fn encoded(&self, array: &Array) -> Result<(Box<dyn Read>, u64)> {
        let (start, len, base64) = match (array.location, self.appended) {
            (Location::Binary { offset, len }, _) => (offset, len, true),
            (Location::Appended { offset }, Some(a)) => {
                let start = a.offset.checked_add(offset).filter(|&s| s <= self.file_len);
                let start = start.ok_or_else(|| {
                    self.error(
                        array,
                        format!(
                            "truncated appended data: offset {offset} is past the end of the file"
                        ),
                    )
                })?;
                (start, self.file_len - start, a.base64)
            }
            (Location::Appended { .. }, None) => {
                return Err(self.error(array, "format=\"appended\" but no <AppendedData>"))
            }
            (Location::Ascii { .. }, _) => unreachable!("ascii is read as text"),
        };
        let r = self.open_at(start)?;
        Ok(if base64 {
            (Box::new(Base64::new(r, start, len)), len / 4 * 3)
        } else {
            (Box::new(r.take(len)), len)
        })
    }

    /// Reads one header word.
    fn word(&self, array: &Array, r: &mut dyn Read, what: &str) -> Result<u64> {
        let mut b = [0u8; 8];
        let n = if self.header64 { 8 } else { 4 };
        r.read_exact(&mut b[..n]).map_err(|e| {
            self.error(
                array,
                if e.kind() == std::io::ErrorKind::UnexpectedEof {
                    format!("truncated: the data ends inside the block header ({what})")
                } else {
                    format!("cannot read the block header: {e}")
                },
            )
        })?;
        Ok(match (self.header64, self.big_endian) {
            (true, false) => u64::from_le_bytes(b),
            (true, true) => u64::from_be_bytes(b),
            (false, false) => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as u64,
            (false, true) => u32::from_be_bytes([b[0], b[1], b[2], b[3]]) as u64,
        })
    }

    /// The header type, for errors about sizes.
    fn header_name(&self) -> &'static str {
        if self.header64 {
            "UInt64"
        } else {
            "UInt32"
        }
    }

    /// The values of binary `array` as a byte stream of exactly `values` values: the block
    /// header is read and checked (its size against `values`, the compressed sizes against
    /// the file) before anything else is read or allocated.
    pub(super) fn values(&self, array: &Array, values: usize) -> Result<Values> {
        let size = array.scalar.size() as u64;
        let want = (values as u64).checked_mul(size).ok_or_else(|| {
            self.error(array, format!("{values} values of {size} bytes overflow"))
        })?;
        let (mut r, room) = self.encoded(array)?;
        let mismatch = |said: u64| {
            self.error(
                array,
                format!(
                    "the block header says {said} bytes of data, {} points of {} values of \
                     {size} bytes need {want} (a NumberOfPoints the data contradicts, or a \
                     header_type of {} the file does not use)",
                    values / array.components,
                    array.components,
                    self.header_name()
                ),
            )
        };
        if self.compressor == Compressor::None {
            let said = self.word(array, &mut r, "the data size")?;
            if said != want {
                return Err(mismatch(said));
            }
            if said > room {
                return Err(self.error(
                    array,
                    format!("truncated: {said} bytes of data, the file holds at most {room} more"),
                ));
            }
            return Ok(Box::new(r.take(said)));
        }
        let blocks = self.word(array, &mut r, "the block count")?;
        let block_size = self.word(array, &mut r, "the block size")?;
        let last = self.word(array, &mut r, "the last block's size")?;
        let last = if last == 0 { block_size } else { last };
        let said = match blocks {
            0 => 0,
            n => (n - 1)
                .checked_mul(block_size)
                .and_then(|s| s.checked_add(last))
                .unwrap_or(u64::MAX),
        };
        if said != want || last > block_size {
            return Err(mismatch(said));
        }
        let word = if self.header64 { 8 } else { 4 };
        if blocks.saturating_mul(word) > room {
            return Err(self.error(
                array,
                format!("truncated: {blocks} compressed blocks, the file cannot hold their sizes"),
            ));
        }
        let mut sizes = Vec::with_capacity(blocks as usize);
        let mut total = 0u64;
        for k in 0..blocks {
            let c = self.word(array, &mut r, "a compressed block size")?;
            let u = if k + 1 == blocks { last } else { block_size };
            if u > c
                .saturating_mul(max_ratio(self.compressor))
                .saturating_add(64)
            {
                return Err(self.error(
                    array,
                    format!("compressed block {k} of {blocks}: {c} bytes cannot inflate to {u}"),
                ));
            }
            total = total.saturating_add(c);
            sizes.push((c, u));
        }
        if total > room {
            return Err(self.error(
                array,
                format!(
                    "truncated: the compressed blocks take {total} bytes, the file holds at most {room} more"
                ),
            ));
        }
        Ok(Box::new(Blocks {
            inner: r,
            compressor: self.compressor,
            sizes,
            next: 0,
            compressed: Vec::new(),
            block: Vec::new(),
            pos: 0,
        }))
    }

    /// The text of ascii `array`, positioned at its first value, after checking that it
    /// can hold `values` numbers; with the line it starts on.
    pub(super) fn text(
        &self,
        array: &Array,
        values: usize,
    ) -> Result<(std::io::Take<std::io::BufReader<std::fs::File>>, usize)> {
        let Location::Ascii { offset, line, len } = array.location else {
            unreachable!("an ascii array")
        };
        if (values as u64).saturating_mul(2) > len.saturating_add(1) {
            return Err(self.error(
                array,
                format!("truncated: {values} values cannot fit in its {len} bytes of text"),
            ));
        }
        Ok((self.open_at(offset)?.take(len), line))
    }

    /// Checks that `array` can hold `values` values (see [`Layout::values`],
    /// [`Layout::text`]) without decoding them.
    pub(super) fn check(&self, array: &Array, values: usize) -> Result<()> {
        match array.location {
            Location::Ascii { .. } => self.text(array, values).map(|_| ()),
            _ => self.values(array, values).map(|_| ()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn decode(text: &str) -> std::io::Result<Vec<u8>> {
        let mut out = Vec::new();
        Base64::new(text.as_bytes(), 0, text.len() as u64).read_to_end(&mut out)?;
        Ok(out)
    }

    #[test]
    fn base64_decodes_units_with_padding_between_them() {
        assert_eq!(decode("Zm9vYmFy").unwrap(), b"foobar");
        assert_eq!(decode(" Zm9v\nYg==Zm8= </x>").unwrap(), b"foobfo");
        assert_eq!(decode("").unwrap(), b"");
        let e = decode("Zm9#").unwrap_err().to_string();
        assert!(
            e.contains("bad base64 character '#' at byte offset 3"),
            "{e}"
        );
        let e = decode("Zm9").unwrap_err().to_string();
        assert!(e.contains("ends inside a group"), "{e}");
        assert!(decode("Z=9v").is_err());
        assert!(decode("Zm=v").is_err());
    }
}
