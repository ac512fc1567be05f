//! Anisotropic particle kernels (Yu and Turk 2013, "Reconstructing Surfaces of
//! Particle-Based Fluids Using Anisotropic Kernels", § 3–4).
//!
//! **Input:** particle centres (world units) and [`AnisotropyOptions`].
//! **Output:** one [`ParticleKernel`] per particle: a smoothed centre and an ellipsoid
//! (its quadratic form), stretched along the local surface and squeezed across it.
//!
//! For particle `i`, over its neighbours `j` within the influence radius `R` (itself
//! included), with `w_ij = 1 − (|x_j − x_i| / R)³`:
//! * the weighted mean `x̄_i = Σ w_ij x_j / Σ w_ij` and covariance
//!   `C_i = Σ w_ij (x_j − x̄_i)(x_j − x̄_i)ᵀ / Σ w_ij`;
//! * the smoothed centre `c_i = x_i + λ (x̄_i − x_i)` (Laplacian smoothing, the paper's
//!   eq. 6), its shift capped at [`AnisotropyOptions::max_shift`];
//! * the eigenvalues `σ1 ≥ σ2 ≥ σ3` of `C_i`, the two smaller ones raised to at least
//!   `σ1 / k_r` (eq. 15), and the ellipsoid's semi-axes along the eigenvectors
//!   `a_k = h_a σ_k / (σ1 σ2 σ3)^{1/3}`: the volume of a sphere of radius `h_a`, so every
//!   particle's kernel has the same integral (the paper's `k_s` scales instead; a fixed
//!   volume keeps the density of the bulk independent of the stretch);
//! * fewer than `N_ε` neighbours: a sphere of radius `h_a` (the paper's `k_n I`).
//!
//! A flat surface particle gets a disc `h_a·(1.59, 1.59, 0.40)` (`k_r = 4`), a filament
//! particle a needle `h_a·(2.52, 0.63, 0.63)`; a particle of the bulk, whose neighbourhood
//! is a full ball, stays close to a sphere.
//!
//! **Evaluation order:** the sums of particle `i` run over its neighbours in the
//! canonical order of the field ([`crate::field`]: home half-block in (z, y, x) order,
//! then input index), in f64 relative to `x_i`; a tile sees the same neighbours in the
//! same order as the whole scene, so the kernels do not depend on the tiling or the
//! thread count.
//!
//! **Every field particle gets its kernel, deep inside the fluid too.** The field
//! evaluates every vertex a kernel reaches, and each kernel reaches the corners of its
//! own particle's cell, which coverage reads as well (at the default options the
//! shortest semi-axis, at least `h_a k_r^{-2/3}` = 2.41 r, exceeds the cell's
//! diagonal); which values the surface actually depends on (corners of the cells
//! marching cubes triangulates) is known only from the signs of the finished field.
//! Skipping kernels exactly would need those signs first; no test before the kernels
//! bounds them (`docs/performance-log.md`, session 18, with what a perfect oracle would
//! skip: about half the kernels, `examples/kernel_skip_census.rs`).

use super::eigen::symmetric_eigen;
use super::gather::{row_groups, Around, Gathered, Reaches, Source};
use crate::field::FieldOptions;
use crate::grid::{BlockKey, HALF_BLOCK_EDGE};
use glam::{DMat3, DVec3, Vec3};
use rayon::prelude::*;

