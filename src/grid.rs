//! The global lattice and its sparse blocks.
//!
//! Grid vertex `(i, j, k)` (integers) sits at world position `(i·h, j·h, k·h)`, `h` the
//! cell size in world units. The origin is the world origin for every frame and every
//! tile, so a vertex has the same integer coordinates however the domain is cut.
//!
//! Vertices are stored in dense blocks of [`BLOCK_EDGE`]³ values; block `(bx, by, bz)` holds
//! the vertices `(8·bx + a, 8·by + b, 8·bz + c)` for `a, b, c ∈ 0..8`. Blocks live in a
//! hashbrown map keyed by block coordinate; only blocks touched by some particle's
//! influence sphere exist. Nothing is sized by the scene's bounding box.

use crate::error::{Error, Result};
use glam::Vec3;
use hashbrown::HashMap;
use rayon::prelude::*;

/// Vertices per block edge.
pub const BLOCK_EDGE: i32 = 8;
/// Vertices per block.
pub const BLOCK_VOLUME: usize = (BLOCK_EDGE * BLOCK_EDGE * BLOCK_EDGE) as usize;

/// Integer coordinate of a block on the global lattice.
pub type BlockKey = [i32; 3];

/// Index of local vertex `(a, b, c)` (each in `0..BLOCK_EDGE`) inside a block's value array.
#[inline]
pub fn local_index(a: i32, b: i32, c: i32) -> usize {
    ((c * BLOCK_EDGE + b) * BLOCK_EDGE + a) as usize
}

/// The block holding global vertex coordinate `i` (one axis), and its offset in the block.
#[inline]
pub fn split_coordinate(i: i32) -> (i32, i32) {
    (i.div_euclid(BLOCK_EDGE), i.rem_euclid(BLOCK_EDGE))
}

/// Largest coordinate, in cells, the lattice accepts (block keys must pack in 21 bits).
const MAX_CELL_COORDINATE: f64 = (1u64 << 23) as f64;

/// An inclusive box of block keys.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct BlockRange {
    /// Lowest block key, per axis.
    pub lo: BlockKey,
    /// Highest block key, per axis (inclusive).
    pub hi: BlockKey,
}

impl BlockRange {
    /// True when `key` lies in the range.
    pub fn contains(&self, key: BlockKey) -> bool {
        (0..3).all(|a| self.lo[a] <= key[a] && key[a] <= self.hi[a])
    }

    /// The range grown by `lo` blocks downwards and `hi` blocks upwards on every axis.
    pub fn grown(&self, lo: i32, hi: i32) -> BlockRange {
        BlockRange {
            lo: self.lo.map(|c| c - lo),
            hi: self.hi.map(|c| c + hi),
        }
    }
}

/// Edge of a half-block, in cells.
pub(crate) const HALF_BLOCK_EDGE: i32 = BLOCK_EDGE / 2;

/// The home half-block of one position (the 4³ cells of its home block's eighth that
/// contain it), `inv_h` = 1 / cell size (world units). Its home block is
/// [`block_of_half`].
#[inline]
pub(crate) fn home_half_block(p: Vec3, inv_h: f64) -> BlockKey {
    home_cube(p, inv_h, HALF_BLOCK_EDGE)
}

/// The block a half-block lies in: its key divided by 2, rounded down.
#[inline]
pub(crate) fn block_of_half(half: BlockKey) -> BlockKey {
    half.map(|c| c.div_euclid(2))
}

/// The home block of one position, `inv_h` = 1 / cell size (world units).
#[inline]
pub(crate) fn home_block(p: Vec3, inv_h: f64) -> BlockKey {
    home_cube(p, inv_h, BLOCK_EDGE)
}

/// The cube of `edge`³ cells, on the global lattice, that contains `p`.
#[inline]
fn home_cube(p: Vec3, inv_h: f64, edge: i32) -> BlockKey {
    let c = p.as_dvec3() * inv_h;
    [c.x, c.y, c.z].map(|v| (v.floor() as i32).div_euclid(edge))
}

