//! The particle radius a frame's own spacing implies, and the check of a given radius
//! against it.
//!
//! SPH and FLIP solvers place particles of radius r at a rest spacing of 2r, so the bulk
//! of the fluid holds one particle per (2r)³. [`estimate_radius`] measures that number
//! density around up to [`SAMPLE`] particles spread evenly through the input, as an SPH
//! density: the sum of the smooth kernel `(1 − d²/h²)³` over the particles within
//! `h` = 2.5 lower-quartile nearest-neighbour distances, divided by the kernel's integral
//! `64πh³/315`. Surface particles see a partly empty ball, so the bulk's density is the
//! sample's 90th percentile, and r = ½·density^(−1/3). The count is steady where the
//! nearest-neighbour distance is not: SPH compresses the fluid and packs surface layers
//! and films closer, so half the median nearest-neighbour distance is 0.70–1.0 r on the
//! shipped frames and splashsurf's examples, where this estimate is within 8 % (0.3 % on
//! the dam break; the analytic sheet, two particles thick, 8.6 % high).
//! [`check_radius`] compares a given radius with it: refused when most of the fluid's
//! particles would be isolated (measured on the sample) or far above it, warned about
//! outside [`PLAUSIBLE`].
//!
//! Particles of several sizes carry their own radius in a point attribute:
//! [`RadiusAttribute`] says which, [`read_radii`] and [`radii_of`] read and check it.
//!
//! [`choose_radius`] is the policy every front end follows to pick a run's radius from
//! a given one, the radius attribute and the estimate.

use crate::error::{Error, Result};
use crate::io::particles::{
    read_particles, stream_positions, MappedXyz, ParticleFormat, ParticleSource,
};
use glam::Vec3;
use hashbrown::HashMap;
use rayon::prelude::*;
use std::path::Path;

mod attribute;
mod policy;
pub use attribute::{
    radii_of, read_radii, ParticleRadii, RadiusAttribute, HOUDINI_RADIUS, RADIUS_LIMITS,
    RADIUS_SPREAD,
};
pub use policy::{choose_radius, RadiusBasis, RadiusCheckOptions, RadiusChoice};

/// Particles sampled at most (evenly through the input).
pub const SAMPLE: usize = 4096;

/// The radius a frame implies (see the module's documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct RadiusEstimate {
    /// The estimated particle radius r, world units.
    pub radius: f32,
    /// Half the median distance from a sampled particle to its nearest neighbour.
    pub half_nearest: f32,
    /// Particles sampled.
    pub sample: usize,
    /// The distance from each sampled particle to its nearest neighbour, world units, in
    /// increasing order; only those found within the search's reach (several
    /// spacings), so loners far from the rest may be missing.
    pub nearest: Vec<f32>,
}

impl RadiusEstimate {
    /// Of the sampled particles with a neighbour within `body_reach` (world units: the
    /// kernel's reach at the radius the particles imply, so the fluid's body rather
    /// than its loners), the fraction with none within `reach`: the share of the fluid a
    /// run whose kernel reaches `reach` would mesh as separate spheres. 0 without such
    /// particles.
    pub fn isolated_fraction(&self, reach: f32, body_reach: f32) -> f32 {
        let body = self.nearest.partition_point(|&d| d <= body_reach);
        let kept = self.nearest.partition_point(|&d| d <= reach).min(body);
        if body == 0 {
            0.0
        } else {
            (body - kept) as f32 / body as f32
        }
    }
}

/// How a given radius compares with the one the particles imply (see [`check_radius`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RadiusCheck {
    /// Within [`PLAUSIBLE`] of the particles' radius.
    Plausible,
    /// Outside [`PLAUSIBLE`] but not refused: worth a warning. `isolated` is the share of
    /// the fluid's particles that would be meshed as separate spheres.
    Doubtful {
        /// The fraction of the fluid's particles without a neighbour within the kernel's
        /// reach ([`RadiusEstimate::isolated_fraction`]).
        isolated: f32,
    },
    /// A run would write a meaningless mesh: refused ([`crate::Error::ImplausibleRadius`]).
    Implausible(RadiusProblem),
}

