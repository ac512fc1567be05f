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
//! [`check_radius`] compares a given radius with it.
//!
//! Particles of several sizes carry their own radius in a point attribute:
//! [`RadiusAttribute`] says which, [`read_radii`] and [`radii_of`] read and check it.

use crate::error::{Error, Result};
use crate::io::particles::{
    read_particles, stream_positions, MappedXyz, ParticleFormat, ParticleSource,
};
use glam::Vec3;
use hashbrown::HashMap;
use rayon::prelude::*;
use std::path::Path;

mod attribute;
pub use attribute::{radii_of, read_radii, ParticleRadii, RadiusAttribute, HOUDINI_RADIUS};

/// Particles sampled at most (evenly through the input).
pub const SAMPLE: usize = 4096;

/// The radius a frame implies (see the module's documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RadiusEstimate {
    /// The estimated particle radius r, world units.
    pub radius: f32,
    /// Half the median distance from a sampled particle to its nearest neighbour.
    pub half_nearest: f32,
    /// Particles sampled.
    pub sample: usize,
}

/// How a given radius compares with the estimate (see [`check_radius`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RadiusCheck {
    /// Within 0.25×–4× of the estimate.
    Plausible,
    /// Outside 0.25×–4× of the estimate but within 0.05×–20×: worth a warning.
    Doubtful,
    /// Outside 0.05×–20× of the estimate: a run would hang or write an absurd mesh.
    Implausible,
}

/// Ratios of a given radius to the estimate that are believed without a word.
pub const PLAUSIBLE: (f32, f32) = (0.25, 4.0);
/// Ratios outside which a given radius is refused.
pub const POSSIBLE: (f32, f32) = (0.05, 20.0);

/// Where `given` lies relative to `estimate` (both world units, > 0).
pub fn check_radius(given: f32, estimate: f32) -> RadiusCheck {
    let ratio = given / estimate;
    if (PLAUSIBLE.0..=PLAUSIBLE.1).contains(&ratio) {
        RadiusCheck::Plausible
    } else if (POSSIBLE.0..=POSSIBLE.1).contains(&ratio) {
        RadiusCheck::Doubtful
    } else {
        RadiusCheck::Implausible
    }
}

/// Checks radius `given` against the estimate for the particles of `path`: `Ok` with
/// the verdict when it is at most [`RadiusCheck::Doubtful`], else an
/// [`Error::ImplausibleRadius`] naming both values.
pub fn verify_radius(path: &Path, given: f32, estimate: &RadiusEstimate) -> Result<RadiusCheck> {
    match check_radius(given, estimate.radius) {
        RadiusCheck::Implausible => Err(Error::ImplausibleRadius {
            path: path.to_path_buf(),
            given,
            estimate: estimate.radius,
            sample: estimate.sample,
        }),
        verdict => Ok(verdict),
    }
}

/// Kernel support, multiples of the lower-quartile nearest-neighbour distance: wide
/// enough that a lattice's shells blur (the kernel is smooth), narrow enough that a film
/// two particles thick still fills much of it.
const BALL: f32 = 2.5;
/// Quantile of the sampled densities taken as the bulk's.
const BULK_QUANTILE: f64 = 0.9;

/// The sampled particles binned into cubic cells: a query visits the 27 cells around a
/// point.
struct SampleGrid {
    inv: f32,
    cells: HashMap<[i32; 3], Vec<u32>>,
}

impl SampleGrid {
    fn new(sample: &[Vec3], cell: f32) -> Self {
        let inv = 1.0 / cell;
        let mut cells: HashMap<[i32; 3], Vec<u32>> = HashMap::new();
        for (k, &p) in sample.iter().enumerate() {
            cells.entry(key(p, inv)).or_default().push(k as u32);
        }
        SampleGrid { inv, cells }
    }

    /// Calls `f(k)` for every sampled particle `k` in the 27 cells around `p`.
    fn around(&self, p: Vec3, mut f: impl FnMut(usize)) {
        let c = key(p, self.inv);
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    if let Some(ks) = self.cells.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                        ks.iter().for_each(|&k| f(k as usize));
                    }
                }
            }
        }
    }
}

fn key(p: Vec3, inv: f32) -> [i32; 3] {
    let c = (p * inv).floor();
    [c.x as i32, c.y as i32, c.z as i32]
}

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
    visit(&mut |chunk| {
        let (n, w) = chunk
            .par_chunks(1 << 12)
            .fold(empty, |(mut near, mut sum), part| {
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
            .reduce(empty, |(mut a, mut b), (c, d)| {
                a.iter_mut().zip(c).for_each(|(x, y)| *x = x.min(y));
                b.iter_mut().zip(d).for_each(|(x, y)| *x += y);
                (a, b)
            });
        near.iter_mut().zip(n).for_each(|(x, y)| *x = x.min(y));
        sum.iter_mut().zip(w).for_each(|(x, y)| *x += y);
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
    let mut among: Vec<f32> = (0..s)
        .into_par_iter()
        .map(|k| {
            let p = sample[k];
            sample
                .iter()
                .map(|q| p.distance_squared(*q))
                .filter(|&d2| d2 > 0.0)
                .fold(f32::INFINITY, f32::min)
        })
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
        dense = found;
    }
    let half_nearest = 0.5 * quantile(&mut dense, 0.5);
    let radius = 0.5 / bulk.cbrt();
    Ok(RadiusEstimate {
        radius,
        half_nearest,
        sample: s,
    })
}