/// Checks that every position of a chunk whose first particle has input index `first` is
/// finite and within the lattice's coordinate range, for cells of `h` (world units) made
/// from the particle radius `particle_radius` (named in the message).
pub(crate) fn check_positions(
    first: usize,
    positions: &[Vec3],
    h: f64,
    particle_radius: f32,
) -> Result<()> {
    let inv_h = 1.0 / h;
    if let Some(i) = positions.par_iter().position_first(|p| {
        !p.is_finite() || (p.as_dvec3() * inv_h).abs().max_element() > MAX_CELL_COORDINATE
    }) {
        let p = positions[i];
        let i = first + i;
        return Err(Error::ParticleOutOfRange {
            path: None,
            message: if p.is_finite() {
                format!(
                    "particle {i} at {p} lies {:.3e} cells of {h:.3e} (the cell size, from the particle radius {}) from the origin; the lattice reaches 2^23 cells: the particle radius is too small for these coordinates, or the coordinates are not in the radius's units",
                    (p.as_dvec3() * inv_h).abs().max_element(),
                    particle_radius
                )
            } else {
                format!("particle {i} has a non-finite coordinate {p}")
            },
        });
    }
    Ok(())
}

/// The values of one block.
pub type BlockValues = [f32; BLOCK_VOLUME];

/// `count` blocks of zeros, allocated zeroed rather than written: a large allocation then
/// gets the operating system's zero pages, first touched by whichever thread fills the
/// block, and blocks nobody fills are never touched. (`vec![[0.0; BLOCK_VOLUME]; n]`
/// writes every value on one thread, since the standard library takes its zeroed path
/// only for arrays of up to 16 elements: on the 4M-particle scene 0.24–0.55 s of serial
/// writing before the field, and 40 MiB of peak memory for candidate blocks no particle
/// reaches, 2026-11-24.)
pub(crate) fn zeroed_blocks(count: usize) -> Vec<BlockValues> {
    if count == 0 {
        return Vec::new();
    }
    let layout = std::alloc::Layout::array::<BlockValues>(count).expect("block array size");
    // SAFETY: the layout's size is non-zero; all-zero bits are a valid `[f32; N]`; the
    // pointer comes from the global allocator with exactly the layout `Vec` uses for
    // `count` elements of `BlockValues`, so the `Vec` may own and free it.
    unsafe {
        let ptr = std::alloc::alloc_zeroed(layout) as *mut BlockValues;
        if ptr.is_null() {
            std::alloc::handle_alloc_error(layout);
        }
        Vec::from_raw_parts(ptr, count, count)
    }
}

/// Values of a scalar field on the sparse lattice: block values in one contiguous array
/// (one allocation, returned to the system when dropped), found through a hashbrown map
/// keyed by block coordinate.
///
/// Invariant: vertices of missing blocks, and vertices without any particle in range, hold
/// [`SparseField::outside_value`] (a positive number: outside the fluid).
#[derive(Clone, Debug)]
pub struct SparseField {
    /// Cell size h, world units.
    pub cell_size: f64,
    /// Value of every vertex not stored (positive: outside).
    pub outside_value: f32,
    index: HashMap<BlockKey, u32>,
    values: Vec<BlockValues>,
}

impl SparseField {
    /// A field holding `blocks` (key, values) pairs; later pairs win on duplicate keys.
    pub fn from_blocks(
        cell_size: f64,
        outside_value: f32,
        blocks: impl IntoIterator<Item = (BlockKey, BlockValues)>,
    ) -> Self {
        let mut field = SparseField {
            cell_size,
            outside_value,
            index: HashMap::new(),
            values: Vec::new(),
        };
        for (key, values) in blocks {
            match field.index.get(&key) {
                Some(&i) => field.values[i as usize] = values,
                None => {
                    field.index.insert(key, field.values.len() as u32);
                    field.values.push(values);
                }
            }
        }
        field
    }

    /// A field from parallel arrays of distinct keys and their values (no copy).
    pub(crate) fn from_parts(
        cell_size: f64,
        outside_value: f32,
        keys: &[BlockKey],
        values: Vec<BlockValues>,
    ) -> Self {
        assert_eq!(keys.len(), values.len(), "one key per block");
        let index = keys
            .iter()
            .enumerate()
            .map(|(i, k)| (*k, i as u32))
            .collect();
        SparseField {
            cell_size,
            outside_value,
            index,
            values,
        }
    }

    /// Adds `delta` to every stored value and to the value of vertices not stored.
    pub(crate) fn shift_values(&mut self, delta: f32) {
        self.outside_value += delta;
        self.values
            .par_iter_mut()
            .for_each(|block| block.iter_mut().for_each(|v| *v += delta));
    }