/// What a run with an implausible radius would do.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RadiusProblem {
    /// More than [`ISOLATED`] of the fluid's particles would have no neighbour within the
    /// kernel's reach and be meshed each as a sphere of its own.
    Isolated {
        /// That fraction, measured on the estimate's sample.
        fraction: f32,
        /// The kernel's reach, multiples of the given radius (the influence radius R).
        influence_radius: f32,
    },
    /// Above [`BLOB`] × the particles' radius: the surface would stand several radii
    /// off the particles and fill the gaps between the fluid's parts, one blob.
    Blob,
    /// Below [`FINEST`] × the particles' radius: lattice cells (multiples of the given
    /// radius) so fine that each particle's kernel spans thousands of them.
    FineLattice,
}

impl std::fmt::Display for RadiusProblem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RadiusProblem::Isolated {
                fraction,
                influence_radius,
            } => write!(
                f,
                "{:.0}% of the fluid's particles would have no neighbour within the kernel's reach ({influence_radius} r) and be meshed each as a sphere of its own",
                100.0 * fraction
            ),
            RadiusProblem::FineLattice => write!(
                f,
                "below {FINEST} × the lattice's cells would be so fine that each particle's kernel spans thousands of them: a run would hang"
            ),
            RadiusProblem::Blob => write!(
                f,
                "above {BLOB} × the surface would stand several radii off the particles and fill the gaps between them: one blob"
            ),
        }
    }
}

/// What a given radius was compared with.
#[derive(Clone, Debug, PartialEq)]
pub enum RadiusSource {
    /// The particles' spacing ([`estimate_radius`]).
    Spacing {
        /// Particles sampled.
        sample: usize,
    },
    /// The median of the particles' radius attribute ([`ParticleRadii::median`]).
    Attribute {
        /// The attribute's name.
        name: String,
    },
}

impl std::fmt::Display for RadiusSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RadiusSource::Spacing { sample } => write!(
                f,
                "the particles' spacing implies (r is half the rest spacing; estimated from {sample} sampled particles)"
            ),
            RadiusSource::Attribute { name } => {
                write!(f, "median of the particles' radius attribute {name:?}")
            }
        }
    }
}

/// Ratios of a given radius to the particles' that are believed without a word.
pub const PLAUSIBLE: (f32, f32) = (0.5, 2.0);
/// Ratio of a given radius to the particles' above which it is refused
/// ([`RadiusProblem::Blob`]).
pub const BLOB: f32 = 4.0;
/// Fraction of the fluid's particles isolated above which a given radius is refused
/// ([`RadiusProblem::Isolated`]): most of them.
pub const ISOLATED: f32 = 0.5;
/// Ratio of a given radius to the particles' below which it is refused
/// ([`RadiusProblem::FineLattice`]).
pub const FINEST: f32 = 0.05;

/// Where `given` lies relative to `reference`, the radius the particles imply (both
/// world units, > 0), for a run whose kernel reaches `influence_radius` × r: refused when
/// more than [`ISOLATED`] of the fluid's particles would have no neighbour within the
/// kernel's reach ([`RadiusEstimate::isolated_fraction`] on `spacing`'s sample), below
/// [`FINEST`] × `reference` (a lattice so fine that a run hangs) or above [`BLOB`] ×
/// `reference`; else plausible within [`PLAUSIBLE`], doubtful outside. `spacing` is
/// `None` where each particle is meshed with its own radius (a radius attribute): its
/// reach, hence isolation, does not depend on `given` then, only the lattice does.
pub fn check_radius(
    given: f32,
    reference: f32,
    spacing: Option<&RadiusEstimate>,
    influence_radius: f32,
) -> RadiusCheck {
    let ratio = given / reference;
    let isolated = spacing.map_or(0.0, |e| {
        e.isolated_fraction(influence_radius * given, influence_radius * reference)
    });
    if isolated > ISOLATED {
        RadiusCheck::Implausible(RadiusProblem::Isolated {
            fraction: isolated,
            influence_radius,
        })
    } else if ratio < FINEST {
        RadiusCheck::Implausible(RadiusProblem::FineLattice)
    } else if ratio > BLOB {
        RadiusCheck::Implausible(RadiusProblem::Blob)
    } else if (PLAUSIBLE.0..=PLAUSIBLE.1).contains(&ratio) {
        RadiusCheck::Plausible
    } else {
        RadiusCheck::Doubtful { isolated }
    }
}

