//! The half-blocks around a half-block of particles, gathered for the anisotropic
//! kernels ([`super::kernels`]): how far a gather reaches ([`Reaches`]), where it reads
//! ([`Source`]) and what it holds ([`Gathered`], seen through [`Around`]).

use crate::grid::BlockKey;
use glam::Vec3;

/// The half-blocks a gather of [`super::kernels`] reaches, per axis on either side of a
/// particle's own: `full` holds every neighbour of any particle, `common` every neighbour
/// of a particle at least the hair inside its half-block's faces.
#[derive(Clone, Copy)]
pub(super) struct Reaches {
    /// `⌈R (1 + ε) / e⌉`.
    pub(super) full: i32,
    /// `⌈R (1 − ε) / e⌉`, at most `full`.
    pub(super) common: i32,
    /// `R (1 + ε) / e`: how far, in half-block edges, a neighbour may lie.
    pub(super) span: f64,
}

impl Reaches {
    /// The relative hair `ε` on `R`: far above the rounding of the f32 distance test of
    /// [`kernel_of`] and of the half-block keys (1e-7 relative or less).
    pub(super) const HAIR: f64 = 1e-6;

    /// The reaches for neighbourhoods of `need` half-block edges.
    pub(super) fn new(need: f64) -> Self {
        let span = need * (1.0 + Self::HAIR);
        let full = span.ceil() as i32;
        let common = ((need * (1.0 - Self::HAIR)).ceil() as i32).clamp(1, full);
        Reaches { full, common, span }
    }

    /// Whether every neighbour of the particle at `p`, of half-block `c` (edge `edge`),
    /// lies within `common` half-blocks of `c`: per axis, its offset `f` in the
    /// half-block (in edges) leaves `span` on both sides inside them,
    /// `span − common ≤ f < common + 1 − span`, with a hair of margin.
    pub(super) fn within_common(&self, p: Vec3, c: BlockKey, edge: f64) -> bool {
        let low = self.span - self.common as f64 + Self::HAIR;
        let high = self.common as f64 + 1.0 - self.span - Self::HAIR;
        (0..3).all(|k| {
            let f = p[k] as f64 / edge - c[k] as f64;
            low <= f && f < high
        })
    }
}

/// Where [`super::kernels`] gathers from.
pub(super) struct Source<'a> {
    pub(super) positions: &'a [Vec3],
    /// Radii, multiples of r, aligned with `positions` (several sizes only).
    pub(super) ratios: Option<&'a [f32]>,
    /// The populated half-blocks: key and range of particles.
    pub(super) runs: &'a [([i32; 3], u32, u32)],
    /// Per (y, z) row of half-blocks, its range of `runs`.
    pub(super) rows: &'a hashbrown::HashMap<[i32; 2], (u32, u32)>,
}

impl Source<'_> {
    /// Gathers into `out` the particles of the half-blocks within `reach` of `c` (per
    /// axis), in (z, y, x, index) order.
    pub(super) fn gather(&self, c: BlockKey, reach: i32, out: &mut Gathered) {
        self.gather_box(c.map(|k| k - reach), c.map(|k| k + reach), out);
    }

    /// Gathers into `out` the particles of the half-blocks from `lo` to `hi` (both
    /// included, per axis), in (z, y, x, index) order. The box is widest along x.
    pub(super) fn gather_box(&self, lo: BlockKey, hi: BlockKey, out: &mut Gathered) {
        out.candidates.clear();
        out.ratios.clear();
        out.cells.clear();
        out.keys.clear();
        out.rows.clear();
        out.rows.push(0);
        let width = (hi[0] - lo[0] + 1) as usize;
        debug_assert!((0..3).all(|k| hi[k] - lo[k] < width as i32));
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                let row = match self.rows.get(&[y, z]) {
                    Some(&(a, b)) => &self.runs[a as usize..b as usize],
                    None => &[][..],
                };
                let first = row.partition_point(|r| r.0[0] < lo[0]);
                let last = row.partition_point(|r| r.0[0] <= hi[0]);
                for &(key, a, b) in &row[first..last] {
                    let base = out.candidates.len() as u32;
                    out.candidates
                        .extend_from_slice(&self.positions[a as usize..b as usize]);
                    if let Some(ratios) = self.ratios {
                        out.ratios
                            .extend_from_slice(&ratios[a as usize..b as usize]);
                    }
                    let offset = |k: usize| (key[k] - lo[k]) as usize + k * width;
                    out.cells
                        .push(([offset(0), offset(1), offset(2)], base, base + (b - a)));
                    out.keys.push(key);
                }
                out.rows.push(out.cells.len() as u32);
            }
        }
        out.low = lo;
        out.rows_y = (hi[1] - lo[1] + 1) as usize;
        out.width = width;
    }
}

