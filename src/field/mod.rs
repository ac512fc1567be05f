//! The scalar field of Solenthaler, Schläfli and Pajarola 2007, "A Unified Particle Model
//! for Fluid-Solid Interactions" (§ surface reconstruction), as used by Akinci et al. 2013.
//!
//! **Input:** particle centres (world units) and [`FieldOptions`].
//! **Output:** a [`SparseField`] holding `phi` (world units, negative inside the fluid) at
//! every lattice vertex that has a particle within the influence radius `R`, in 8³ blocks.
//!
//! For a vertex `v`, with `k(s) = max(0, (1 − s²)³)` and `w_i = k(|v − x_i| / R)`:
//! * `vbar(v) = Σ w_i x_i / Σ w_i`,
//! * `phi(v) = |v − vbar(v)| − r·f(v)`,
//! * `f = 1` when `EVmax < t_low`, else `γ³ − 3γ² + 3γ` with
//!   `γ = (t_high − EVmax) / (t_high − t_low)`, EVmax clamped to `[t_low, t_high]`,
//!   EVmax the largest eigenvalue of the Jacobian `∇vbar`.
//!
//! `∇vbar` has the closed form `J_ab = (Σ x_ia ∂_b w_i − vbar_a Σ ∂_b w_i) / Σ w_i` with
//! `∇w_i = −6 (1 − s²)² (v − x_i) / R²`; with `r_i = v − x_i` the sums become
//! `Σ w`, `Σ w r`, `Σ ∇w` and the symmetric `Σ g r⊗r`, thirteen per vertex. `J` is not symmetric; its eigenvalues are the
//! roots of the characteristic cubic, solved in f64 in closed form (Cardano for one real
//! root, the trigonometric form for three); "largest" is the largest real part.
//!
//! **Evaluation order (the invariant that makes tiling exact):** the sums at a vertex run
//! over particles binned by *home half-block* (the 4³-cell eighth of a lattice block that
//! contains the particle), half-blocks visited in a fixed (z, y, x) offset order, particles
//! of a half-block in ascending input index. The order depends only on global lattice
//! coordinates, never on the thread count or on how the domain is cut. Sums are accumulated in f32 on block-local
//! coordinates (in cells), which keeps them exact enough far from the origin.

pub use crate::anisotropy::AnisotropyOptions;
use crate::error::{Error, Result};
use crate::grid::{zeroed_blocks, BlockKey, BlockValues, SparseField, BLOCK_EDGE, BLOCK_VOLUME};
use glam::Vec3;
use rayon::prelude::*;
use std::borrow::Cow;

pub mod anisotropic;
mod candidates;
mod concavity;
mod coverage;
mod rows;
use candidates::candidate_blocks;
pub(crate) use concavity::concavity_factor;
use concavity::largest_eigenvalue_real_part_lanes;
pub(crate) use coverage::apply_coverage;
use rows::{row_mask, transpose_bits, HalfRowIndex, RowLists};