/// Kernel support, multiples of the lower-quartile nearest-neighbour distance: wide
/// enough that a lattice's shells blur (the kernel is smooth), narrow enough that a film
/// two particles thick still fills much of it.
const BALL: f32 = 2.5;
/// Quantile of the sampled densities taken as the bulk's.
const BULK_QUANTILE: f64 = 0.9;

/// The sampled particles binned into cubic cells, each cell listing the sampled particles
/// of the 27 cells around it (itself included, in sample order): a query looks up one
/// cell. (A query looking up the 27 cells instead took 27 hash look-ups per input
/// particle: 0.5 s a pass on 4M particles.)
struct SampleGrid {
    inv: f32,
    cells: HashMap<[i32; 3], Vec<u32>>,
}

impl SampleGrid {
    fn new(sample: &[Vec3], cell: f32) -> Self {
        let inv = 1.0 / cell;
        let mut cells: HashMap<[i32; 3], Vec<u32>> = HashMap::new();
        for (k, &p) in sample.iter().enumerate() {
            let c = key(p, inv);
            for dz in -1..=1 {
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        cells
                            .entry([c[0] + dx, c[1] + dy, c[2] + dz])
                            .or_default()
                            .push(k as u32);
                    }
                }
            }
        }
        SampleGrid { inv, cells }
    }

    /// Calls `f(k)` for every sampled particle `k` in the 27 cells around `p`.
    fn around(&self, p: Vec3, mut f: impl FnMut(usize)) {
        if let Some(ks) = self.cells.get(&key(p, self.inv)) {
            ks.iter().for_each(|&k| f(k as usize));
        }
    }
}

fn key(p: Vec3, inv: f32) -> [i32; 3] {
    let c = (p * inv).floor();
    [c.x as i32, c.y as i32, c.z as i32]
}

/// Input particles per part of a chunk in [`neighbours`].
const PART_PARTICLES: usize = 1 << 12;

/// Visits every position of the input in chunks, in the same order each time.
type Visit<'a> = dyn FnMut(&mut dyn FnMut(&[Vec3]) -> Result<()>) -> Result<()> + 'a;

/// Per sampled particle: its nearest distinct neighbour's distance (`f32::INFINITY` when
/// none lies within `cell`) and the sum of `(1 - d²/ball²)³` over the particles within
/// `ball` (itself included; `ball` 0 skips the sum). One pass over the input.
fn neighbours(
    visit: &mut Visit<'_>,
    sample: &[Vec3],
    cell: f32,
    ball: f32,
) -> Result<(Vec<f32>, Vec<f32>)> {
    let grid = SampleGrid::new(sample, cell);
    let (cell2, ball2) = (cell * cell, ball * ball);
    let empty = || (vec![f32::INFINITY; sample.len()], vec![0f32; sample.len()]);
    let (mut near, mut sum) = empty();
    // Fixed parts of the chunk, their sums added in part order: the same sums whatever
    // the thread count (a parallel fold groups the parts as the threads happen to split
    // them, and the bulk density, hence an estimated r, could differ in its last bits).
    visit(&mut |chunk| {
        let parts: Vec<(Vec<f32>, Vec<f32>)> = chunk
            .par_chunks(PART_PARTICLES)
            .map(|part| {
                let (mut near, mut sum) = empty();
                for &p in part {
                    grid.around(p, |k| {
                        let d2 = p.distance_squared(sample[k]);
                        if d2 > 0.0 && d2 <= cell2 {
                            near[k] = near[k].min(d2);
                        }
                        if d2 < ball2 {
                            sum[k] += (1.0 - d2 / ball2).powi(3);
                        }
                    });
                }
                (near, sum)
            })
            .collect();
        for (n, w) in parts {
            near.iter_mut().zip(n).for_each(|(x, y)| *x = x.min(y));
            sum.iter_mut().zip(w).for_each(|(x, y)| *x += y);
        }
        Ok(())
    })?;
    Ok((near.into_iter().map(f32::sqrt).collect(), sum))
}

