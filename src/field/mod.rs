//! The scalar field whose zero set is the surface, with either particle kernel
//! ([`Kernel`]):
//!
//! * **anisotropic** (the default): Yu & Turk 2013 kernels, each particle's ellipsoid from
//!   the weighted covariance of its neighbours within `R` ([`compute_kernels`], in
//!   `kernels.rs`; gathers in `gather.rs`, the 3×3 eigen-solver in `eigen.rs`), and
//!   `phi(v) = (v − vbar(v))·n(v) − ρ_s·r` with `vbar` the ellipsoid-weighted mean, `n`
//!   the direction in which that weight falls off and `ρ_s` =
//!   [`AnisotropyOptions::surface_distance`] (`anisotropic.rs`);
//! * **isotropic** (the paper's): the field of Solenthaler, Schläfli and Pajarola 2007, "A
//!   Unified Particle Model for Fluid-Solid Interactions" (§ surface reconstruction), as
//!   used by Akinci et al. 2013 (`isotropic.rs`, the concavity factor in `concavity.rs`),
//!   detailed below.
//!
//! Both evaluate block by block over `evaluate.rs`; a particle the surface would leave
//! outside is then covered by a ball (`coverage.rs`), and the iso offset shifts the level.
//! `compute_tile` is the one path of a tile's field.
//!
//! **Input:** particle centres (world units) and [`FieldOptions`].
//! **Output:** a [`SparseField`] holding `phi` (world units, negative inside the fluid) at
//! every lattice vertex that has a particle within the influence radius `R`, in 8³ blocks.
//!
//! For the isotropic field at a vertex `v`, with `k(s) = max(0, (1 − s²)³)` and `w_i = k(|v − x_i| / R)`:
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

use crate::error::{Error, Result};
use crate::grid::{
    check_positions, home_half_block, BlockKey, BlockRange, SparseField, BLOCK_EDGE,
};
use glam::Vec3;
use rayon::prelude::*;
use std::time::Instant;

mod anisotropic;
mod candidates;
mod concavity;
mod coverage;
mod eigen;
mod evaluate;
mod gather;
mod isotropic;
mod kernels;
mod rows;
pub(crate) use coverage::apply_coverage;
pub use kernels::{compute_kernels, AnisotropyOptions, AnisotropyStats, ParticleKernel};

