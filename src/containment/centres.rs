//! What measuring centres finds, and the tests a centre's measure goes through: how deep
//! each centre must lie ([`Need`], per particle when the particles have several sizes),
//! the shallow ones confirmed ([`settle`]) and pushed a little deeper than required, and
//! the watched ones that a later push could bring too close.

use super::measure::{Probe, SurfaceIndex};
use glam::{DVec3, Vec3};
use hashbrown::{HashMap, HashSet};
use rayon::prelude::*;

/// What measuring some centres found.
#[derive(Default)]
pub(super) struct Found {
    /// Centres with the surface near.
    pub(super) near: usize,
    /// Centres less than the depth under it.
    pub(super) shallow: Vec<Shallow>,
    /// Centres within r of that.
    pub(super) watched: Vec<Watched>,
    /// Centres whose probe found them too shallow, to be confirmed ([`settle`]).
    pub(super) pending: Vec<(u32, Vec3, Probe)>,
    /// Centres measured outside farther than [`Need::farthest_outside`]: not pushed.
    pub(super) folded: Vec<u32>,
}

impl Found {
    pub(super) fn extend(&mut self, other: Found) {
        self.near += other.near;
        self.shallow.extend(other.shallow);
        self.watched.extend(other.watched);
        self.pending.extend(other.pending);
        self.folded.extend(other.folded);
    }

    /// Watches centre `i` at `p` if its `probe` lies within `margin` of being too shallow
    /// (`depth`: its least depth).
    pub(super) fn watch(&mut self, i: u32, p: Vec3, probe: &Probe, depth: f64, margin: f64) {
        if probe.signed_distance > -(depth + margin) {
            self.watched.push(Watched {
                particle: i,
                position: p,
                parent: probe.control_triangle,
            });
        }
    }
}

/// How deep each centre must lie, world units: `depth` (and the tolerances of `r`) times
/// its radius ratio when the particles have several sizes; `margin` (the largest
/// particle's r) within which a centre is watched, the most a push may move the surface
/// without measuring again around it.
pub(super) struct Need<'a> {
    pub(super) depth: f64,
    pub(super) r: f64,
    pub(super) margin: f64,
    pub(super) ratios: Option<&'a [f32]>,
    /// Farthest a centre can really be outside, world units (infinite: no bound); one
    /// measured farther out was read through a fold ([`Found::folded`]).
    pub(super) farthest_outside: f64,
}

impl Need<'_> {
    /// The least depth of centre `i` and its radius, world units.
    #[inline]
    pub(super) fn of(&self, i: u32) -> (f64, f64) {
        match self.ratios {
            None => (self.depth, self.r),
            Some(ratios) => {
                let k = ratios[i as usize] as f64;
                (self.depth * k, self.r * k)
            }
        }
    }
}

/// Measures the centres `ps` (particle indices `is`) against `index`, in parallel,
/// skipping those at the positions of `isolated`: those shallower than their depth
/// ([`Need`]) are left to [`settle`], those within the margin of that are watched.
pub(super) fn measure_centres(
    index: &SurfaceIndex,
    isolated: &HashSet<[u32; 3]>,
    need: &Need<'_>,
    ps: &[Vec3],
    is: &[u32],
) -> Found {
    let measure = |ps: &[Vec3], is: &[u32]| {
        let mut found = Found::default();
        for (&p, &i) in ps.iter().zip(is) {
            let Some(probe) = index.probe(p.as_dvec3()) else {
                continue;
            };
            if !isolated.is_empty() && isolated.contains(&bits(p)) {
                continue;
            }
            found.near += 1;
            let (depth, r) = need.of(i);
            if shallow(&probe, depth, r) {
                found.pending.push((i, p, probe));
            } else {
                found.watch(i, p, &probe, depth, need.margin);
            }
        }
        found
    };
    let parts: Vec<Found> = ps
        .par_chunks(PROBE_CHUNK)
        .zip(is.par_chunks(PROBE_CHUNK))
        .map(|(ps, is)| measure(ps, is))
        .collect();
    let mut found = Found::default();
    for part in parts {
        found.extend(part);
    }
    found
}

/// Whether a centre at `probe` is to be pushed: less than `depth` under the surface.
pub(super) fn shallow(probe: &Probe, depth: f64, r: f64) -> bool {
    probe.signed_distance > -depth + TOLERANCE * r
}