/// Parameters of the anisotropic kernels; lengths in multiples of the particle radius
/// `r`. The covariance neighbourhood is the field's influence radius `R`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub struct AnisotropyOptions {
    /// Radius `h_a` of the kernel of a particle with an isotropic neighbourhood, multiples
    /// of `r`. Default 3.5.
    pub kernel_radius: f32,
    /// Largest ratio `k_r` of the longest to the shortest axis. Default 1.75 (the paper
    /// uses 4; 1.75 measured better here, see `docs/quality.md`).
    pub max_stretch: f32,
    /// Fewest neighbours `N_ε` (within `R`, the particle itself not counted) for a
    /// stretched kernel; fewer give a sphere of radius `h_a`. Default 8.
    pub min_neighbours: u32,
    /// Centre smoothing `λ` in `[0, 1]` (0: the particle positions). Default 0: smoothing
    /// pulls the outer particles inwards (the fluid shrinks) and made faces rougher in
    /// every measurement (`docs/quality.md`).
    pub centre_smoothing: f32,
    /// Largest shift of a centre by smoothing, multiples of `r`. Default 1.
    pub max_shift: f32,
    /// Distance `ρ_s` of the surface from the weighted mean of the centres, multiples of
    /// `r` (the field's `phi = (v − vbar)·n − ρ_s r`). Default 1.08: on flat faces `vbar`
    /// lies a little below the outer centres (the second layer weighs in), which the
    /// extra 0.08 r makes up (see `docs/quality.md`).
    pub surface_distance: f32,
}

impl Default for AnisotropyOptions {
    fn default() -> Self {
        AnisotropyOptions {
            kernel_radius: 3.5,
            max_stretch: 1.75,
            min_neighbours: 8,
            centre_smoothing: 0.0,
            max_shift: 1.0,
            surface_distance: 1.08,
        }
    }
}

impl AnisotropyOptions {
    /// Longest semi-axis any kernel can have, multiples of `r`: `h_a k_r^{2/3}` (a needle).
    pub fn longest_axis(&self) -> f32 {
        self.kernel_radius * self.max_stretch.powf(2.0 / 3.0)
    }

    /// Farthest a kernel reaches from its particle, multiples of `r` (the longest axis,
    /// plus the largest shift when centres are smoothed).
    pub fn reach(&self) -> f32 {
        self.longest_axis()
            + if self.centre_smoothing > 0.0 {
                self.max_shift
            } else {
                0.0
            }
    }

    /// Checks that every parameter can work.
    pub fn validate(&self) -> crate::Result<()> {
        let bad = |option: &'static str, message: String| {
            Err(crate::Error::InvalidOption { option, message })
        };
        if !(self.kernel_radius.is_finite() && self.kernel_radius > 0.0) {
            return bad(
                "kernel_radius",
                format!("must be > 0 (multiples of r), got {}", self.kernel_radius),
            );
        }
        if !(self.max_stretch.is_finite() && self.max_stretch >= 1.0 && self.max_stretch <= 16.0) {
            return bad(
                "max_stretch",
                format!("must be between 1 and 16, got {}", self.max_stretch),
            );
        }
        if !(self.centre_smoothing.is_finite() && (0.0..=1.0).contains(&self.centre_smoothing)) {
            return bad(
                "centre_smoothing",
                format!("must be between 0 and 1, got {}", self.centre_smoothing),
            );
        }
        if !(self.surface_distance.is_finite()
            && self.surface_distance > 0.0
            && self.surface_distance <= 2.0)
        {
            return bad(
                "surface_distance",
                format!(
                    "must be > 0 and at most 2 (multiples of r), got {}",
                    self.surface_distance
                ),
            );
        }
        if !(self.max_shift.is_finite() && self.max_shift >= 0.0 && self.max_shift <= 4.0) {
            return bad(
                "max_shift",
                format!(
                    "must be between 0 and 4 (multiples of r), got {}",
                    self.max_shift
                ),
            );
        }
        Ok(())
    }
}

/// Bytes per particle that anisotropic kernels add to a tile or an untiled run: the
/// kernel of every loaded particle (64), then for the field particles the kernels kept
/// (64), the prepared copy (48, 52 sized; counted as 64: the tile sizes a budget picks,
/// and so the decimated output, stay as they were) and the sort by centre (16).
pub(crate) const BYTES_PER_PARTICLE: u64 = 208;

/// The kernel of one particle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParticleKernel {
    /// Smoothed centre, world units.
    pub centre: Vec3,
    /// Semi-axes, world units, longest first.
    pub axes: [f32; 3],
    /// Unit directions of the semi-axes (the eigenvectors of the covariance).
    pub directions: [Vec3; 3],
    /// Neighbours within `R`, the particle itself not counted.
    pub neighbours: u32,
}