    /// Number of stored blocks.
    pub fn block_count(&self) -> usize {
        self.values.len()
    }

    /// The values of block `key`, if stored.
    #[inline]
    pub fn block(&self, key: &BlockKey) -> Option<&BlockValues> {
        self.index.get(key).map(|&i| &self.values[i as usize])
    }

    /// The values of block `key` for writing, if stored.
    pub(crate) fn block_mut(&mut self, key: &BlockKey) -> Option<&mut BlockValues> {
        self.index.get(key).map(|&i| &mut self.values[i as usize])
    }

    /// The keys of the blocks holding a value `< 0`, in no particular order; the blocks
    /// are scanned in parallel.
    pub(crate) fn keys_of_negative_blocks(&self) -> Vec<BlockKey> {
        let mut key_of = vec![None; self.values.len()];
        for (key, &slot) in &self.index {
            key_of[slot as usize] = Some(*key);
        }
        self.values
            .par_iter()
            .zip(key_of)
            .filter_map(|(values, key)| key.filter(|_| values.iter().any(|&v| v < 0.0)))
            .collect()
    }

    /// Every stored block, in no particular order.
    pub fn blocks(&self) -> impl Iterator<Item = (&BlockKey, &BlockValues)> {
        self.index
            .iter()
            .map(|(k, &i)| (k, &self.values[i as usize]))
    }

    /// The value at global vertex `(i, j, k)`.
    pub fn value(&self, i: i32, j: i32, k: i32) -> f32 {
        let (bx, a) = split_coordinate(i);
        let (by, b) = split_coordinate(j);
        let (bz, c) = split_coordinate(k);
        match self.block(&[bx, by, bz]) {
            Some(block) => block[local_index(a, b, c)],
            None => self.outside_value,
        }
    }

    /// Block keys in ascending (z, y, x) order: the canonical processing order.
    pub fn sorted_keys(&self) -> Vec<BlockKey> {
        let mut keys: Vec<BlockKey> = self.index.keys().copied().collect();
        keys.sort_unstable_by_key(|k| [k[2], k[1], k[0]]);
        keys
    }

    /// Bytes held by the block values and their index (the dominant memory of the field
    /// stage).
    pub fn memory_bytes(&self) -> usize {
        self.values.capacity() * BLOCK_VOLUME * 4 + self.index.capacity() * 24
    }
}

/// The indices of `keys` in ascending (z, y, x, index) order: the canonical order of
/// particles binned by cell or block. Packs each key into one integer of just the bits its
/// axes span (relative to the smallest key) and sorts those with a stable radix sort:
/// beside the index in one `u64` when they fit in 32 bits, in a pair when they fit in 63
/// (as any block key does); else compares the keys.
pub(crate) fn sort_by_key_zyx(keys: &[[i32; 3]]) -> Vec<u32> {
    use rayon::prelude::*;
    if keys.is_empty() {
        return Vec::new();
    }
    let (lo, hi) = keys.par_iter().map(|&k| (k, k)).reduce(
        || ([i32::MAX; 3], [i32::MIN; 3]),
        |(lo, hi), (l, h)| {
            (
                [0, 1, 2].map(|a| lo[a].min(l[a])),
                [0, 1, 2].map(|a| hi[a].max(h[a])),
            )
        },
    );
    // Bits each axis spans: x lowest, z highest, so the packed order is (z, y, x).
    let bits =
        [0, 1, 2].map(|a| u64::BITS - ((hi[a] as i64 - lo[a] as i64) as u64).leading_zeros());
    let key_bits = bits.iter().sum::<u32>();
    let pack = |k: &[i32; 3]| {
        let d = [0, 1, 2].map(|a| (k[a] as i64 - lo[a] as i64) as u64);
        (d[2] << (bits[0] + bits[1])) | (d[1] << bits[0]) | d[0]
    };
    if key_bits <= 32 {
        let packed: Vec<u64> = keys
            .par_iter()
            .enumerate()
            .map(|(i, k)| (pack(k) << 32) | i as u64)
            .collect();
        radix_sort(packed, |&w| w >> 32, key_bits)
            .into_par_iter()
            .map(|w| w as u32)
            .collect()
    } else if key_bits <= 63 {
        let packed: Vec<(u64, u32)> = keys
            .par_iter()
            .enumerate()
            .map(|(i, k)| (pack(k), i as u32))
            .collect();
        radix_sort(packed, |&(key, _)| key, key_bits)
            .into_par_iter()
            .map(|(_, i)| i)
            .collect()
    } else {
        let mut order: Vec<u32> = (0..keys.len() as u32).collect();
        order.par_sort_unstable_by_key(|&i| {
            let k = keys[i as usize];
            (k[2], k[1], k[0], i)
        });
        order
    }
}