/// Parameters of the field. Lengths other than the particle radius are multiples of `r`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FieldOptions {
    /// Particle radius `r`, world units (half the rest spacing). Required, > 0.
    pub particle_radius: f32,
    /// Influence radius `R` in multiples of `r`. Default 4.
    pub influence_radius: f32,
    /// Marching-cubes cell edge `h` in multiples of `r`. Default 1.
    pub cell_size: f32,
    /// Lower eigenvalue threshold `t_low` of the concavity factor ([`Kernel::Isotropic`]).
    /// Default 0.4.
    pub t_low: f32,
    /// Upper eigenvalue threshold `t_high` of the concavity factor ([`Kernel::Isotropic`]).
    /// Default 3.5.
    pub t_high: f32,
    /// Coverage radius `c`, multiples of `r`. The Solenthaler surface retreats inside
    /// particles at sharp convex corners and in one-particle films (`f → 0` there). A
    /// particle where the field, trilinearly interpolated from its cell's eight lattice
    /// vertices, is above `−r/4` is *uncovered*; around every uncovered particle
    /// `phi ← min(phi, |v − x_i| − c·r)`, so the surface encloses it. Covered particles
    /// (all of the bulk and of flat surfaces) leave the field exactly the paper's.
    /// `c ≥ (√3/2)·h/r` puts a negative lattice vertex next to every uncovered particle;
    /// `c·r` must not exceed `6h`. 0 turns coverage off. Default 0.9.
    pub particle_coverage: f32,
    /// Iso-surface offset `δ`, multiples of `r`: the surface is extracted where
    /// `phi = δ·r` instead of 0, i.e. moved outwards by `δ·r / |∇phi|` (`|∇phi|` is
    /// between 1/2 and 1 near the surface: 0.19 r for `δ = 0.133` on the box's faces). The paper's surface (`δ = 0`) lies inside the outer particles: on
    /// `dambreak_small` frame 25 the outer particle centres sit 0.87 r deep instead of r
    /// (meshq depth bias −0.13 r), and the analytic box comes out 6 % small. `δ = 0.133`
    /// removes that bias (box: volume error −1 %, flat normal error 0.79° instead of
    /// 1.02°; frame 25: mean |d − r| 0.16 r instead of 0.25 r) but makes flat regions of
    /// frame 25 bumpier (0.0090 r instead of 0.0079 r). Within `[−1, 1]`. Default 0 (the
    /// paper's).
    #[serde(default)]
    pub iso_offset: f32,
    /// Which kernel the field sums. Default [`Kernel::Isotropic`] (the paper's); the
    /// pipeline's default ([`crate::pipeline::ReconstructOptions::new`]) is
    /// [`Kernel::Anisotropic`].
    #[serde(default)]
    pub kernel: Kernel,
    /// Parameters of [`Kernel::Anisotropic`].
    #[serde(default)]
    pub anisotropy: AnisotropyOptions,
}

/// The kernel of the field.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Kernel {
    /// The Solenthaler et al. 2007 field with spherical kernels of radius `R` (the paper's).
    #[default]
    Isotropic,
    /// Yu and Turk 2013 anisotropic kernels ([`crate::anisotropy`]), see
    /// [`anisotropic`].
    Anisotropic,
}

impl FieldOptions {
    /// The paper's field for a given particle radius (world units), with coverage balls of
    /// 0.9 r.
    pub fn new(particle_radius: f32) -> Self {
        FieldOptions {
            particle_radius,
            influence_radius: 4.0,
            cell_size: 1.0,
            t_low: 0.4,
            t_high: 3.5,
            particle_coverage: 0.9,
            iso_offset: 0.0,
            kernel: Kernel::Isotropic,
            anisotropy: AnisotropyOptions::default(),
        }
    }

    /// Cell size `h` in world units.
    pub fn cell_size_world(&self) -> f64 {
        self.cell_size as f64 * self.particle_radius as f64
    }

    /// Influence radius `R` in world units.
    pub fn influence_radius_world(&self) -> f64 {
        self.influence_radius as f64 * self.particle_radius as f64
    }

    /// Value stored for vertices with no particle in range (positive: outside).
    pub fn outside_value(&self) -> f32 {
        (self.influence_radius_world()) as f32
    }