/// Measures the centres of `found.pending` again over every triangle that may pass nearer
/// than their probes found (`SurfaceIndex::confirm`; once per slab, as it reads all of
/// the slab's triangles), and files them: too shallow they are pushed a little deeper than
/// their depth (so that rounding cannot leave a centre a hair short of it for another
/// round), within the margin of it they are watched.
pub(super) fn settle(index: &SurfaceIndex, found: &mut Found, need: &Need<'_>) {
    let pending = std::mem::take(&mut found.pending);
    let mut probes: Vec<(DVec3, Probe)> = pending
        .iter()
        .map(|&(_, p, probe)| (p.as_dvec3(), probe))
        .collect();
    index.confirm(&mut probes);
    for ((i, p, _), (_, probe)) in pending.into_iter().zip(probes) {
        let (depth, r) = need.of(i);
        found.watch(i, p, &probe, depth, need.margin);
        if probe.signed_distance > need.farthest_outside {
            found.folded.push(i);
        } else if shallow(&probe, depth, r) {
            let aim = depth + AIM_BEYOND * r;
            found.shallow.push(Shallow {
                particle: i,
                push: probe.normal * (probe.signed_distance + aim),
                signed_distance: probe.signed_distance,
                control_triangle: probe.control_triangle,
            });
        }
    }
}

/// How much deeper than required a push aims, multiples of r.
const AIM_BEYOND: f64 = 0.02;
/// How much shallower than required a centre may be before it is pushed, multiples of r
/// (float rounding of the pushed positions).
const TOLERANCE: f64 = 1e-3;

/// Centres per parallel task.
const PROBE_CHUNK: usize = 4096;

/// The exact bits of a position (isolated centres are matched by position).
pub(super) fn bits(p: Vec3) -> [u32; 3] {
    p.to_array().map(f32::to_bits)
}

/// A centre found too close to the surface.
pub(super) struct Shallow {
    pub(super) particle: u32,
    /// How its nearest surface point has to move, world units.
    pub(super) push: DVec3,
    /// Its signed distance to the surface, world units (positive outside).
    pub(super) signed_distance: f64,
    /// Control triangle under its nearest surface point.
    pub(super) control_triangle: u32,
}

impl Shallow {
    pub(super) fn outside(&self) -> bool {
        self.signed_distance > 0.0
    }
}

/// The centres counted as folded over the rounds (`ContainmentStats::folded`): their
/// side was read through a fold of the surface, and they are not pushed.
#[derive(Default)]
pub(super) struct Folds {
    folded: HashSet<u32>,
    /// Centres pushed while outside, and how far outside they were (where
    /// [`Need::farthest_outside`] is finite).
    pushed_from: HashMap<u32, f64>,
}

impl Folds {
    /// Takes a round's findings: the centres measured beyond the bound (`folded`), and,
    /// where the surface can only have moved so far off the centres, the shallow ones
    /// pushed before while outside and measured outside now no closer (taken out of
    /// `shallow`): the push moved the surface away from such a centre (it is inside), and
    /// pushing it again would raise the spike further.
    pub(super) fn take(&mut self, folded: Vec<u32>, shallow: &mut Vec<Shallow>, need: &Need<'_>) {
        self.folded.extend(folded);
        if !need.farthest_outside.is_finite() {
            return;
        }
        shallow.retain(|s| {
            let stuck = s.outside()
                && self
                    .pushed_from
                    .get(&s.particle)
                    .is_some_and(|&before| s.signed_distance > 0.5 * before);
            if stuck {
                self.folded.insert(s.particle);
            }
            !stuck
        });
        for s in shallow.iter().filter(|s| s.outside()) {
            self.pushed_from.insert(s.particle, s.signed_distance);
        }
    }

    /// How many centres are folded, those still `shallow` at the end not counted.
    pub(super) fn count(&mut self, shallow: &[Shallow]) -> usize {
        for s in shallow {
            self.folded.remove(&s.particle);
        }
        self.folded.len()
    }
}

/// A centre that a push could bring too close to the surface.
#[derive(Clone, Copy)]
pub(super) struct Watched {
    pub(super) particle: u32,
    pub(super) position: Vec3,
    /// Control triangle over which its nearest surface point lay.
    pub(super) parent: u32,
}