impl ParticleKernel {
    /// The quadratic form `M` with `(v − c)ᵀ M (v − c) = 1` on the ellipsoid, for lengths
    /// measured in units of `unit` (world units per unit), as `[xx, xy, xz, yy, yz, zz]`.
    pub fn quadratic_form(&self, unit: f64) -> [f64; 6] {
        let mut m = [0.0f64; 6];
        for (a, d) in self.axes.iter().zip(&self.directions) {
            let inv = (unit / *a as f64).powi(2);
            let d = d.as_dvec3();
            m[0] += inv * d.x * d.x;
            m[1] += inv * d.x * d.y;
            m[2] += inv * d.x * d.z;
            m[3] += inv * d.y * d.y;
            m[4] += inv * d.y * d.z;
            m[5] += inv * d.z * d.z;
        }
        m
    }

    /// Half-extents of the ellipsoid's axis-aligned bounding box, in units of `unit`.
    pub fn half_extents(&self, unit: f64) -> [f64; 3] {
        let mut e = [0.0f64; 3];
        for (a, d) in self.axes.iter().zip(&self.directions) {
            let a2 = (*a as f64 / unit).powi(2);
            let d = d.as_dvec3();
            e[0] += a2 * d.x * d.x;
            e[1] += a2 * d.y * d.y;
            e[2] += a2 * d.z * d.z;
        }
        e.map(f64::sqrt)
    }
}

/// What the kernel stage did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct AnisotropyStats {
    /// Kernels computed.
    pub particles: usize,
    /// Kernels left spherical (fewer than `N_ε` neighbours).
    pub spherical: usize,
    /// Mean ratio of the longest to the shortest axis.
    pub mean_stretch: f64,
}

/// Computes the kernel of every particle of `positions` (world units, any order).
pub fn compute_kernels(
    positions: &[Vec3],
    field: &FieldOptions,
) -> crate::Result<(Vec<ParticleKernel>, AnisotropyStats)> {
    field.validate()?;
    crate::grid::check_positions(0, positions, field.cell_size_world(), field.particle_radius)?;
    let (order, sorted, sorted_halves) = super::canonical_order(positions, field);
    let kernels = kernels_sorted(
        &sorted,
        &sorted_halves,
        field,
        &vec![true; sorted.len()],
        None,
    );
    let mut out = vec![
        ParticleKernel {
            centre: Vec3::ZERO,
            axes: [0.0; 3],
            directions: [Vec3::X, Vec3::Y, Vec3::Z],
            neighbours: 0,
        };
        positions.len()
    ];
    for (k, &i) in kernels.into_iter().zip(&order) {
        out[i as usize] = k;
    }
    let stats = kernel_stats(&out, &field.anisotropy);
    Ok((out, stats))
}

/// Figures of a set of kernels.
pub(crate) fn kernel_stats(
    kernels: &[ParticleKernel],
    options: &AnisotropyOptions,
) -> AnisotropyStats {
    let spherical = kernels
        .iter()
        .filter(|k| k.neighbours < options.min_neighbours)
        .count();
    let stretch: f64 = kernels
        .iter()
        .map(|k| k.axes[0] as f64 / k.axes[2] as f64)
        .sum();
    AnisotropyStats {
        particles: kernels.len(),
        spherical,
        mean_stretch: if kernels.is_empty() {
            0.0
        } else {
            stretch / kernels.len() as f64
        },
    }
}