    /// Checks that every parameter can work.
    pub fn validate(&self) -> Result<()> {
        let positive = |v: f32| v.is_finite() && v > 0.0;
        if !positive(self.particle_radius) {
            return Err(Error::InvalidOption {
                option: "particle_radius",
                message: format!("must be a finite number > 0, got {}", self.particle_radius),
            });
        }
        if !positive(self.influence_radius) {
            return Err(Error::InvalidOption {
                option: "influence_radius",
                message: format!(
                    "must be > 0 (multiples of r), got {}",
                    self.influence_radius
                ),
            });
        }
        if !positive(self.cell_size) {
            return Err(Error::InvalidOption {
                option: "cell_size",
                message: format!("must be > 0 (multiples of r), got {}", self.cell_size),
            });
        }
        // Either one may be the one the user set: the pair is named.
        if self.influence_radius / self.cell_size > 64.0 {
            return Err(Error::InvalidOption {
                option: "influence_radius/cell_size",
                message: format!(
                    "the influence radius R = {} r spans more than 64 cells of {} r: a smaller R or larger cells",
                    self.influence_radius, self.cell_size
                ),
            });
        }
        if !(self.particle_coverage.is_finite()
            && self.particle_coverage >= 0.0
            && self.particle_coverage <= 6.0 * self.cell_size)
        {
            return Err(Error::InvalidOption {
                option: "particle_coverage",
                message: format!(
                    "must be between 0 and 6 cells ({} r), got {}",
                    6.0 * self.cell_size,
                    self.particle_coverage
                ),
            });
        }
        if !(self.iso_offset.is_finite() && self.iso_offset.abs() <= 1.0) {
            return Err(Error::InvalidOption {
                option: "iso_offset",
                message: format!(
                    "must be between −1 and 1 (multiples of r), got {}",
                    self.iso_offset
                ),
            });
        }
        if self.kernel == Kernel::Anisotropic {
            self.anisotropy.validate()?;
            if self.anisotropy.reach() / self.cell_size > 64.0 {
                return Err(Error::InvalidOption {
                    option: "kernel_radius/cell_size",
                    message: format!(
                        "anisotropic kernels of radius {} r stretched up to {} reach {:.1} r, more than 64 cells of {} r: a smaller kernel radius or stretch, or larger cells",
                        self.anisotropy.kernel_radius,
                        self.anisotropy.max_stretch,
                        self.anisotropy.reach(),
                        self.cell_size
                    ),
                });
            }
        }
        if !(self.t_low.is_finite() && self.t_high.is_finite() && self.t_low < self.t_high) {
            return Err(Error::InvalidOption {
                option: "t_low/t_high",
                message: format!(
                    "need t_low < t_high, got {} and {}",
                    self.t_low, self.t_high
                ),
            });
        }
        Ok(())
    }
}

/// What the field stage did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct FieldStats {
    /// Particles that entered the field.
    pub particles: usize,
    /// Allocated 8³ blocks.
    pub blocks: usize,
    /// Lattice vertices with at least one particle in range.
    pub vertices_in_band: usize,
    /// Particles the Solenthaler surface would leave outside, covered by a sphere of
    /// radius `c·r` (see [`FieldOptions::particle_coverage`]).
    pub uncovered_particles: usize,
    /// Bytes of block storage.
    pub block_bytes: usize,
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

/// Blocks, per axis, between a block and the farthest block a particle of it can reach
/// (`⌈R / (8h)⌉`).
pub(crate) fn block_reach(options: &FieldOptions) -> i32 {
    (kernel_reach(options) / options.cell_size / BLOCK_EDGE as f32).ceil() as i32
}

