//! Edge collapses on the decimation state (of the candidates `candidate.rs` declares):
//! the raw view of the state that the walks share, and the tests a collapse must pass
//! (link condition, normals, triangle quality) before it is made. See the module docs of
//! [`super`] for the rules.

use super::candidate::{Candidate, Mark};
use super::placement::placement_of;
use super::quadric::Quadric;
use super::tri_list::TriList;
use super::State;
use glam::{DVec3, Vec3};

/// The rules of one attempt: the pass (a vertex moves at most once per pass), the error
/// bound (unit-box units) and the clock a collapse stamps its one-ring with.
#[derive(Clone, Copy)]
pub(super) struct Attempt {
    pub(super) pass: u32,
    pub(super) max_cost_error: Option<f64>,
    pub(super) clock: u32,
}

/// What [`View::try_collapse`] did.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum Outcome {
    Collapsed,
    /// Refused by the link condition, the valence rule or the geometry tests: refused
    /// again as long as no collapse stamps `u` or `v` (see [`View::collapse`]).
    Refused,
    /// Not tried: an end is gone or moved in this pass, or the cost is over the bound.
    Passed,
}

const MIN_NORMAL_DOT: f64 = 0.5;
const MIN_NORMAL_DOT_2: f64 = MIN_NORMAL_DOT * MIN_NORMAL_DOT;
/// Triangles of a vertex whose corners the link test gathers on the stack.
const LINK_TRIANGLES: usize = 16;
const MIN_QUALITY: f64 = 0.02;

/// Counters of one walk.
#[derive(Default)]
pub(super) struct WalkTally {
    pub(super) collapses: usize,
    pub(super) removed_triangles: usize,
    pub(super) refused_topology: usize,
    pub(super) refused_geometry: usize,
    pub(super) max_error: f64,
}

/// Raw access to the state's arrays, shared by the chunks of a parallel walk.
///
/// Every method is `unsafe`: the caller guarantees that no other thread reads or writes
/// the elements it touches, which are those of the closed one-rings of the edge's two
/// vertices (their positions, quadrics, vertex lists, flags and incident triangles).
#[derive(Clone, Copy)]
pub(super) struct View {
    pos: *mut DVec3,
    quadric: *mut Quadric,
    tris: *mut [u32; 3],
    reference_normal: *const Vec3,
    tri_alive: *mut bool,
    vert_tris: *mut TriList,
    alive: *mut bool,
    touched: *mut u32,
    stamp: *mut u32,
    owner: *const u32,
}

// SAFETY: a `View` is only dereferenced under the ownership discipline described on it.
unsafe impl Send for View {}
unsafe impl Sync for View {}

impl View {
    /// Raw access to `state`'s arrays.
    pub(super) fn new(state: &mut State) -> View {
        View {
            pos: state.pos.as_mut_ptr(),
            quadric: state.quadric.as_mut_ptr(),
            tris: state.tris.as_mut_ptr(),
            reference_normal: state.reference_normal.as_ptr(),
            tri_alive: state.tri_alive.as_mut_ptr(),
            vert_tris: state.vert_tris.as_mut_ptr(),
            alive: state.alive.as_mut_ptr(),
            touched: state.touched.as_mut_ptr(),
            stamp: state.stamp.as_mut_ptr(),
            owner: state.owner.as_ptr(),
        }
    }

    unsafe fn pos(&self, v: u32) -> DVec3 {
        *self.pos.add(v as usize)
    }
    unsafe fn tri(&self, t: u32) -> [u32; 3] {
        *self.tris.add(t as usize)
    }
    unsafe fn vert_tris(&self, v: u32) -> &TriList {
        &*self.vert_tris.add(v as usize)
    }
    #[allow(clippy::mut_from_ref)]
    unsafe fn vert_tris_mut(&self, v: u32) -> &mut TriList {
        &mut *self.vert_tris.add(v as usize)
    }
    unsafe fn alive(&self, v: u32) -> bool {
        *self.alive.add(v as usize)
    }
    unsafe fn touched(&self, v: u32) -> u32 {
        *self.touched.add(v as usize)
    }
    unsafe fn owner(&self, v: u32) -> u32 {
        *self.owner.add(v as usize)
    }