/// Up to [`SAMPLE`] positions spread evenly through the input: every `stride`-th, the
/// stride doubling whenever the sample fills (so the count need not be known).
#[derive(Default)]
struct Sampler {
    sample: Vec<Vec3>,
    stride: usize,
    seen: usize,
}

impl Sampler {
    fn add(&mut self, chunk: &[Vec3]) {
        self.stride = self.stride.max(1);
        for &p in chunk {
            if self.seen % self.stride == 0 {
                if self.sample.len() == SAMPLE {
                    self.sample = self.sample.iter().copied().step_by(2).collect();
                    self.stride *= 2;
                }
                if self.seen % self.stride == 0 {
                    self.sample.push(p);
                }
            }
            self.seen += 1;
        }
    }
}

/// Rings of cells [`nearest_among`] searches around a sampled particle before it
/// compares it with every other one.
const MAX_RINGS: i32 = 3;

/// The squared distance from each sampled particle to the nearest other one at a
/// distinct place (`f32::INFINITY` when none): the least of the same `distance_squared`
/// as a comparison with every other particle gives, found in rings of cells around it
/// (cells holding about 8 particles of the sample's bounding box; comparing every pair
/// took 46–92 ms for 4096 particles, a quarter of a small frame's run).
fn nearest_among(sample: &[Vec3]) -> Vec<f32> {
    let brute = |p: Vec3| {
        sample
            .iter()
            .map(|q| p.distance_squared(*q))
            .filter(|&d2| d2 > 0.0)
            .fold(f32::INFINITY, f32::min)
    };
    let (lo, hi) = sample
        .iter()
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &p| {
            (lo.min(p), hi.max(p))
        });
    let extent = hi - lo;
    let floor = extent.max_element() * 1e-3;
    let volume = extent.max(Vec3::splat(floor));
    let cell = (8.0 * volume.x * volume.y * volume.z / sample.len() as f32).cbrt();
    if !(cell.is_finite() && cell > 0.0) {
        return sample.par_iter().map(|&p| brute(p)).collect();
    }
    let inv = 1.0 / cell;
    let mut cells: HashMap<[i32; 3], Vec<u32>> = HashMap::new();
    for (k, &p) in sample.iter().enumerate() {
        cells.entry(key(p, inv)).or_default().push(k as u32);
    }
    sample
        .par_iter()
        .map(|&p| {
            let c = key(p, inv);
            let mut best = f32::INFINITY;
            for ring in 0..=MAX_RINGS {
                for dz in -ring..=ring {
                    for dy in -ring..=ring {
                        for dx in -ring..=ring {
                            if dx.abs().max(dy.abs()).max(dz.abs()) != ring {
                                continue;
                            }
                            let Some(ks) = cells.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) else {
                                continue;
                            };
                            for &k in ks {
                                let d2 = p.distance_squared(sample[k as usize]);
                                if d2 > 0.0 && d2 < best {
                                    best = d2;
                                }
                            }
                        }
                    }
                }
                // Every particle outside the rings searched lies at least `ring` cells
                // away (less a hair for the rounding of the cell keys).
                let clear = (ring as f32 - 0.01).max(0.0) * cell;
                if best <= clear * clear {
                    return best;
                }
            }
            brute(p)
        })
        .collect()
}