/// Farthest a particle's kernel reaches from the particle, multiples of `r`: `R`, or with
/// anisotropic kernels the longer of `R` (the covariance neighbourhood) and the longest
/// semi-axis plus the largest centre shift.
pub(crate) fn kernel_reach(options: &FieldOptions) -> f32 {
    match options.kernel {
        Kernel::Isotropic => options.influence_radius,
        Kernel::Anisotropic => options.influence_radius.max(options.anisotropy.reach()),
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

/// Checks that every position is finite and within the lattice's coordinate range.
pub(crate) fn check_positions(positions: &[Vec3], options: &FieldOptions) -> Result<()> {
    check_positions_from(0, positions, options)
}

/// [`check_positions`] for a chunk whose first particle has input index `first`.
pub(crate) fn check_positions_from(
    first: usize,
    positions: &[Vec3],
    options: &FieldOptions,
) -> Result<()> {
    let inv_h = 1.0 / options.cell_size_world();
    if let Some(i) = positions.par_iter().position_first(|p| {
        !p.is_finite() || (p.as_dvec3() * inv_h).abs().max_element() > MAX_CELL_COORDINATE
    }) {
        let p = positions[i];
        let i = first + i;
        let h = options.cell_size_world();
        return Err(Error::ParticleOutOfRange {
            path: None,
            message: if p.is_finite() {
                format!(
                    "particle {i} at {p} lies {:.3e} cells of {h:.3e} (the cell size, from the particle radius {}) from the origin; the lattice reaches 2^23 cells: the particle radius is too small for these coordinates, or the coordinates are not in the radius's units",
                    (p.as_dvec3() * inv_h).abs().max_element(),
                    options.particle_radius
                )
            } else {
                format!("particle {i} has a non-finite coordinate {p}")
            },
        });
    }
    Ok(())
}

/// Computes the field of `positions` (world units) on the whole sparse lattice.
pub fn compute_field(
    positions: &[Vec3],
    options: &FieldOptions,
) -> Result<(SparseField, FieldStats)> {
    options.validate()?;
    check_positions(positions, options)?;
    let (mut field, mut stats) = match options.kernel {
        Kernel::Isotropic => compute_blocks(positions, options, None),
        Kernel::Anisotropic => {
            let (kernels, _) = crate::anisotropy::compute_kernels(positions, options)?;
            anisotropic::compute_blocks(&kernels, options, None)
        }
    };
    stats.uncovered_particles = apply_coverage(&mut field, positions, options, None);
    apply_iso_offset(&mut field, options);
    Ok((field, stats))
}

/// Moves the zero level set outwards by [`FieldOptions::iso_offset`]: every value, and
/// the value of vertices not stored, minus `δ·r`. Applied last, after coverage.
pub(crate) fn apply_iso_offset(field: &mut SparseField, options: &FieldOptions) {
    let delta = options.iso_offset * options.particle_radius;
    if delta != 0.0 {
        field.shift_values(-delta);
    }
}

/// Computes the blocks of the pure Solenthaler field within `range` (all blocks when
/// `None`) from `positions`, which must include every particle within `R` of those blocks,
/// in a canonical order (the same relative order in every tiling). Coverage is applied
/// afterwards by [`apply_coverage`]. Options must be valid.
pub(crate) fn compute_blocks(
    positions: &[Vec3],
    options: &FieldOptions,
    range: Option<BlockRange>,
) -> (SparseField, FieldStats) {
    compute_blocks_with(positions, options, range, true)
}

/// [`compute_blocks`]; `simd`: the AVX2 copy of the kernel may be used (the values are the
/// same either way, which the tests check).
fn compute_blocks_with(
    positions: &[Vec3],
    options: &FieldOptions,
    range: Option<BlockRange>,
    simd: bool,
) -> (SparseField, FieldStats) {
    let h = options.cell_size_world();
    let inv_h = 1.0 / h;
    let radius_cells = options.influence_radius / options.cell_size;

    // Particles sorted by (home half-block, index) in (z, y, x) order, copied into that
    // order: a block then scans the particles of the half-blocks within reach, not of whole
    // neighbour blocks (with R = 4 h, 512 particle slots instead of 1728, most of which
    // would be out of reach), and the half-blocks of one (y, z) half-row within reach are
    // one contiguous run of the copy. Particles already in that order (a tile's) are
    // taken as they are: sorting them would not move any.
    let halves: Vec<BlockKey> = positions
        .par_iter()
        .map(|p| home_half_block(*p, inv_h))
        .collect();
    let zyx = |k: &BlockKey| [k[2], k[1], k[0]];
    let (runs, sorted) = if halves.par_windows(2).all(|w| zyx(&w[0]) <= zyx(&w[1])) {
        let runs = crate::grid::key_runs(halves.iter().copied());
        (runs, Cow::Borrowed(positions))
    } else {
        let order = crate::grid::sort_by_key_zyx(&halves);
        let runs = crate::grid::key_runs(order.iter().map(|&i| halves[i as usize]));
        let sorted: Vec<Vec3> = order.par_iter().map(|&i| positions[i as usize]).collect();
        (runs, Cow::Owned(sorted))
    };
    drop(halves);
    let half_reach = (radius_cells / HALF_BLOCK_EDGE as f32).ceil() as i32;
    let candidates = candidate_blocks(runs.iter().map(|r| r.0), half_reach, range);
    let index = HalfRowIndex::new(&runs);
    drop(runs);

    let kernel = BlockKernel {
        sorted: &sorted,
        index: &index,
        half_reach,
        inv_h,
        radius_cells,
        h,
        options,
        simd,
    };
    evaluate_candidates(
        &candidates,
        positions.len(),
        options,
        RowLists::new,
        |lists, key, out| kernel.evaluate(key, lists, out),
    )
}

/// Evaluates every candidate block into one contiguous array with `evaluate` (per-thread
/// scratch from `scratch`; `None` when no particle reaches the block), then compacts
/// away the candidates no particle reaches: the field and its figures. Shared by the
/// isotropic and the anisotropic kernel.
pub(super) fn evaluate_candidates<T: Send>(
    candidates: &[BlockKey],
    particles: usize,
    options: &FieldOptions,
    scratch: impl Fn() -> T + Sync + Send,
    evaluate: impl Fn(&mut T, BlockKey, &mut BlockValues) -> Option<usize> + Sync + Send,
) -> (SparseField, FieldStats) {
    let mut values: Vec<BlockValues> = zeroed_blocks(candidates.len());
    let in_band: Vec<Option<usize>> = candidates
        .par_iter()
        .zip(values.par_iter_mut())
        .map_init(scratch, |t, (&key, out)| evaluate(t, key, out))
        .collect();
    let mut stats = FieldStats {
        particles,
        ..FieldStats::default()
    };
    let mut kept = 0;
    let mut keys = Vec::with_capacity(candidates.len());
    for (slot, (key, n)) in candidates.iter().zip(&in_band).enumerate() {
        if let Some(n) = n {
            stats.vertices_in_band += n;
            if slot != kept {
                // A move, not a swap: the block left behind is dropped.
                values.copy_within(slot..=slot, kept);
            }
            keys.push(*key);
            kept += 1;
        }
    }
    values.truncate(kept);
    values.shrink_to_fit();
    stats.blocks = kept;
    let field = SparseField::from_parts(
        options.cell_size_world(),
        options.outside_value(),
        &keys,
        values,
    );
    stats.block_bytes = field.memory_bytes();
    (field, stats)
}

/// Rows of vertices in a block.
const ROWS: usize = BLOCK_VOLUME / ROW;

struct BlockKernel<'a> {
    /// Particle positions (world units) sorted by home half-block (see [`HalfRowIndex`]).
    sorted: &'a [Vec3],
    index: &'a HalfRowIndex,
    /// Half-blocks, per axis, beyond a block's own two whose particles can reach it
    /// (`⌈R / 4h⌉`).
    half_reach: i32,
    inv_h: f64,
    radius_cells: f32,
    h: f64,
    options: &'a FieldOptions,
    /// May use the AVX2 copy of the kernel.
    simd: bool,
}

impl BlockKernel<'_> {
    /// Accumulates and finalises one block; `None` when no particle reaches it.
    ///
    /// On x86-64 CPUs with AVX2 the same code is compiled a second time with AVX2 and FMA
    /// enabled and picked at run time: one row of eight vertices is then one vector
    /// instruction instead of two. The fused products are written as `mul_add` (one
    /// rounding, in hardware or in libm) and Rust never contracts other `a * b + c`, so
    /// both versions round identically and give bit-identical fields.
    fn evaluate(
        &self,
        key: BlockKey,
        lists: &mut RowLists,
        values: &mut BlockValues,
    ) -> Option<usize> {
        #[cfg(target_arch = "x86_64")]
        if self.simd
            && std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: the CPU supports the features the function is compiled for.
            return unsafe { self.evaluate_avx2(key, lists, values) };
        }
        self.evaluate_portable(key, lists, values)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn evaluate_avx2(
        &self,
        key: BlockKey,
        lists: &mut RowLists,
        values: &mut BlockValues,
    ) -> Option<usize> {
        self.evaluate_portable(key, lists, values)
    }

    /// Two steps: the particles within reach are listed (in scan order) with the set of
    /// rows of vertices each one meets, a 64-bit mask, and the masks of every 64 particles
    /// are transposed into per-row sets of particles; then each row sums its particles
    /// with its running sums in registers and is finalised at once. Each vertex adds its
    /// particles in scan order, whatever the steps.
    // Index loops over lanes on purpose: they inline into (and vectorize within) the AVX2
    // copy, where iterator adaptors' closures may not.
    #[allow(clippy::needless_range_loop)]
    #[inline(always)]
    fn evaluate_portable(
        &self,
        key: BlockKey,
        lists: &mut RowLists,
        values: &mut BlockValues,
    ) -> Option<usize> {
        lists.particles.clear();
        lists.rows.clear();
        let origin = [0, 1, 2].map(|a| key[a] as f64 * BLOCK_EDGE as f64);
        let rc = self.radius_cells;
        let rc2 = rc * rc;
        let inv_rc2 = 1.0 / rc2;
        // A particle of half-block j lies in cells [4j, 4j + 4): it reaches the block's
        // vertices [8k, 8k + 7] only for 2k − ⌈R/4h⌉ ≤ j ≤ 2k + 1 + ⌈R/4h⌉.
        let (first, last) = (
            key.map(|k| 2 * k - self.half_reach),
            key.map(|k| 2 * k + 1 + self.half_reach),
        );
        for hz in first[2]..=last[2] {
            for hy in first[1]..=last[1] {
                for p in &self.sorted[self.index.run(hy, hz, first[0], last[0])] {
                    let p = p.as_dvec3() * self.inv_h;
                    // Particle in block-local cell units.
                    let x = [
                        (p.x - origin[0]) as f32,
                        (p.y - origin[1]) as f32,
                        (p.z - origin[2]) as f32,
                    ];
                    let lo = x.map(|c| ((c - rc).ceil() as i32).max(0));
                    let hi = x.map(|c| ((c + rc).floor() as i32).min(BLOCK_EDGE - 1));
                    if lo[0] > hi[0] || lo[1] > hi[1] || lo[2] > hi[2] {
                        continue;
                    }
                    let index = lists.particles.len();
                    if index % 64 == 0 {
                        lists.rows.push([0; ROWS]);
                    }
                    let group = lists.rows.last_mut().expect("a group");
                    group[index % 64] = row_mask(x, lo, hi, inv_rc2);
                    lists.particles.push(x);
                }
            }
        }
        let n = lists.particles.len();
        if n == 0 {
            return None;
        }
        for group in &mut lists.rows {
            transpose_bits(group);
        }
        let mut in_band = 0;
        for row in 0..ROWS {
            if lists.rows.iter().all(|group| group[row] == 0) {
                // No particle within reach of the row: outside the band.
                values[row * ROW..][..ROW].fill(self.options.outside_value());
                continue;
            }
            let (b, c) = ((row % ROW) as f32, (row / ROW) as f32);
            let mut sums = [[0.0f32; ROW]; SUMS];
            for (group, members) in lists.particles.chunks(64).zip(&lists.rows) {
                let mut bits = members[row];
                while bits != 0 {
                    let x = group[bits.trailing_zeros() as usize];
                    accumulate_row(&mut sums, x[0], b - x[1], c - x[2], inv_rc2);
                    bits &= bits - 1;
                }
            }
            in_band += self.finalize_row(&sums, row, values);
        }
        Some(in_band)
    }

    /// Turns one row's running sums into field values; returns how many of its vertices
    /// are in the band (`Σw > 0`).
    #[allow(clippy::needless_range_loop)]
    #[inline(always)]
    fn finalize_row(
        &self,
        row_sums: &[[f32; ROW]; SUMS],
        row: usize,
        values: &mut BlockValues,
    ) -> usize {
        let r = self.options.particle_radius as f64;
        let (t_low, t_high) = (self.options.t_low as f64, self.options.t_high as f64);
        // Each quantity as a lane array, so that the Jacobians and their eigenvalues run
        // as vector instructions. Lanes outside the band (Σw = 0) compute garbage that is
        // not stored. (Plain loops rather than closures: they stay inside the AVX2 copy of
        // the kernel.)
        let mut sums = [[0.0f64; ROW]; SUMS];
        for k in 0..SUMS {
            for i in 0..ROW {
                sums[k][i] = row_sums[k][i] as f64;
            }
        }
        let w = sums[0];
        // One division per vertex, then products, instead of twelve f64 divisions (4M
        // scene: field 2.02–2.07 → 1.99–2.00 s; the outputs of the eight reference runs
        // and of the 4M scene stayed byte for byte the same).
        let mut inv_w = [0.0f64; ROW];
        for i in 0..ROW {
            inv_w[i] = 1.0 / w[i];
        }
        // v − vbar = Σ w r / Σ w.
        let mut d = [[0.0f64; ROW]; 3];
        for a in 0..3 {
            for i in 0..ROW {
                d[a][i] = sums[1 + a][i] * inv_w[i];
            }
        }
        // x_i = v − r_i gives J_ab = ((v − vbar)_a Σ∂_b w − Σ g r_a r_b) / Σ w, with
        // Σ∂_b w = sums[4 + b] and the symmetric Σ g r_a r_b in sums[7..13].
        const SYMMETRIC: [usize; 9] = [7, 8, 9, 8, 10, 11, 9, 11, 12];
        let mut jac = [[0.0f64; ROW]; 9];
        for a in 0..3 {
            for b in 0..3 {
                for i in 0..ROW {
                    jac[a * 3 + b][i] =
                        (d[a][i] * sums[4 + b][i] - sums[SYMMETRIC[a * 3 + b]][i]) * inv_w[i];
                }
            }
        }
        let ev = largest_eigenvalue_real_part_lanes(&jac);
        let mut in_band = 0;
        for i in 0..ROW {
            let idx = row * ROW + i;
            if w[i] <= 0.0 {
                values[idx] = self.options.outside_value();
                continue;
            }
            in_band += 1;
            let f = concavity_factor(ev[i], t_low, t_high);
            let dist_cells = (d[0][i] * d[0][i] + d[1][i] * d[1][i] + d[2][i] * d[2][i]).sqrt();
            values[idx] = (dist_cells * self.h - r * f) as f32;
        }
        in_band
    }
}

