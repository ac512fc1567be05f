//! The two compressions of the crate (`usdc`) format: the integer coding of int arrays
//! and structural tables, and LZ4 blocks in the chunked framing Pixar's readers expect.
//!
//! **Integer coding.** A list of `n` 32-bit integers becomes the list of differences to
//! the previous one (the first to 0), then: a common difference (4 bytes; here the most
//! common one that fits an `i16`, the largest on a tie), a 2-bit code per integer (four to a byte, lowest bits first:
//! 0 the common difference, 1 an `i8`, 2 an `i16`, 3 an `i32` follows), and the
//! differences that are not the common one, in order, each in the size its code says.
//! Arithmetic wraps, so any `u32` or `i32` sequence round-trips.
//!
//! **LZ4 framing.** One leading byte: 0 for a single LZ4 block holding everything (inputs
//! up to [`LZ4_CHUNK`] bytes), else the number of chunks, each an `i32` byte count and an
//! LZ4 block of at most [`LZ4_CHUNK`] input bytes.

use std::io;

/// Largest input of one LZ4 block in the framing (LZ4's own maximum input size).
pub(crate) const LZ4_CHUNK: usize = 0x7E00_0000;

/// Most chunks the framing's leading byte can count.
const MAX_CHUNKS: usize = 127;

/// Code of a difference: the common one, or the width that holds it.
fn code(delta: i32, common: i32) -> (u8, usize) {
    if delta == common {
        (0, 0)
    } else if i8::try_from(delta).is_ok() {
        (1, 1)
    } else if i16::try_from(delta).is_ok() {
        (2, 2)
    } else {
        (3, 4)
    }
}

/// The differences of `values` to their predecessors (the first to 0), wrapping.
fn deltas(values: impl Iterator<Item = i32>, len: usize) -> Vec<i32> {
    let mut out = Vec::with_capacity(len);
    let mut previous = 0i32;
    for v in values {
        out.push(v.wrapping_sub(previous));
        previous = v;
    }
    out
}

/// The most common of `deltas` among those that fit an `i16`, the largest on a tie (0
/// when none fits). Counting in a table keeps this linear and cheap; a difference beyond
/// an `i16` repeated more often than every small one (rare in indices and tables) would
/// only cost size: any common value decodes.
fn most_common(deltas: &[i32]) -> i32 {
    let mut counts = vec![0u32; 1 << 16];
    for &d in deltas {
        if let Ok(s) = i16::try_from(d) {
            counts[(s as i32 + 32768) as usize] += 1;
        }
    }
    // Largest count, then largest value.
    let (count, value) = counts
        .iter()
        .enumerate()
        .map(|(i, &c)| (c, i as i32 - 32768))
        .max()
        .expect("a non-empty table");
    if count == 0 {
        0
    } else {
        value
    }
}

/// The integer coding of the `len` integers `values` yields.
pub(crate) fn encode_ints(len: usize, values: impl Iterator<Item = i32>) -> Vec<u8> {
    let deltas = deltas(values, len);
    if deltas.is_empty() {
        return Vec::new();
    }
    let common = most_common(&deltas);
    let codes = 4;
    let mut vints = codes + deltas.len().div_ceil(4);
    let mut out = vec![0u8; vints + 4 * deltas.len()];
    out[..4].copy_from_slice(&common.to_le_bytes());
    for (k, group) in deltas.chunks(4).enumerate() {
        let mut byte = 0u8;
        for (i, &d) in group.iter().enumerate() {
            let (c, width) = code(d, common);
            byte |= c << (2 * i);
            out[vints..vints + width].copy_from_slice(&d.to_le_bytes()[..width]);
            vints += width;
        }
        out[codes + k] = byte;
    }
    out.truncate(vints);
    out
}

/// `input` as LZ4 blocks in the chunked framing, chunks of at most `chunk` bytes.
fn lz4_framed_in(input: &[u8], chunk: usize) -> io::Result<Vec<u8>> {
    if input.len() <= chunk {
        let mut out = Vec::with_capacity(1 + lz4_flex::block::get_maximum_output_size(input.len()));
        out.push(0);
        out.extend_from_slice(&lz4_flex::block::compress(input));
        return Ok(out);
    }
    let chunks = input.len().div_ceil(chunk);
    if chunks > MAX_CHUNKS {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!(
                "{} bytes are more than one crate value can hold",
                input.len()
            ),
        ));
    }
    let mut out = vec![chunks as u8];
    for piece in input.chunks(chunk) {
        let block = lz4_flex::block::compress(piece);
        out.extend_from_slice(&(block.len() as i32).to_le_bytes());
        out.extend_from_slice(&block);
    }
    Ok(out)
}

/// `input` as LZ4 blocks in the chunked framing.
pub(crate) fn lz4_framed(input: &[u8]) -> io::Result<Vec<u8>> {
    lz4_framed_in(input, LZ4_CHUNK)
}

/// The compressed form of an int array or table: integer coding, then LZ4.
pub(crate) fn compress_ints(len: usize, values: impl Iterator<Item = i32>) -> io::Result<Vec<u8>> {
    lz4_framed(&encode_ints(len, values))
}

#[cfg(test)]
pub(crate) mod decode {
    //! Readers of both compressions, for the tests (the writer never reads back).