    /// Whether a collapse refused at `clock` would be refused again: no collapse since
    /// has stamped either end. A collapse changes the positions, triangles and valences of
    /// the closed one-ring of the merged vertex alone, and stamps it all; the test of an
    /// edge reads its ends' one-rings and its opposite vertices' valences, and an
    /// unstamped opposite vertex can only have lost triangles, which never turns a refusal
    /// into a collapse.
    pub(super) unsafe fn refused_since(&self, c: &Candidate) -> bool {
        c.mark != Mark::NONE
            && c.mark != Mark::DECIDED
            && *self.stamp.add(c.u as usize) <= c.mark
            && *self.stamp.add(c.v as usize) <= c.mark
    }

    /// Walks one chunk's candidates, taking at most `share` collapses whose closed
    /// one-rings the chunk owns; marks every candidate it decided.
    pub(super) unsafe fn walk_chunk(
        &self,
        chunk: u32,
        candidates: &mut [Candidate],
        cost_limit: f64,
        share: usize,
        attempt: Attempt,
    ) -> WalkTally {
        let mut tally = WalkTally::default();
        for c in candidates.iter_mut() {
            if tally.collapses >= share {
                break;
            }
            if c.cost > cost_limit || self.refused_since(c) || !self.owns_rings(chunk, c.u, c.v) {
                continue;
            }
            let candidate = *c;
            c.mark = Mark::DECIDED;
            self.try_collapse(&candidate, attempt, &mut tally);
        }
        tally
    }

    /// Whether `chunk` owns `u`, `v` and every vertex of their triangles.
    unsafe fn owns_rings(&self, chunk: u32, u: u32, v: u32) -> bool {
        if self.owner(u) != chunk || self.owner(v) != chunk {
            return false;
        }
        [u, v].iter().all(|&x| {
            self.vert_tris(x)
                .iter()
                .all(|&t| self.tri(t).iter().all(|&w| self.owner(w) == chunk))
        })
    }

    /// Collapses the candidate if it is still valid and allowed, stamping the merged
    /// vertex's closed one-ring with the attempt's clock; counts what happened.
    pub(super) unsafe fn try_collapse(
        &self,
        c: &Candidate,
        attempt: Attempt,
        tally: &mut WalkTally,
    ) -> Outcome {
        let Attempt {
            pass,
            max_cost_error,
            clock,
        } = attempt;
        let (u, v) = (c.u, c.v);
        if !self.alive(u) || !self.alive(v) || self.touched(u) == pass || self.touched(v) == pass {
            return Outcome::Passed;
        }
        let error = c.cost.sqrt();
        if max_cost_error.is_some_and(|m| error > m) {
            return Outcome::Passed;
        }
        if !self.link_ok(u, v) {
            tally.refused_topology += 1;
            return Outcome::Refused;
        }
        // Neither end has moved since the candidate was costed: the placement is the one
        // its cost was measured at.
        let (target_point, _) = placement_of(
            self.pos(u),
            self.pos(v),
            &*self.quadric.add(u as usize),
            &*self.quadric.add(v as usize),
        );
        if !self.geometry_ok(u, v, target_point) {
            tally.refused_geometry += 1;
            return Outcome::Refused;
        }
        tally.removed_triangles += self.collapse(u, v, target_point);
        *self.touched.add(u as usize) = pass;
        *self.touched.add(v as usize) = pass;
        for &t in self.vert_tris(u) {
            for &w in &self.tri(t) {
                *self.stamp.add(w as usize) = clock;
            }
        }
        tally.collapses += 1;
        tally.max_error = tally.max_error.max(error);
        Outcome::Collapsed
    }

    unsafe fn is_neighbour(&self, a: u32, b: u32) -> bool {
        self.vert_tris(a).iter().any(|&t| self.tri(t).contains(&b))
    }