/// The kernels of the particles `positions` sorted by home half-block (`halves`, in
/// (z, y, x) order, then input index) where `wanted` is true, in their order. Every
/// neighbour within `R` of a wanted particle must be among `positions`. With `sizes`
/// (aligned with `positions`), particle i's neighbourhood is the particles within its own
/// `R·ρ_i`, its kernel radius `ĥ_a·r·ρ_i`, and its centre shift at most `max_shift·r·ρ_i`.
///
/// Per populated half-block, the particles of the half-blocks around it that can hold a
/// neighbour are gathered once, in their (z, y, x, index) order, and each wanted particle
/// of the half-block scans them: the neighbours of a particle are met in the canonical
/// order whatever the tiling.
///
/// **How far the gather reaches.** A particle's neighbours lie within `R` (a hair more,
/// against rounding), so they lie within `⌈R (1 + ε) / e⌉` half-blocks of edge `e` of its
/// own. With the default `R = 4 r` and `h = r`, `R` is exactly one half-block edge and
/// the hair makes that two: 125 half-blocks instead of 27. Only particles within the hair
/// of their half-block's faces can have a neighbour two half-blocks away, so the
/// half-blocks within `⌈R (1 − ε) / e⌉` are gathered for all, and the particles near a
/// face (about 1 in 10⁵) scan a wider gather of their own. The neighbours met, and their
/// order, are the same either way (the half-blocks a particle can reach come in the same
/// relative order in both gathers): on the 4M splash the kernels took 13–25 % less
/// time, the output byte for byte the same.
pub(crate) fn kernels_sorted(
    positions: &[Vec3],
    halves: &[BlockKey],
    field: &FieldOptions,
    wanted: &[bool],
    sizes: Option<super::Sizes<'_>>,
) -> Vec<ParticleKernel> {
    let edge = field.cell_size_world() * HALF_BLOCK_EDGE as f64;
    let largest = super::largest_ratio(sizes) as f64;
    let reaches = Reaches::new(field.influence_radius_world() * largest / edge);
    kernels_reaching(positions, halves, field, wanted, sizes, reaches)
}

