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
        out.candidates.clear();
        out.ratios.clear();
        out.cells.clear();
        let width = 2 * reach as usize + 1;
        for dz in -reach..=reach {
            for dy in -reach..=reach {
                let Some(&(a, b)) = self.rows.get(&[c[1] + dy, c[2] + dz]) else {
                    continue;
                };
                let row = &self.runs[a as usize..b as usize];
                let first = row.partition_point(|r| r.0[0] < c[0] - reach);
                let last = row.partition_point(|r| r.0[0] <= c[0] + reach);
                for &(key, a, b) in &row[first..last] {
                    let base = out.candidates.len() as u32;
                    out.candidates
                        .extend_from_slice(&self.positions[a as usize..b as usize]);
                    if let Some(ratios) = self.ratios {
                        out.ratios
                            .extend_from_slice(&ratios[a as usize..b as usize]);
                    }
                    let offset = |k: usize| (key[k] - c[k] + reach) as usize + k * width;
                    out.cells
                        .push(([offset(0), offset(1), offset(2)], base, base + (b - a)));
                }
            }
        }
        out.low = c.map(|k| k - reach);
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
}

/// The half-blocks around the one of the current particles, `width` = 2·reach + 1 per
/// axis, from key `low` up.
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
