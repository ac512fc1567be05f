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

/// The values of one block.
pub type BlockValues = [f32; BLOCK_VOLUME];

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
    pub fn from_parts(
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
    pub fn shift_values(&mut self, delta: f32) {
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
    pub fn block_mut(&mut self, key: &BlockKey) -> Option<&mut BlockValues> {
        self.index.get(key).map(|&i| &mut self.values[i as usize])
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn negative_coordinates_split_into_lower_blocks() {
        assert_eq!(split_coordinate(-1), (-1, 7));
        assert_eq!(split_coordinate(-8), (-1, 0));
        assert_eq!(split_coordinate(-9), (-2, 7));
        assert_eq!(split_coordinate(8), (1, 0));
        assert_eq!(split_coordinate(7), (0, 7));
    }
}