    /// The link condition: the common neighbours of `u` and `v` are exactly the opposite
    /// vertices of the two triangles on the edge, each of valence above 3.
    unsafe fn link_ok(&self, u: u32, v: u32) -> bool {
        let mut opposite = [u32::MAX; 2];
        let mut shared = 0;
        for &t in self.vert_tris(u) {
            let tri = self.tri(t);
            if tri.contains(&v) {
                if shared == 2 {
                    return false;
                }
                opposite[shared] = *tri
                    .iter()
                    .find(|&&w| w != u && w != v)
                    .expect("a third vertex");
                shared += 1;
            }
        }
        if shared != 2 || opposite[0] == opposite[1] {
            return false;
        }
        // The corners of v's triangles, gathered once (each of v's neighbours is among
        // them), unless v has too many triangles for the buffer.
        let mut around_v = [u32::MAX; 3 * LINK_TRIANGLES];
        let v_tris = self.vert_tris(v);
        let gathered = v_tris.len() <= LINK_TRIANGLES;
        if gathered {
            for (corners, &t) in around_v.chunks_exact_mut(3).zip(v_tris.iter()) {
                corners.copy_from_slice(&self.tri(t));
            }
        }
        let neighbour_of_v = |w: u32| {
            if gathered {
                around_v.contains(&w)
            } else {
                self.is_neighbour(v, w)
            }
        };
        for &t in self.vert_tris(u) {
            for &w in &self.tri(t) {
                if w != u && w != v && !opposite.contains(&w) && neighbour_of_v(w) {
                    return false;
                }
            }
        }
        opposite.iter().all(|&w| self.vert_tris(w).len() > 3)
    }

    /// No surviving triangle around `u` or `v` flips or degenerates when both move to `p`.
    unsafe fn geometry_ok(&self, u: u32, v: u32, p: DVec3) -> bool {
        for &x in &[u, v] {
            for &t in self.vert_tris(x) {
                let tri = self.tri(t);
                if tri.contains(&u) && tri.contains(&v) {
                    continue;
                }
                let old = tri.map(|w| self.pos(w));
                let new = tri.map(|w| if w == u || w == v { p } else { self.pos(w) });
                // Squared lengths throughout: `a·b < k·|a|·|b|` (k > 0) is
                // `a·b < 0 or (a·b)² < k²·|a|²·|b|²`, with no square root.
                let n0 = (old[1] - old[0]).cross(old[2] - old[0]);
                let n1 = (new[1] - new[0]).cross(new[2] - new[0]);
                let (s0, s1) = (n0.length_squared(), n1.length_squared());
                if s1 == 0.0 {
                    return false;
                }
                let turn = n0.dot(n1);
                if s0 > 0.0 && (turn < 0.0 || turn * turn < MIN_NORMAL_DOT_2 * s0 * s1) {
                    return false;
                }
                // The reference normal is a unit vector (or zero: then always refused).
                let reference = (*self.reference_normal.add(t as usize)).as_dvec3();
                let drift = n1.dot(reference);
                if drift < 0.0 || drift * drift < MIN_NORMAL_DOT_2 * s1 {
                    return false;
                }
                // Quality 4√3·area / Σl² = 2√3·|n1| / Σl², below MIN_QUALITY.
                let edges2 = (new[1] - new[0]).length_squared()
                    + (new[2] - new[1]).length_squared()
                    + (new[0] - new[2]).length_squared();
                let bound = MIN_QUALITY / (2.0 * 3f64.sqrt()) * edges2;
                if s1 < bound * bound {
                    return false;
                }
            }
        }
        true
    }

    /// Collapses `v` into `u` at `p`; returns the number of triangles removed.
    unsafe fn collapse(&self, u: u32, v: u32, p: DVec3) -> usize {
        let mut removed = 0;
        let v_tris = std::mem::take(self.vert_tris_mut(v));
        for &t in &v_tris {
            let tri = &mut *self.tris.add(t as usize);
            if tri.contains(&u) {
                *self.tri_alive.add(t as usize) = false;
                removed += 1;
                let tri = *tri;
                for &w in &tri {
                    if w != v {
                        self.vert_tris_mut(w).retain(|&x| x != t);
                    }
                }
            } else {
                for w in tri.iter_mut() {
                    if *w == v {
                        *w = u;
                    }
                }
                self.vert_tris_mut(u).push(t);
            }
        }
        *self.pos.add(u as usize) = p;
        let q = *self.quadric.add(v as usize);
        *self.quadric.add(u as usize) += q;
        *self.alive.add(v as usize) = false;
        removed
    }
}