/// [`kernels_sorted`] with the gathers' reaches given.
fn kernels_reaching(
    positions: &[Vec3],
    halves: &[BlockKey],
    field: &FieldOptions,
    wanted: &[bool],
    sizes: Option<super::Sizes<'_>>,
    reaches: Reaches,
) -> Vec<ParticleKernel> {
    debug_assert_eq!(positions.len(), halves.len());
    // The populated half-blocks (runs of the sorted particles) and, per (y, z) row of
    // half-blocks, the range of runs in it.
    let runs = crate::grid::key_runs(halves.iter().copied());
    let rows = crate::grid::row_ranges(runs.iter().map(|r| r.0));
    let edge = field.cell_size_world() * HALF_BLOCK_EDGE as f64;
    let source = Source {
        positions,
        ratios: sizes.map(|s| s.ratios),
        runs: &runs,
        rows: &rows,
    };
    // Finer cells than h = r: a gather per group of half-blocks along x ([`row_groups`]);
    // at h = r one per half-block, as a group of one.
    let common = reaches.common;
    let grouped = common >= 2;
    let groups = if grouped {
        row_groups(&runs)
    } else {
        Vec::new()
    };
    let count = if grouped { groups.len() } else { runs.len() };
    (0..count)
        .into_par_iter()
        .map_init(Scratch::default, |scratch, g| {
            let Scratch {
                gathered,
                wide,
                cells,
                near,
                volumes,
                gaps,
            } = scratch;
            let (g0, g1) = if grouped { groups[g] } else { (g, g + 1) };
            let group = &runs[g0..g1];
            let any_wanted = |&(_, start, end): &([i32; 3], u32, u32)| {
                wanted[start as usize..end as usize].iter().any(|&w| w)
            };
            if !group.iter().any(any_wanted) {
                return Vec::new();
            }
            // One gather over the group's half-blocks and those within reach of them.
            let (first, last) = (group[0].0, group[group.len() - 1].0);
            let lo = first.map(|k| k - common);
            let hi = [last[0] + common, first[1] + common, first[2] + common];
            source.gather_box(lo, hi, gathered);
            let mut out = Vec::new();
            for run @ &(c, start, end) in group {
                if !any_wanted(run) {
                    continue;
                }
                let (start, end) = (start as usize, end as usize);
                let here = gathered.around_of(c, common, edge, cells);
                // The wider gather, made for the first particle near a face that needs it.
                let mut wide_ready = false;
                for i in (start..end).filter(|&i| wanted[i]) {
                    let (around, gathered): (Around<'_>, &Gathered) = if reaches.common
                        == reaches.full
                        || reaches.within_common(positions[i], c, edge)
                    {
                        (here, &*gathered)
                    } else {
                        if !wide_ready {
                            source.gather(c, reaches.full, wide);
                            wide_ready = true;
                        }
                        (wide.around(edge), &*wide)
                    };
                    let around = &around;
                    let candidates = (&gathered.candidates[..], &gathered.ratios[..]);
                    out.push(match sizes {
                        None => kernel_of::<false>(
                            positions[i],
                            1.0,
                            candidates,
                            around,
                            (near, volumes, gaps),
                            field,
                        ),
                        Some(s) => kernel_of::<true>(
                            positions[i],
                            s.ratios[i] as f64,
                            candidates,
                            around,
                            (near, volumes, gaps),
                            field,
                        ),
                    });
                }
            }
            out
        })
        .flatten_iter()
        .collect()
}

/// Lanes of the neighbour sums of [`kernel_of`].
const LANES: usize = 8;

/// Per-thread scratch of [`kernels_sorted`].
#[derive(Default)]
struct Scratch {
    /// The gather of the current half-block, for its particles away from the faces.
    gathered: Gathered,
    /// The wider gather, for its particles near a face ([`Reaches`]).
    wide: Gathered,
    /// The half-blocks of the current one's gather ([`Gathered::around_of`]).
    cells: Vec<([usize; 3], u32, u32)>,
    /// Offsets of the candidates near the current particle.
    near: Vec<[f32; 3]>,
    /// Their volumes relative to the current particle's (several sizes only).
    volumes: Vec<f32>,
    /// Squared distances from the current particle to the slabs of half-blocks.
    gaps: Vec<f64>,
}

/// The kernel of the particle at `p`, of radius `ratio`·r, from `candidates` (its
/// neighbours within `R·ratio`,
/// itself and any others, in the canonical order), binned into the half-blocks
/// `around`; `near`, `volumes` and `gaps` are scratch. `SIZED`: particles of several sizes,
/// `candidates` with their radius ratios; each neighbour then weighs with its volume
/// relative to the particle's (`(ρ_j / ρ_i)³`), so that a coarse particle beside many
/// fine ones (or a fine one beside a few coarse ones) sees the fluid's distribution of
/// volume, not of particle count. Inlined into its one caller: when the
/// compiler left it out of line (after an unrelated change elsewhere), frame 25's run took
/// 2 % more instructions (callgrind), its kernel loop compiled worse.
#[inline(always)]
fn kernel_of<const SIZED: bool>(
    p: Vec3,
    ratio: f64,
    (candidates, candidate_ratios): (&[Vec3], &[f32]),
    around: &Around<'_>,
    (near, volumes, gaps): (&mut Vec<[f32; 3]>, &mut Vec<f32>, &mut Vec<f64>),
    field: &FieldOptions,
) -> ParticleKernel {
    let options = &field.anisotropy;
    let radius = field.influence_radius_world() * ratio;
    let r = field.particle_radius as f64 * ratio;
    let sphere = |centre: Vec3, neighbours: u32| ParticleKernel {
        centre,
        axes: [(options.kernel_radius as f64 * r) as f32; 3],
        directions: [Vec3::X, Vec3::Y, Vec3::Z],
        neighbours,
    };
    let x = p.as_dvec3();
    // The neighbours' offsets, compacted without branches into lanes (padding far
    // outside R, where the weight is 0), then summed lane by lane in f32 and the lanes
    // added in order: a fixed order of operations, whatever the compiler vectorizes.
    let radius32 = radius as f32;
    let r2 = radius32 * radius32;
    // Half-blocks (boxes of edge `around.edge` from `key·edge`) farther than R from p hold no
    // neighbour: a hair more than R, against the rounding of the half-blocks and of the
    // f32 distances below, so that no particle the test below would count is skipped.
    // The squared distance to a half-block is the sum of those to its three slabs.
    let u = x / around.edge;
    let reach2 = (radius * (1.0 + 1e-5) / around.edge).powi(2);
    gaps.clear();
    for k in 0..3 {
        gaps.extend((0..around.width as i32).map(|o| {
            let low = (around.low[k] + o) as f64;
            let (below, above) = (low - u[k], u[k] - (low + 1.0));
            let gap = if below > above { below } else { above };
            let gap = if gap > 0.0 { gap } else { 0.0 };
            gap * gap
        }));
    }
    let pad = [2.0 * radius32, 0.0, 0.0];
    if near.len() < candidates.len() + LANES {
        near.resize(candidates.len() + LANES, pad);
    }
    if SIZED && volumes.len() < candidates.len() + LANES {
        volumes.resize(candidates.len() + LANES, 0.0);
    }
    let inv_ratio = (1.0 / ratio) as f32;
    let (mut n, mut coincident) = (0, 0u32);
    for &([ox, oy, oz], a, b) in around.cells {
        if gaps[ox] + gaps[oy] + gaps[oz] > reach2 {
            continue;
        }
        for (k, q) in candidates[a as usize..b as usize].iter().enumerate() {
            let d = *q - p;
            let d2 = d.length_squared();
            near[n] = d.to_array();
            if SIZED {
                volumes[n] = (candidate_ratios[a as usize + k] * inv_ratio).powi(3);
            }
            n += (d2 < r2) as usize;
            coincident += (d2 == 0.0) as u32;
        }
    }
    // Within R, the particle itself and any coincident ones not counted.
    let neighbours = n as u32 - coincident;
    let padded = n.div_ceil(LANES) * LANES;
    near[n..padded].fill(pad);
    let inv_radius = 1.0 / radius32;
    let mut acc = [[0.0f32; LANES]; 10];
    for (c, chunk) in near[..padded].chunks_exact(LANES).enumerate() {
        for (l, d) in chunk.iter().enumerate() {
            let [dx, dy, dz] = *d;
            let s = (dx * dx + dy * dy + dz * dz).sqrt() * inv_radius;
            let w = (1.0 - s * s * s).max(0.0);
            let w = if SIZED { w * volumes[c * LANES + l] } else { w };
            let (wx, wy, wz) = (w * dx, w * dy, w * dz);
            acc[0][l] += w;
            acc[1][l] += wx;
            acc[2][l] += wy;
            acc[3][l] += wz;
            acc[4][l] += wx * dx;
            acc[5][l] += wx * dy;
            acc[6][l] += wx * dz;
            acc[7][l] += wy * dy;
            acc[8][l] += wy * dz;
            acc[9][l] += wz * dz;
        }
    }
    let total = acc.map(|lanes| lanes.iter().map(|&v| v as f64).sum::<f64>());
    let sw = total[0];
    let swd = DVec3::new(total[1], total[2], total[3]);
    let swdd = [total[4], total[5], total[6], total[7], total[8], total[9]];
    let mean = swd / sw;
    let mut shift = mean * options.centre_smoothing as f64;
    let max_shift = options.max_shift as f64 * r;
    if shift.length() > max_shift {
        shift *= max_shift / shift.length();
    }
    let centre = (x + shift).as_vec3();
    if neighbours < options.min_neighbours {
        return sphere(centre, neighbours);
    }
    let cov = DMat3::from_cols(
        DVec3::new(swdd[0], swdd[1], swdd[2]) / sw - mean * mean.x,
        DVec3::new(swdd[1], swdd[3], swdd[4]) / sw - mean * mean.y,
        DVec3::new(swdd[2], swdd[4], swdd[5]) / sw - mean * mean.z,
    );
    let (values, vectors) = symmetric_eigen(cov);
    let s1 = values[0];
    if !(s1 > 0.0 && s1.is_finite()) {
        return sphere(centre, neighbours);
    }
    let floor = s1 / options.max_stretch as f64;
    let s = [s1, values[1].max(floor), values[2].max(floor)];
    let scale = options.kernel_radius as f64 * r / (s[0] * s[1] * s[2]).cbrt();
    ParticleKernel {
        centre,
        axes: s.map(|v| (v * scale) as f32),
        directions: vectors.map(|v| v.as_vec3()),
        neighbours,
    }
}

#[cfg(test)]
mod tests;