/// The particles of the half-blocks around one, gathered by [`Source::gather`].
#[derive(Default)]
pub(super) struct Gathered {
    /// Particles of the half-blocks around the current one, in canonical order.
    pub(super) candidates: Vec<Vec3>,
    /// Their radii, multiples of r (particles of several sizes only).
    pub(super) ratios: Vec<f32>,
    /// The half-blocks of `candidates`: [`Around::cells`].
    pub(super) cells: Vec<([usize; 3], u32, u32)>,
    /// Their keys.
    pub(super) keys: Vec<BlockKey>,
    /// Where each (y, z) row of the box starts in `cells` (y fastest, one more at the end).
    rows: Vec<u32>,
    /// Rows along y in the box.
    rows_y: usize,
    /// Key of the first half-block along each axis.
    pub(super) low: BlockKey,
    /// Half-blocks per axis.
    pub(super) width: usize,
}

impl Gathered {
    /// The gathered half-blocks, of edge `edge` (world units).
    pub(super) fn around(&self, edge: f64) -> Around<'_> {
        Around {
            cells: &self.cells,
            low: self.low,
            width: self.width,
            edge,
        }
    }

    /// Of a gather over a box that holds the half-blocks within `reach` of `c`, those
    /// half-blocks (in `cells`, scratch): what [`Source::gather`] of `c` and `reach` would
    /// give, the candidates read from this gather. The same half-blocks in the same order,
    /// so the same neighbours in the same order.
    pub(super) fn around_of<'a>(
        &'a self,
        c: BlockKey,
        reach: i32,
        edge: f64,
        cells: &'a mut Vec<([usize; 3], u32, u32)>,
    ) -> Around<'a> {
        let width = 2 * reach as usize + 1;
        if self.low == c.map(|k| k - reach) && self.width == width && self.rows_y == width {
            // The gather is `c`'s own (a group of one): its half-blocks as they are.
            return self.around(edge);
        }
        cells.clear();
        for z in c[2] - reach..=c[2] + reach {
            for y in c[1] - reach..=c[1] + reach {
                let row = (z - self.low[2]) as usize * self.rows_y + (y - self.low[1]) as usize;
                let (s, e) = (self.rows[row] as usize, self.rows[row + 1] as usize);
                let keys = &self.keys[s..e];
                let first = s + keys.partition_point(|key| key[0] < c[0] - reach);
                let last = s + keys.partition_point(|key| key[0] <= c[0] + reach);
                cells.extend(
                    self.keys[first..last]
                        .iter()
                        .zip(&self.cells[first..last])
                        .map(|(key, &(_, a, b))| {
                            let offset = |k: usize| (key[k] - c[k] + reach) as usize + k * width;
                            ([offset(0), offset(1), offset(2)], a, b)
                        }),
                );
            }
        }
        Around {
            cells,
            low: c.map(|k| k - reach),
            width,
            edge,
        }
    }
}

/// The half-blocks around the one of the current particles, `width` = 2·reach + 1 per
/// axis, from key `low` up.
#[derive(Clone, Copy)]
pub(super) struct Around<'a> {
    /// Per populated half-block, its offset from `low` along axis k plus `k·width`
    /// (where its slab's distance is in the gap table), and its range of candidates.
    pub(super) cells: &'a [([usize; 3], u32, u32)],
    /// Key of the first half-block along each axis.
    pub(super) low: BlockKey,
    /// Half-blocks per axis.
    pub(super) width: usize,
    /// Edge of a half-block, world units.
    pub(super) edge: f64,
}