/// The value at quantile `q` of `values` (sorted in place; not empty).
fn quantile(values: &mut [f32], q: f64) -> f32 {
    values.sort_by(f32::total_cmp);
    values[((values.len() - 1) as f64 * q).round() as usize]
}

/// Estimates the particle radius of `positions` from up to [`SAMPLE`] particles spread
/// evenly through them (see the module's documentation). Deterministic. An
/// [`Error::InvalidOption`] on `particle_radius` when the positions give no spacing to
/// measure (fewer than two distinct ones).
pub fn estimate_radius(positions: &[Vec3]) -> Result<RadiusEstimate> {
    estimate_radius_of(&positions)
}

/// [`estimate_radius`] of the particles of a source: three passes over its chunks,
/// memory of the sample and one chunk.
pub fn estimate_radius_of(source: &dyn ParticleSource) -> Result<RadiusEstimate> {
    estimate(&mut |f| source.visit_chunks(&mut |chunk| f(chunk.positions)))
}

/// [`estimate_radius`] of the particles of a file, streamed from disk where the format
/// streams ([`stream_positions`]; `.xyz` memory-mapped), else read whole.
pub fn estimate_radius_of_file(
    path: &Path,
    format: Option<ParticleFormat>,
) -> Result<RadiusEstimate> {
    let estimate = estimate_file(path, format);
    // The passes' chunk buffers are freed; the run that follows must not count them.
    crate::allocator::release_freed_memory();
    estimate
}

fn estimate_file(path: &Path, format: Option<ParticleFormat>) -> Result<RadiusEstimate> {
    let format = match format {
        Some(f) => f,
        None => ParticleFormat::from_path(path)?,
    };
    if format == ParticleFormat::Xyz {
        return estimate_radius_of(&MappedXyz::open(path)?);
    }
    let mut visit = |f: &mut dyn FnMut(&[Vec3]) -> Result<()>| {
        stream_positions(path, Some(format), f).map(|_| ())
    };
    let mut sampler = Sampler::default();
    let streams = stream_positions(path, Some(format), &mut |chunk| {
        sampler.add(chunk);
        Ok(())
    })?;
    if streams.is_none() {
        return estimate_radius(&read_particles(path, Some(format))?.positions);
    }
    from_sample(sampler, &mut visit)
}

fn estimate(visit: &mut Visit<'_>) -> Result<RadiusEstimate> {
    let mut sampler = Sampler::default();
    visit(&mut |chunk| {
        sampler.add(chunk);
        Ok(())
    })?;
    from_sample(sampler, visit)
}