/// Items per chunk of the radix sort's counting and scattering (any size gives the same
/// order: the sort is stable).
const RADIX_CHUNK: usize = 1 << 16;
/// Widest digit of the radix sort, bits (2048 buckets: the counts of a chunk stay in L1).
const RADIX_DIGIT_BITS: u32 = 11;

/// `items` sorted by the low `key_bits` bits of `key(item)`, stably (equal keys keep their
/// order): least significant digit first, each pass counting digits per chunk in parallel
/// and scattering every chunk to its own slots. Digits in which all keys agree are skipped.
fn radix_sort<T: Copy + Send + Sync>(
    mut items: Vec<T>,
    key: impl Fn(&T) -> u64 + Sync,
    key_bits: u32,
) -> Vec<T> {
    use rayon::prelude::*;
    if items.len() < 2 || key_bits == 0 {
        return items;
    }
    let passes = key_bits.div_ceil(RADIX_DIGIT_BITS);
    let digit_bits = key_bits.div_ceil(passes);
    let buckets = 1usize << digit_bits;
    let mask = buckets as u64 - 1;
    let mut scratch: Vec<T> = Vec::with_capacity(items.len());
    for pass in 0..passes {
        let shift = pass * digit_bits;
        let digit = |item: &T| ((key(item) >> shift) & mask) as usize;
        let mut counts: Vec<Vec<u32>> = items
            .par_chunks(RADIX_CHUNK)
            .map(|chunk| {
                let mut count = vec![0u32; buckets];
                for item in chunk {
                    count[digit(item)] += 1;
                }
                count
            })
            .collect();
        let total = |d: usize| counts.iter().map(|c| c[d] as usize).sum::<usize>();
        if (0..buckets).any(|d| total(d) == items.len()) {
            continue;
        }
        // Each chunk's first slot per digit: digits in order, chunks in order within one.
        let mut next = 0u32;
        for d in 0..buckets {
            for count in counts.iter_mut() {
                let n = count[d];
                count[d] = next;
                next += n;
            }
        }
        let out = SharedSlots(scratch.as_mut_ptr());
        items
            .par_chunks(RADIX_CHUNK)
            .zip(counts.par_iter_mut())
            .for_each(|(chunk, slot)| {
                for item in chunk {
                    let s = &mut slot[digit(item)];
                    // SAFETY: the chunks' slots are disjoint and cover `0..items.len()`,
                    // within `scratch`'s capacity.
                    unsafe { out.write(*s as usize, *item) };
                    *s += 1;
                }
            });
        // SAFETY: every slot in `0..items.len()` was written above.
        unsafe { scratch.set_len(items.len()) };
        std::mem::swap(&mut items, &mut scratch);
        scratch.clear();
    }
    items
}

/// The radix sort's output buffer, written by every chunk at its own slots.
struct SharedSlots<T>(*mut T);
impl<T> Clone for SharedSlots<T> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<T> Copy for SharedSlots<T> {}
// SAFETY: only used by `radix_sort`, whose chunks write disjoint slots.
unsafe impl<T: Send> Send for SharedSlots<T> {}
unsafe impl<T: Send> Sync for SharedSlots<T> {}

impl<T> SharedSlots<T> {
    /// Writes `item` at slot `at`.
    ///
    /// # Safety
    /// `at` lies within the buffer's capacity and no other thread writes it.
    unsafe fn write(self, at: usize, item: T) {
        self.0.add(at).write(item);
    }
}

#[cfg(test)]
/// Per key (cell or block), the range of a sorted index list holding its entries.
pub(crate) type KeyRanges = hashbrown::HashMap<[i32; 3], (u32, u32)>;

#[cfg(test)]
/// `keys` binned: the indices in [`sort_by_key_zyx`] order, and for every key present the
/// range of that order holding its indices (ascending index within a key).
pub(crate) fn bin_by_key(keys: &[[i32; 3]]) -> (Vec<u32>, KeyRanges) {
    let order = sort_by_key_zyx(keys);
    let ranges = group_runs(order.iter().map(|&i| keys[i as usize]));
    (order, ranges)
}