/// Number of running sums per vertex: Σw, Σw·r (3), Σ∇w (3), Σ g·r⊗r (6, symmetric),
/// with `r = v − x_i` (cells) and `∇w_i = g·r`, `g = −6 (1 − s²)² / R²`.
const SUMS: usize = 13;
/// Row length: one block row of vertices along x.
const ROW: usize = BLOCK_EDGE as usize;

/// Adds one particle's terms to one row of vertices' running sums (`x`: the particle's
/// block-local x (cells), `ry`, `rz`: the row's offsets from it, `inv_rc2 = 1 / R²` in
/// cells). Lanes outside the influence sphere get `q = 0`, hence
/// zero weight and zero gradient: adding them leaves every sum as it was.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn accumulate_row(sums: &mut [[f32; ROW]; SUMS], x: f32, ry: f32, rz: f32, inv_rc2: f32) {
    let ryz2 = ry * ry + rz * rz;
    let g_scale = -6.0 * inv_rc2;
    let [s0, s1, s2, s3, s4, s5, s6, s7, s8, s9, s10, s11, s12] = sums;
    for i in 0..ROW {
        let rx = i as f32 - x;
        let q = (1.0 - (rx * rx + ryz2) * inv_rc2).max(0.0);
        let q2 = q * q;
        let w = q2 * q;
        let g = q2 * g_scale;
        let (gx, gy, gz) = (g * rx, g * ry, g * rz);
        s0[i] += w;
        s1[i] = w.mul_add(rx, s1[i]);
        s2[i] = w.mul_add(ry, s2[i]);
        s3[i] = w.mul_add(rz, s3[i]);
        s4[i] += gx;
        s5[i] += gy;
        s6[i] += gz;
        s7[i] = gx.mul_add(rx, s7[i]);
        s8[i] = gx.mul_add(ry, s8[i]);
        s9[i] = gx.mul_add(rz, s9[i]);
        s10[i] = gy.mul_add(ry, s10[i]);
        s11[i] = gy.mul_add(rz, s11[i]);
        s12[i] = gz.mul_add(rz, s12[i]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_vector_kernel_gives_the_portable_kernel_values_bit_for_bit() {
        // A jittered block of particles with a loose film and a few strays: every branch
        // of the eigenvalue (one or three real roots, flat and sharp neighbourhoods).
        let r = 0.01f32;
        let mut rng = crate::test_rng::TestRng::new(5);
        let mut jitter = || (rng.unit_f32() - 0.5) * r;
        let mut positions = Vec::new();
        for z in 0..10 {
            for y in 0..14 {
                for x in 0..12 {
                    let p = Vec3::new(x as f32, y as f32, z as f32) * 2.0 * r;
                    positions.push(p + Vec3::new(jitter(), jitter(), jitter()));
                }
            }
        }
        for k in 0..40 {
            let t = k as f32 * 0.7;
            positions.push(Vec3::new(t.sin(), 0.3 * t.cos(), 0.6) * 0.3 + Vec3::splat(0.12));
        }
        let options = FieldOptions::new(r);
        let (portable, _) = compute_blocks_with(&positions, &options, None, false);
        let (vector, _) = compute_blocks_with(&positions, &options, None, true);
        assert_same_blocks_bit_for_bit(&portable, &vector);
    }

    /// Both fields hold the same blocks (more than 10) with bit-identical values.
    fn assert_same_blocks_bit_for_bit(a: &SparseField, b: &SparseField) {
        assert!(a.blocks().count() > 10);
        assert_eq!(a.blocks().count(), b.blocks().count());
        for (key, values) in a.blocks() {
            let other = b.block(key).expect("same blocks");
            for (x, y) in values.iter().zip(other.iter()) {
                assert_eq!(x.to_bits(), y.to_bits(), "block {key:?}");
            }
        }
    }

    #[test]
    fn particles_already_in_half_block_order_give_the_sorted_values() {
        // A shuffled cloud, and the same cloud sorted as the field sorts it (home
        // half-block, then index): the second is taken as it is, the first is sorted
        // into the second, and the values must agree bit for bit.
        let r = 0.01f32;
        let mut rng = crate::test_rng::TestRng::new(17);
        let shuffled: Vec<Vec3> = (0..3000)
            .map(|_| Vec3::new(rng.unit_f32(), rng.unit_f32(), rng.unit_f32()) * 0.3 - 0.1)
            .collect();
        let options = FieldOptions::new(r);
        let inv_h = 1.0 / options.cell_size_world();
        let mut order: Vec<usize> = (0..shuffled.len()).collect();
        order.sort_by_key(|&i| {
            let k = home_half_block(shuffled[i], inv_h);
            (k[2], k[1], k[0], i)
        });
        let sorted: Vec<Vec3> = order.iter().map(|&i| shuffled[i]).collect();
        let (from_shuffled, _) = compute_blocks(&shuffled, &options, None);
        let (from_sorted, _) = compute_blocks(&sorted, &options, None);
        assert_same_blocks_bit_for_bit(&from_shuffled, &from_sorted);
    }
}