/// The estimate from the sample, with two more passes over the input.
fn from_sample(sampler: Sampler, visit: &mut Visit<'_>) -> Result<RadiusEstimate> {
    let Sampler { sample, seen, .. } = sampler;
    let s = sample.len();
    let none = || Error::InvalidOption {
        option: "particle_radius",
        message: format!(
            "cannot be estimated from {seen} particles without two at distinct places; give it"
        ),
    };
    if s < 2 {
        return Err(none());
    }
    // Every particle's nearest neighbour lies no farther than the nearest other sampled
    // particle: within the median of those distances for at least half the sample.
    let mut among: Vec<f32> = nearest_among(&sample)
        .into_iter()
        .filter(|d2| d2.is_finite())
        .map(f32::sqrt)
        .collect();
    if among.is_empty() {
        return Err(none());
    }
    let cell = quantile(&mut among, 0.75);
    let (near, _) = neighbours(visit, &sample, cell, 0.0)?;
    let mut found: Vec<f32> = near.iter().copied().filter(|d| d.is_finite()).collect();
    if found.is_empty() {
        return Err(none());
    }
    let ball = BALL * quantile(&mut found, 0.25);
    let (_, sum) = neighbours(visit, &sample, ball, ball)?;
    // The kernel integrates to 64π/315 · ball³.
    let volume = 64.0 * std::f32::consts::PI / 315.0 * ball.powi(3);
    let density: Vec<f32> = sum.iter().map(|&w| w / volume).collect();
    let bulk = quantile(&mut density.clone(), BULK_QUANTILE);
    let mut dense: Vec<f32> = near
        .iter()
        .zip(&density)
        .filter(|&(d, &rho)| d.is_finite() && rho >= 0.5 * bulk)
        .map(|(&d, _)| d)
        .collect();
    if dense.is_empty() {
        dense = found.clone();
    }
    let half_nearest = 0.5 * quantile(&mut dense, 0.5);
    let radius = 0.5 / bulk.cbrt();
    let mut nearest = found;
    nearest.sort_by(f32::total_cmp);
    Ok(RadiusEstimate {
        radius,
        half_nearest,
        sample: s,
        nearest,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every pair compared: the reference of [`nearest_among`].
    fn brute(sample: &[Vec3]) -> Vec<f32> {
        sample
            .iter()
            .map(|&p| {
                sample
                    .iter()
                    .map(|q| p.distance_squared(*q))
                    .filter(|&d2| d2 > 0.0)
                    .fold(f32::INFINITY, f32::min)
            })
            .collect()
    }

    /// The rings give what comparing every pair gives, bit for bit: a jittered block with
    /// a far cluster and loners (whose nearest lies beyond the rings), a flat sheet (a
    /// bounding box without depth), coincident particles, and one particle alone.
    #[test]
    fn nearest_among_the_sample_is_the_nearest_of_all_pairs() {
        let mut rng = crate::test_rng::TestRng::new(7);
        let mut jitter = || Vec3::new(rng.unit_f32(), rng.unit_f32(), rng.unit_f32()) - 0.5;
        let mut block = Vec::new();
        for z in 0..12 {
            for y in 0..12 {
                for x in 0..12 {
                    block.push(Vec3::new(x as f32, y as f32, z as f32) * 0.02 + jitter() * 0.01);
                }
            }
        }
        block.extend((0..50).map(|k| Vec3::splat(40.0) + Vec3::X * k as f32 * 0.02));
        block.extend([Vec3::new(-30.0, 5.0, 0.0), Vec3::new(9.0, -70.0, 3.0)]);
        let sheet: Vec<Vec3> = (0..900)
            .map(|k| {
                Vec3::new((k % 30) as f32, (k / 30) as f32, 0.0) * 0.5
                    + jitter() * Vec3::new(0.1, 0.1, 0.0)
            })
            .collect();
        let coincident = vec![Vec3::ONE, Vec3::ONE, Vec3::new(1.0, 1.0, 1.5), Vec3::ONE];
        for sample in [block, sheet, coincident, vec![Vec3::ZERO]] {
            let found = nearest_among(&sample);
            let reference = brute(&sample);
            assert_eq!(found.len(), reference.len());
            for (a, b) in found.iter().zip(&reference) {
                assert_eq!(a.to_bits(), b.to_bits(), "{a} against {b}");
            }
        }
    }

    /// The estimate does not depend on the thread count (the sums of the density pass
    /// are added in a fixed order).
    #[test]
    fn the_estimate_is_the_same_on_any_number_of_threads() {
        let mut rng = crate::test_rng::TestRng::new(9);
        let positions: Vec<Vec3> = (0..60_000)
            .map(|k| {
                let c = Vec3::new((k % 40) as f32, (k / 40 % 40) as f32, (k / 1600) as f32);
                c * 0.02 + (Vec3::new(rng.unit_f32(), rng.unit_f32(), rng.unit_f32()) - 0.5) * 0.004
            })
            .collect();
        let on = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| estimate_radius(&positions).unwrap())
        };
        let one = on(1);
        assert!((one.radius / 0.01 - 1.0).abs() < 0.1, "{one:?}");
        for threads in [2, 3, 8] {
            assert_eq!(on(threads), one, "{threads} threads");
        }
    }
}