/// The runs of populated half-blocks cut into groups gathered at once: consecutive runs
/// of one (y, z) row within [`GROUP`] half-blocks of the group's first along x, as ranges
/// of `runs` (in order, so the kernels come out in the particles' order).
pub(super) fn row_groups(runs: &[([i32; 3], u32, u32)]) -> Vec<(usize, usize)> {
    let mut groups = Vec::new();
    let mut start = 0;
    for k in 1..=runs.len() {
        let split = k == runs.len() || {
            let (a, b) = (runs[start].0, runs[k].0);
            a[1] != b[1] || a[2] != b[2] || b[0] - a[0] >= GROUP
        };
        if split {
            groups.push((start, k));
            start = k;
        }
    }
    groups
}

/// Half-blocks along x gathered at once ([`row_groups`]) where the cells are finer than
/// h = r. At h = 0.71 r a half-block holds about three particles and its gather (two
/// half-blocks out) 125 half-blocks: one gather per half-block copied every particle
/// about forty times. (At h = r, a gather of 27, grouping made the kernels 9 % faster
/// but the 4M still run's peak passed 1 GiB in 3 of 15 runs: not there.)
const GROUP: i32 = 8;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::FieldOptions;
    use crate::grid::HALF_BLOCK_EDGE;

    /// A group's gather read around one of its half-blocks ([`Gathered::around_of`])
    /// holds the half-blocks, at the same offsets and in the same order, and the same
    /// particles in each, as that half-block's own gather.
    #[test]
    fn a_groups_gather_around_a_half_block_is_its_own_gather() {
        let r = 0.01f32;
        let mut rng = crate::test_rng::TestRng::new(5);
        let positions: Vec<Vec3> = (0..3000)
            .map(|_| Vec3::new(rng.unit_f32(), rng.unit_f32(), rng.unit_f32()) * 40.0 * r)
            .collect();
        let field = FieldOptions {
            cell_size: 0.71,
            kernel: crate::field::Kernel::Anisotropic,
            ..FieldOptions::new(r)
        };
        let (_, sorted, halves) = super::super::canonical_order(&positions, &field);
        let runs = crate::grid::key_runs(halves.iter().copied());
        let rows = crate::grid::row_ranges(runs.iter().map(|r| r.0));
        let source = Source {
            positions: &sorted,
            ratios: None,
            runs: &runs,
            rows: &rows,
        };
        let edge = field.cell_size_world() * HALF_BLOCK_EDGE as f64;
        let groups = row_groups(&runs);
        assert!(
            groups.len() < runs.len(),
            "some groups hold several half-blocks"
        );
        let (mut group, mut own, mut cells) =
            (Gathered::default(), Gathered::default(), Vec::new());
        for reach in [1, 2] {
            for &(g0, g1) in &groups {
                let (first, last) = (runs[g0].0, runs[g1 - 1].0);
                let lo = first.map(|k| k - reach);
                source.gather_box(
                    lo,
                    [last[0] + reach, first[1] + reach, first[2] + reach],
                    &mut group,
                );
                for &(c, _, _) in &runs[g0..g1] {
                    source.gather(c, reach, &mut own);
                    let here = group.around_of(c, reach, edge, &mut cells);
                    let theirs = own.around(edge);
                    assert_eq!((here.low, here.width), (theirs.low, theirs.width));
                    assert_eq!(here.cells.len(), theirs.cells.len());
                    for (a, b) in here.cells.iter().zip(theirs.cells) {
                        assert_eq!(a.0, b.0);
                        assert_eq!(
                            group.candidates[a.1 as usize..a.2 as usize],
                            own.candidates[b.1 as usize..b.2 as usize]
                        );
                    }
                }
            }
        }
    }
}