#[cfg(test)]
/// The range of positions each key holds in `keys`, a sequence in which equal keys are
/// contiguous (panics otherwise).
pub(crate) fn group_runs(keys: impl IntoIterator<Item = [i32; 3]>) -> KeyRanges {
    let mut ranges = KeyRanges::new();
    for (key, start, end) in key_runs(keys) {
        let previous = ranges.insert(key, (start, end));
        assert!(previous.is_none(), "equal keys must be contiguous");
    }
    ranges
}

/// The runs of equal keys in `keys`, in order: each key with the range of positions
/// `start..end` it holds.
pub(crate) fn key_runs(keys: impl IntoIterator<Item = [i32; 3]>) -> Vec<([i32; 3], u32, u32)> {
    let mut runs: Vec<([i32; 3], u32, u32)> = Vec::new();
    for (n, key) in (0u32..).zip(keys) {
        match runs.last_mut() {
            Some((k, _, end)) if *k == key => *end = n + 1,
            _ => runs.push((key, n, n + 1)),
        }
    }
    runs
}

/// Per row `[y, z]` of `keys`, a sequence in (z, y, x) order, the range of positions
/// `start..end` holding that row's keys (panics when a row's keys are not contiguous).
pub(crate) fn row_ranges(
    keys: impl IntoIterator<Item = [i32; 3]>,
) -> HashMap<[i32; 2], (u32, u32)> {
    let mut rows: Vec<([i32; 2], u32, u32)> = Vec::new();
    for (n, key) in (0u32..).zip(keys) {
        let row = [key[1], key[2]];
        match rows.last_mut() {
            Some((r, _, end)) if *r == row => *end = n + 1,
            _ => rows.push((row, n, n + 1)),
        }
    }
    let mut ranges = HashMap::with_capacity(rows.len());
    for (row, start, end) in rows {
        let previous = ranges.insert(row, (start, end));
        assert!(previous.is_none(), "keys must be in (z, y, x) order");
    }
    ranges
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packed_sort_orders_like_the_key_tuples() {
        let mut rng = crate::test_rng::TestRng::new(3);
        let mut next = |m: i32| ((rng.next_u64() >> 33) as i32).rem_euclid(2 * m) - m;
        // Narrow, wide and too wide to pack (the comparison sort); the long list spans
        // several chunks of the radix sort, with many equal keys.
        for (spread, count) in [
            (3, 150_000),
            (1 << 19, 5000),
            (1 << 22, 5000),
            (1 << 30, 5000),
        ] {
            let keys: Vec<[i32; 3]> = (0..count)
                .map(|_| [next(spread), next(3), next(spread)])
                .collect();
            let mut expected: Vec<u32> = (0..keys.len() as u32).collect();
            expected.sort_by_key(|&i| {
                let k = keys[i as usize];
                (k[2], k[1], k[0], i)
            });
            assert_eq!(sort_by_key_zyx(&keys), expected, "spread {spread}");
        }
        assert!(sort_by_key_zyx(&[]).is_empty());
    }

    #[test]
    fn negative_blocks_are_those_with_a_value_below_zero() {
        let block = |v: f32, at: usize| {
            let mut values = [1.0f32; BLOCK_VOLUME];
            values[at] = v;
            values
        };
        let field = SparseField::from_blocks(
            1.0,
            1.0,
            [
                ([0, 0, 0], block(0.0, 5)),
                ([-1, 2, 0], block(-0.5, BLOCK_VOLUME - 1)),
                ([3, 0, -4], block(2.0, 0)),
                ([7, 7, 7], block(-1e-30, 0)),
            ],
        );
        let mut negative = field.keys_of_negative_blocks();
        negative.sort();
        assert_eq!(negative, vec![[-1, 2, 0], [7, 7, 7]]);
    }

    #[test]
    fn negative_coordinates_split_into_lower_blocks() {
        assert_eq!(split_coordinate(-1), (-1, 7));
        assert_eq!(split_coordinate(-8), (-1, 0));
        assert_eq!(split_coordinate(-9), (-2, 7));
        assert_eq!(split_coordinate(8), (1, 0));
        assert_eq!(split_coordinate(7), (0, 7));
    }
}