    /// The `len` integers of an integer coding.
    pub(crate) fn decode_ints(data: &[u8], len: usize) -> Vec<i32> {
        if len == 0 {
            return Vec::new();
        }
        let common = i32::from_le_bytes(data[..4].try_into().unwrap());
        let mut vints = 4 + (len * 2).div_ceil(8);
        let mut previous = 0i32;
        (0..len)
            .map(|i| {
                let delta = match (data[4 + i / 4] >> (2 * (i % 4))) & 3 {
                    0 => common,
                    c => {
                        let width = [0, 1, 2, 4][c as usize];
                        let mut bytes = [0u8; 4];
                        bytes[..width].copy_from_slice(&data[vints..vints + width]);
                        vints += width;
                        match width {
                            1 => bytes[0] as i8 as i32,
                            2 => i16::from_le_bytes([bytes[0], bytes[1]]) as i32,
                            _ => i32::from_le_bytes(bytes),
                        }
                    }
                };
                previous = previous.wrapping_add(delta);
                previous
            })
            .collect()
    }

    /// The bytes of a chunked LZ4 framing (`size` of them).
    pub(crate) fn unframe(data: &[u8], size: usize) -> Vec<u8> {
        let chunks = data[0] as usize;
        if chunks == 0 {
            return lz4_flex::block::decompress(&data[1..], size).unwrap();
        }
        let mut out = Vec::with_capacity(size);
        let mut at = 1;
        for _ in 0..chunks {
            let n = i32::from_le_bytes(data[at..at + 4].try_into().unwrap()) as usize;
            at += 4;
            let room = (size - out.len()).min(super::LZ4_CHUNK);
            out.extend(lz4_flex::block::decompress(&data[at..at + n], room).unwrap());
            at += n;
        }
        out
    }

    /// The integers of a [`super::compress_ints`] output.
    pub(crate) fn decompress_ints(data: &[u8], len: usize) -> Vec<i32> {
        let encoded = 4 + (len * 2).div_ceil(8) + 4 * len;
        decode_ints(&unframe(data, encoded), len)
    }
}

#[cfg(test)]
mod tests {
    use super::decode::*;
    use super::*;

    #[test]
    fn the_format_description_example_codes_to_its_bytes() {
        // Differences 123, 1, 1, 100000, 0, 1, 0: the common one is 1.
        let input = [123, 124, 125, 100125, 100125, 100126, 100126];
        let out = encode_ints(input.len(), input.iter().copied());
        let mut expected = 1i32.to_le_bytes().to_vec();
        // Codes, two bits each from the lowest: 01 00 00 11 | 01 00 01 (xx).
        expected.extend([0b1100_0001, 0b0001_0001]);
        expected.push(123);
        expected.extend(100000i32.to_le_bytes());
        expected.extend([0, 0]);
        assert_eq!(out, expected);
        assert_eq!(decode_ints(&out, input.len()), input);
    }

    #[test]
    fn every_width_and_the_wrap_round_trip() {
        let input = [
            0,
            127,
            -1,
            -129,
            40000,
            i32::MAX,
            i32::MIN,
            5,
            5,
            5,
            -32768,
            32767,
            u32::MAX as i32,
        ];
        for n in 0..=input.len() {
            let out = encode_ints(n, input[..n].iter().copied());
            assert_eq!(decode_ints(&out, n), &input[..n], "first {n}");
        }
    }

    #[test]
    fn a_tie_takes_the_largest_common_difference() {
        // Differences 2, 2, -3, -3 (from 0): 2 and -3 tie; 2 is taken.
        let input = [2, 4, 1, -2];
        let out = encode_ints(4, input.iter().copied());
        assert_eq!(i32::from_le_bytes(out[..4].try_into().unwrap()), 2);
    }

    #[test]
    fn a_constant_array_compresses_to_a_few_bytes() {
        let n = 1_000_000;
        let out = compress_ints(n, std::iter::repeat_n(3, n)).unwrap();
        assert!(out.len() < 2000, "{} bytes", out.len());
        assert!(decompress_ints(&out, n).iter().all(|&v| v == 3));
    }

    #[test]
    fn framing_splits_into_counted_chunks() {
        let input: Vec<u8> = (0..10_000u32).map(|i| (i * 7 % 251) as u8).collect();
        let framed = lz4_framed_in(&input, 4096).unwrap();
        assert_eq!(framed[0], 3);
        assert_eq!(unframe(&framed, input.len()), input);
        let single = lz4_framed(&input).unwrap();
        assert_eq!(single[0], 0);
        assert_eq!(unframe(&single, input.len()), input);
        assert!(
            lz4_framed_in(&input, 64).is_err(),
            "157 chunks cannot be counted"
        );
    }

    #[test]
    fn mesh_indices_round_trip_through_both_compressions() {
        let mut rng = crate::test_rng::TestRng::new(7);
        let indices: Vec<i32> = (0..30_000)
            .map(|i| i / 6 + (rng.next_u64() % 40) as i32)
            .collect();
        let out = compress_ints(indices.len(), indices.iter().copied()).unwrap();
        assert!(out.len() < indices.len() * 4 / 2, "{} bytes", out.len());
        assert_eq!(decompress_ints(&out, indices.len()), indices);
    }
}