/// Parameters of the field. Lengths other than the particle radius are multiples of `r`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
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
    /// Yu and Turk 2013 anisotropic kernels (`anisotropy`), see
    /// `anisotropic`.
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

    /// Bytes per particle the kernels add to a tile or an untiled run (0 for the
    /// isotropic kernel, which needs nothing beyond the positions).
    pub(crate) fn kernel_bytes_per_particle(&self) -> u64 {
        match self.kernel {
            Kernel::Isotropic => 0,
            Kernel::Anisotropic => kernels::BYTES_PER_PARTICLE,
        }
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
        let (lo, hi) = crate::radius::RADIUS_LIMITS;
        if !(lo..=hi).contains(&self.particle_radius) {
            return Err(Error::InvalidOption {
                option: "particle_radius",
                message: format!(
                    "must lie within {lo:e}–{hi:e} world units (the squares of the reaches must stay finite in f32), got {:?}",
                    self.particle_radius
                ),
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

/// Particles of several sizes (a radius attribute): each particle's radius `r_i` as a
/// multiple `ρ_i = r_i / r` of the reference radius r ([`FieldOptions::particle_radius`],
/// in which every option is given), aligned with the particles it is passed with. Every
/// length of a particle's own (influence radius, kernel radius, coverage ball, surface
/// distance) is then `ρ_i` times the option's; the lattice stays one cell size.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Sizes<'a> {
    /// `ρ_i`, one per particle.
    pub ratios: &'a [f32],
    /// The largest `ρ_i` of the whole frame, at least 1: reaches grow by it.
    pub largest: f32,
}

/// The largest radius as a multiple of r, at least 1 (1 without sizes).
pub(crate) fn largest_ratio(sizes: Option<Sizes<'_>>) -> f32 {
    sizes.map_or(1.0, |s| s.largest.max(1.0))
}

/// Blocks, per axis, between a block and the farthest block a particle of it can reach
/// (`⌈R / (8h)⌉`, R of the largest particle).
pub(crate) fn block_reach(options: &FieldOptions, sizes: Option<Sizes<'_>>) -> i32 {
    (kernel_reach(options, sizes) / options.cell_size / BLOCK_EDGE as f32).ceil() as i32
}

/// Blocks, per axis, that particle coverage needs around the blocks whose values are used
/// (`c·r_max + 2h`, see [`apply_coverage`]): 1 unless particles are much larger than r.
pub(crate) fn coverage_blocks(options: &FieldOptions, sizes: Option<Sizes<'_>>) -> i32 {
    let reach = options.particle_coverage * largest_ratio(sizes) + 2.0 * options.cell_size;
    ((reach / options.cell_size / BLOCK_EDGE as f32).ceil() as i32).max(1)
}

/// Farthest a particle's kernel reaches from the particle, multiples of `r`: `R`, or with
/// anisotropic kernels the longer of `R` (the covariance neighbourhood) and the longest
/// semi-axis plus the largest centre shift; times the largest particle's `ρ`.
pub(crate) fn kernel_reach(options: &FieldOptions, sizes: Option<Sizes<'_>>) -> f32 {
    let reach = match options.kernel {
        Kernel::Isotropic => options.influence_radius,
        Kernel::Anisotropic => options.influence_radius.max(options.anisotropy.reach()),
    };
    reach * largest_ratio(sizes)
}

/// Computes the field of `positions` (world units, any order) on the whole sparse
/// lattice: every particle enters the field (the pipeline first splits off the isolated
/// ones). The same computation as a tile's (`compute_tile`) over one tile holding every
/// particle.
pub fn compute_field(
    positions: &[Vec3],
    options: &FieldOptions,
) -> Result<(SparseField, FieldStats)> {
    options.validate()?;
    check_positions(
        0,
        positions,
        options.cell_size_world(),
        options.particle_radius,
    )?;
    let (_, sorted, sorted_halves) = canonical_order(positions, options);
    let in_field = vec![true; sorted.len()];
    let particles = TileParticles {
        positions: sorted,
        halves: sorted_halves,
        in_field,
        ratios: None,
    };
    let tile = compute_tile(particles, options, None, None);
    Ok((tile.field, tile.stats))
}

/// `positions` in the canonical order (home half-block in (z, y, x) order, then input
/// index; see the module docs): the input index of each, the positions and their home
/// half-blocks.
pub(crate) fn canonical_order(
    positions: &[Vec3],
    options: &FieldOptions,
) -> (Vec<u32>, Vec<Vec3>, Vec<BlockKey>) {
    let inv_h = 1.0 / options.cell_size_world();
    let halves: Vec<BlockKey> = positions
        .par_iter()
        .map(|p| home_half_block(*p, inv_h))
        .collect();
    let order = crate::grid::sort_by_key_zyx(&halves);
    let sorted: Vec<Vec3> = order.par_iter().map(|&i| positions[i as usize]).collect();
    let sorted_halves: Vec<BlockKey> = order.iter().map(|&i| halves[i as usize]).collect();
    (order, sorted, sorted_halves)
}

/// The particles one tile's field is computed from, in the canonical order (home
/// half-block in (z, y, x) order, then input index; see the module docs).
pub(crate) struct TileParticles {
    /// Positions, world units: the particles of the field and, for the anisotropic
    /// kernels, every particle within `R` of them.
    pub positions: Vec<Vec3>,
    /// The home half-block of each ([`crate::grid::home_half_block`]).
    pub halves: Vec<BlockKey>,
    /// Whether each one enters the field (not isolated, and near enough to the tile).
    pub in_field: Vec<bool>,
    /// For particles of several sizes, each one's radius in multiples of r, and the
    /// largest of the frame ([`Sizes`]).
    pub ratios: Option<(Vec<f32>, f32)>,
}

/// One tile's field and what it took.
pub(crate) struct TileField {
    /// The field blocks, coverage and iso offset applied.
    pub field: SparseField,
    /// Its figures (`uncovered_particles` counts those of the counted blocks).
    pub stats: FieldStats,
    /// Seconds spent on the anisotropic kernels (0 with isotropic ones).
    pub kernel_seconds: f64,
    /// Seconds spent on the field blocks, coverage and the iso offset.
    pub field_seconds: f64,
}

/// The field of one tile, the path of every reconstruction: the anisotropic kernels of
/// the particles `in_field` (from all their neighbours among `particles`), the field
/// blocks within `blocks` (all when `None`), particle coverage ([`apply_coverage`];
/// uncovered particles counted when their home block lies in `counted`, all when
/// `None`), and the iso offset. `particles` must hold every particle within reach of
/// those blocks (and for the kernels every neighbour within `R` of those), and the blocks
/// used must lie `c·r + 2h` inside `blocks` (coverage). Options must be valid.
pub(crate) fn compute_tile(
    particles: TileParticles,
    options: &FieldOptions,
    blocks: Option<BlockRange>,
    counted: Option<BlockRange>,
) -> TileField {
    let clock = Instant::now();
    let sizes = particles.ratios.as_ref().map(|(ratios, largest)| Sizes {
        ratios,
        largest: *largest,
    });
    let kernels = (options.kernel == Kernel::Anisotropic).then(|| {
        kernels::kernels_sorted(
            &particles.positions,
            &particles.halves,
            options,
            &particles.in_field,
            sizes,
        )
    });
    let kernel_seconds = clock.elapsed().as_secs_f64();
    let clock = Instant::now();
    let wanted = |k: &usize| particles.in_field[*k];
    let field_particles: Vec<Vec3> = (0..particles.positions.len())
        .filter(wanted)
        .map(|k| particles.positions[k])
        .collect();
    let field_ratios: Option<Vec<f32>> = sizes.map(|s| {
        (0..s.ratios.len())
            .filter(wanted)
            .map(|k| s.ratios[k])
            .collect()
    });
    let largest = sizes.map_or(1.0, |s| s.largest);
    // The particles are held only until the field has its own (`field_particles`, and the
    // kernels sorted by centre).
    drop(particles);
    let sizes = field_ratios
        .as_deref()
        .map(|ratios| Sizes { ratios, largest });
    let (mut field, mut stats) = match kernels {
        None => isotropic::compute_blocks(&field_particles, sizes, options, blocks),
        Some(kernels) => anisotropic::compute_blocks(kernels, sizes, options, blocks),
    };
    stats.uncovered_particles =
        apply_coverage(&mut field, &field_particles, sizes, options, counted);
    apply_iso_offset(&mut field, options);
    TileField {
        field,
        stats,
        kernel_seconds,
        field_seconds: clock.elapsed().as_secs_f64(),
    }
}

/// Moves the zero level set outwards by [`FieldOptions::iso_offset`]: every value, and
/// the value of vertices not stored, minus `δ·r`. Applied last, after coverage.
fn apply_iso_offset(field: &mut SparseField, options: &FieldOptions) {
    let delta = options.iso_offset * options.particle_radius;
    if delta != 0.0 {
        field.shift_values(-delta);
    }
}
