//! Base64 (standard alphabet, `=` padding) written as a stream: what the glTF writer
//! embeds as a `data:` URI, encoded chunk by chunk instead of as one copy of the buffer.

use std::io::{Result, Write};

/// Base64-encodes what is written to it (standard alphabet, `=` padding on `finish`).
pub(crate) struct Base64Writer<W: Write> {
    inner: W,
    /// Bytes of an incomplete 3-byte group.
    carry: Vec<u8>,
    /// Encoded text not yet written.
    out: Vec<u8>,
    /// Encoded bytes gathered before each write to `inner`.
    chunk_bytes: usize,
}

impl<W: Write> Write for Base64Writer<W> {
    fn write(&mut self, bytes: &[u8]) -> Result<usize> {
        let mut rest = bytes;
        if !self.carry.is_empty() {
            let take = (3 - self.carry.len()).min(rest.len());
            self.carry.extend_from_slice(&rest[..take]);
            rest = &rest[take..];
            if self.carry.len() < 3 {
                return Ok(bytes.len());
            }
            let group = std::mem::take(&mut self.carry);
            encode_base64(&group, &mut self.out);
        }
        let whole = rest.len() / 3 * 3;
        encode_base64(&rest[..whole], &mut self.out);
        self.carry.extend_from_slice(&rest[whole..]);
        if self.out.len() >= self.chunk_bytes {
            self.inner.write_all(&self.out)?;
            self.out.clear();
        }
        Ok(bytes.len())
    }

    fn flush(&mut self) -> Result<()> {
        self.inner.flush()
    }
}

impl<W: Write> Base64Writer<W> {
    /// An encoder writing to `inner` in pieces of about `chunk_bytes` encoded bytes.
    pub(crate) fn new(inner: W, chunk_bytes: usize) -> Self {
        Base64Writer {
            inner,
            carry: Vec::with_capacity(3),
            out: Vec::with_capacity(chunk_bytes / 3 * 4 + 8),
            chunk_bytes,
        }
    }

    /// Encodes the last bytes (padded) and writes what is left.
    pub(crate) fn finish(mut self) -> Result<()> {
        let tail = std::mem::take(&mut self.carry);
        encode_base64(&tail, &mut self.out);
        self.inner.write_all(&self.out)
    }
}

/// Appends the base64 text of `bytes` to `out` (padded when `bytes.len()` is not a
/// multiple of 3).
fn encode_base64(bytes: &[u8], out: &mut Vec<u8>) {
    const TABLE: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = ((b[0] as u32) << 16) | ((b[1] as u32) << 8) | b[2] as u32;
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(TABLE[((n >> (18 - 6 * k)) & 63) as usize]);
            } else {
                out.push(b'=');
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use std::io::Write;

    fn base64(bytes: &[u8]) -> String {
        let mut out = Vec::new();
        super::encode_base64(bytes, &mut out);
        String::from_utf8(out).unwrap()
    }

    #[test]
    fn base64_matches_known_vectors() {
        assert_eq!(base64(b""), "");
        assert_eq!(base64(b"f"), "Zg==");
        assert_eq!(base64(b"fo"), "Zm8=");
        assert_eq!(base64(b"foo"), "Zm9v");
        assert_eq!(base64(b"foobar"), "Zm9vYmFy");
    }

    #[test]
    fn streamed_base64_equals_one_shot_for_any_split() {
        let data: Vec<u8> = (0..1000u32).map(|i| (i * 7919 % 251) as u8).collect();
        for split in [1, 2, 3, 4, 5, 7, 64, 999] {
            let mut out = Vec::new();
            let mut w = super::Base64Writer::new(&mut out, 0);
            for piece in data.chunks(split) {
                w.write_all(piece).unwrap();
            }
            w.finish().unwrap();
            assert_eq!(
                String::from_utf8(out).unwrap(),
                base64(&data),
                "split {split}"
            );
        }
    }
}
