//! Where an edge collapse puts the merged vertex, and what it costs: the quadric optimum
//! when `A` is well conditioned and the optimum lies within one edge length of the edge's
//! midpoint, otherwise the quadric minimum on the segment; the cost is `Q(p)` divided by
//! the area the quadric stands for.
//!
//! [`place_candidates`] costs candidates two at a time, one per lane of an SSE2 register
//! (on x86-64; elsewhere one by one): the same IEEE operations in the same order as the
//! scalar [`placement`], with both branches computed and the right one selected per lane,
//! so its results are bit for bit those of the scalar code (a unit test checks it). Costing
//! every live edge of every pass is about a quarter of the decimation; the optimum's
//! Cramer rule and the segment minimum were half of that.

use super::candidate::Candidate;
use super::quadric::Quadric;
use glam::DVec3;

/// Where the collapse of edge `(u, v)` puts the merged vertex, and its quadric cost `Q(p)`
/// (not divided by the area). The scalar reference: the lanes compute the same.
#[cfg_attr(all(target_arch = "x86_64", not(test)), allow(dead_code))]
pub(super) fn placement(pos: &[DVec3], quadric: &[Quadric], u: u32, v: u32) -> (DVec3, f64) {
    placement_of(
        pos[u as usize],
        pos[v as usize],
        &quadric[u as usize],
        &quadric[v as usize],
    )
}

/// [`placement`] of the edge with ends at `pu`, `pv` and quadrics `qu`, `qv`: what a
/// collapse recomputes when it is made (the candidates keep their cost only).
pub(super) fn placement_of(pu: DVec3, pv: DVec3, qu: &Quadric, qv: &Quadric) -> (DVec3, f64) {
    let q = *qu + *qv;
    let mid = (pu + pv) * 0.5;
    let target = match q.optimum() {
        Some(p) if (p - mid).length() <= (pv - pu).length() => p,
        _ => q.segment_minimum(pu, pv),
    };
    (target, q.evaluate(target))
}

/// The candidate of edge `(u, v)`, costed by [`placement`] and ranked by its squared RMS
/// distance, `Q(p) / area` (0 for a quadric without area).
#[cfg_attr(all(target_arch = "x86_64", not(test)), allow(dead_code))]
pub(super) fn candidate(pos: &[DVec3], quadric: &[Quadric], u: u32, v: u32) -> Candidate {
    let (_, cost) = placement(pos, quadric, u, v);
    let weight = quadric[u as usize].weight + quadric[v as usize].weight;
    Candidate {
        cost: if weight > 0.0 { cost / weight } else { 0.0 },
        ..Candidate::edge(0, u, v)
    }
}

/// The cost of every candidate (its `u`, `v` set), exactly as [`candidate`] would one by
/// one, and each placement's target, exactly as [`placement`] would.
#[cfg(test)]
pub(super) fn place_candidates(
    pos: &[DVec3],
    quadric: &[Quadric],
    candidates: &mut [Candidate],
) -> Vec<DVec3> {
    let mut targets = vec![DVec3::NAN; candidates.len()];
    #[cfg(target_arch = "x86_64")]
    {
        let all: Vec<u32> = (0..candidates.len() as u32).collect();
        lanes::place_at(pos, quadric, candidates, &all, |i, target| {
            targets[i] = target
        });
    }
    #[cfg(not(target_arch = "x86_64"))]
    for (c, t) in candidates.iter_mut().zip(&mut targets) {
        c.cost = candidate(pos, quadric, c.u, c.v).cost;
        *t = placement(pos, quadric, c.u, c.v).0;
    }
    targets
}

/// [`place_candidates`] on the candidates at the indices `at` only.
pub(super) fn place_candidates_at(
    pos: &[DVec3],
    quadric: &[Quadric],
    candidates: &mut [Candidate],
    at: &[u32],
) {
    #[cfg(target_arch = "x86_64")]
    lanes::place_at(pos, quadric, candidates, at, |_, _| {});
    #[cfg(not(target_arch = "x86_64"))]
    for &i in at {
        let c = &mut candidates[i as usize];
        c.cost = candidate(pos, quadric, c.u, c.v).cost;
    }
}

/// The lanes: SSE2 registers of two `f64` (SSE2 is part of x86-64, so no run-time
/// dispatch). The `unsafe` blocks call SSE2 intrinsics, which x86-64 always has.
#[cfg(target_arch = "x86_64")]
mod lanes {
    use super::super::candidate::Candidate;
    use super::super::quadric::Quadric;
    use glam::DVec3;
    use std::arch::x86_64::*;

    /// Lanes per group: one SSE2 register of `f64` (SSE2 is part of x86-64, so no run-time
    /// dispatch).
    const LANES: usize = 2;

    /// One `f64` per lane.
    #[derive(Clone, Copy)]
    struct F(__m128d);

    /// One flag per lane: all bits set or none.
    #[derive(Clone, Copy)]
    struct M(__m128d);

    impl F {
        #[inline(always)]
        fn splat(v: f64) -> F {
            F(unsafe { _mm_set1_pd(v) })
        }
        #[inline(always)]
        fn new(lanes: [f64; LANES]) -> F {
            F(unsafe { _mm_setr_pd(lanes[0], lanes[1]) })
        }
        #[inline(always)]
        fn lanes(self) -> [f64; LANES] {
            let mut out = [0.0; LANES];
            // SAFETY: `out` holds two f64.
            unsafe { _mm_storeu_pd(out.as_mut_ptr(), self.0) };
            out
        }
        #[inline(always)]
        fn neg(self) -> F {
            F(unsafe { _mm_xor_pd(self.0, _mm_set1_pd(-0.0)) })
        }
        #[inline(always)]
        fn abs(self) -> F {
            F(unsafe { _mm_andnot_pd(_mm_set1_pd(-0.0), self.0) })
        }
        #[inline(always)]
        fn sqrt(self) -> F {
            F(unsafe { _mm_sqrt_pd(self.0) })
        }
        /// `f64::max(x, 0.0)` per lane: 0 for NaN.
        #[inline(always)]
        fn max_zero(self) -> F {
            // maxpd returns its second operand when either is NaN.
            F(unsafe { _mm_max_pd(self.0, _mm_setzero_pd()) })
        }
        /// `f64::clamp(x, 0.0, 1.0)` per lane: NaN stays NaN.
        #[inline(always)]
        fn clamp_unit(self) -> F {
            let zero = F::splat(0.0);
            let one = F::splat(1.0);
            let low = self.lt(zero).select(zero, self);
            low.gt(one).select(one, low)
        }
        #[inline(always)]
        fn is_finite(self) -> M {
            self.abs().lt(F::splat(f64::INFINITY))
        }
    }

    impl M {
        #[inline(always)]
        fn select(self, yes: F, no: F) -> F {
            F(unsafe { _mm_or_pd(_mm_and_pd(self.0, yes.0), _mm_andnot_pd(self.0, no.0)) })
        }
        #[inline(always)]
        fn and(self, o: M) -> M {
            M(unsafe { _mm_and_pd(self.0, o.0) })
        }
    }

    macro_rules! lane_op {
        ($trait:ident, $method:ident, $intrinsic:ident) => {
            impl std::ops::$trait for F {
                type Output = F;
                #[inline(always)]
                fn $method(self, o: F) -> F {
                    F(unsafe { $intrinsic(self.0, o.0) })
                }
            }
        };
    }
    lane_op!(Add, add, _mm_add_pd);
    lane_op!(Sub, sub, _mm_sub_pd);
    lane_op!(Mul, mul, _mm_mul_pd);
    lane_op!(Div, div, _mm_div_pd);

    macro_rules! lane_cmp {
        ($(#[$doc:meta])* $method:ident, $intrinsic:ident) => {
            impl F {
                $(#[$doc])*
                #[inline(always)]
                fn $method(self, o: F) -> M {
                    M(unsafe { $intrinsic(self.0, o.0) })
                }
            }
        };
    }
    lane_cmp!(lt, _mm_cmplt_pd);
    lane_cmp!(le, _mm_cmple_pd);
    lane_cmp!(gt, _mm_cmpgt_pd);
    lane_cmp!(
        /// `!(self < o)`: also set where either is NaN.
        not_lt,
        _mm_cmpnlt_pd
    );

    /// A vector per lane.
    #[derive(Clone, Copy)]
    struct V {
        x: F,
        y: F,
        z: F,
    }

    impl V {
        #[inline(always)]
        fn dot(self, o: V) -> F {
            // glam: (x·x') + (y·y') + (z·z')
            self.x * o.x + self.y * o.y + self.z * o.z
        }
        #[inline(always)]
        fn cross(self, o: V) -> V {
            // glam's component formulas.
            V {
                x: self.y * o.z - o.y * self.z,
                y: self.z * o.x - o.z * self.x,
                z: self.x * o.y - o.x * self.y,
            }
        }
        #[inline(always)]
        fn add(self, o: V) -> V {
            V {
                x: self.x + o.x,
                y: self.y + o.y,
                z: self.z + o.z,
            }
        }
        #[inline(always)]
        fn sub(self, o: V) -> V {
            V {
                x: self.x - o.x,
                y: self.y - o.y,
                z: self.z - o.z,
            }
        }
        #[inline(always)]
        fn scale(self, s: F) -> V {
            V {
                x: self.x * s,
                y: self.y * s,
                z: self.z * s,
            }
        }
        #[inline(always)]
        fn divide(self, s: F) -> V {
            V {
                x: self.x / s,
                y: self.y / s,
                z: self.z / s,
            }
        }
        #[inline(always)]
        fn length(self) -> F {
            self.dot(self).sqrt()
        }
        #[inline(always)]
        fn select(m: M, yes: V, no: V) -> V {
            V {
                x: m.select(yes.x, no.x),
                y: m.select(yes.y, no.y),
                z: m.select(yes.z, no.z),
            }
        }
    }

    /// A quadric per lane (see [`Quadric`] for the names).
    struct Q {
        xx: F,
        xy: F,
        xz: F,
        yy: F,
        yz: F,
        zz: F,
        x: F,
        y: F,
        z: F,
        c: F,
        weight: F,
    }

    impl Q {
        /// `A p`, as [`Quadric`] computes it.
        #[inline(always)]
        fn mul_a(&self, p: V) -> V {
            V {
                x: self.xx * p.x + self.xy * p.y + self.xz * p.z,
                y: self.xy * p.x + self.yy * p.y + self.yz * p.z,
                z: self.xz * p.x + self.yz * p.y + self.zz * p.z,
            }
        }

        /// [`Quadric::evaluate`].
        #[inline(always)]
        fn evaluate(&self, p: V) -> F {
            let ap = self.mul_a(p);
            let linear = self.x * p.x + self.y * p.y + self.z * p.z;
            (p.dot(ap) + F::splat(2.0) * linear + self.c).max_zero()
        }
    }

    /// Costs the candidates at the indices `at`, group by group (a short last group
    /// repeats its first candidate in the spare lanes), handing each placement's target
    /// to `target` (candidate index, point).
    #[inline(always)]
    pub(super) fn place_at(
        pos: &[DVec3],
        quadric: &[Quadric],
        candidates: &mut [Candidate],
        at: &[u32],
        mut target_of: impl FnMut(usize, DVec3),
    ) {
        for group in at.chunks(LANES) {
            let at = [group[0], group[group.len() - 1]].map(|i| i as usize);
            let (a, b) = (&candidates[at[0]], &candidates[at[1]]);
            let (ua, va, ub, vb) = (a.u as usize, a.v as usize, b.u as usize, b.v as usize);
            let vector = |p: &DVec3, o: &DVec3| V {
                x: F::new([p.x, o.x]),
                y: F::new([p.y, o.y]),
                z: F::new([p.z, o.z]),
            };
            let pu = vector(&pos[ua], &pos[ub]);
            let pv = vector(&pos[va], &pos[vb]);
            // Q_u + Q_v per lane, read in place (no copies of the 88-byte quadrics).
            let (qua, qva, qub, qvb) = (&quadric[ua], &quadric[va], &quadric[ub], &quadric[vb]);
            let sum = |f: fn(&Quadric) -> f64| F::new([f(qua), f(qub)]) + F::new([f(qva), f(qvb)]);
            let q = Q {
                xx: sum(|q| q.xx),
                xy: sum(|q| q.xy),
                xz: sum(|q| q.xz),
                yy: sum(|q| q.yy),
                yz: sum(|q| q.yz),
                zz: sum(|q| q.zz),
                x: sum(|q| q.x),
                y: sum(|q| q.y),
                z: sum(|q| q.z),
                c: sum(|q| q.c),
                weight: sum(|q| q.weight),
            };
            let (target, cost) = place_group(&q, pu, pv);
            let cost = q
                .weight
                .gt(F::splat(0.0))
                .select(cost / q.weight, F::splat(0.0));
            let (cost, x, y, z) = (
                cost.lanes(),
                target.x.lanes(),
                target.y.lanes(),
                target.z.lanes(),
            );
            for (i, &c) in at.iter().enumerate() {
                candidates[c].cost = cost[i];
                target_of(c, DVec3::new(x[i], y[i], z[i]));
            }
        }
    }

    /// [`placement`] on every lane: [`Quadric::optimum`] where it exists and lies within an
    /// edge length of the midpoint, else [`Quadric::segment_minimum`].
    #[inline(always)]
    fn place_group(q: &Q, pu: V, pv: V) -> (V, F) {
        let zero = F::splat(0.0);
        let mid = pu.add(pv).scale(F::splat(0.5));
        // The optimum by Cramer's rule, where A is well conditioned.
        let det = q.xx * (q.yy * q.zz - q.yz * q.yz) - q.xy * (q.xy * q.zz - q.yz * q.xz)
            + q.xz * (q.xy * q.yz - q.yy * q.xz);
        let mean = (q.xx + q.yy + q.zz) / F::splat(3.0);
        // Scalar: !(mean.is_nan() || mean <= 0 || |det| < 1e-3·mean³).
        let conditioned = mean
            .gt(F::splat(0.0))
            .and(det.abs().not_lt(F::splat(1e-3) * mean * mean * mean));
        let b = V {
            x: q.x.neg(),
            y: q.y.neg(),
            z: q.z.neg(),
        };
        let cols = [
            V {
                x: q.xx,
                y: q.xy,
                z: q.xz,
            },
            V {
                x: q.xy,
                y: q.yy,
                z: q.yz,
            },
            V {
                x: q.xz,
                y: q.yz,
                z: q.zz,
            },
        ];
        let triple = |c0: V, c1: V, c2: V| c0.dot(c1.cross(c2));
        let optimum = V {
            x: triple(b, cols[1], cols[2]),
            y: triple(cols[0], b, cols[2]),
            z: triple(cols[0], cols[1], b),
        }
        .divide(det);
        let finite = optimum
            .x
            .is_finite()
            .and(optimum.y.is_finite())
            .and(optimum.z.is_finite());
        let near = optimum.sub(mid).length().le(pv.sub(pu).length());
        let use_optimum = conditioned.and(finite).and(near);
        // The minimum on the segment.
        let d = pv.sub(pu);
        let curvature = d.dot(q.mul_a(d));
        let end = V::select(q.evaluate(pu).le(q.evaluate(pv)), pu, pv);
        let slope = d.dot(q.mul_a(pu)) + q.x * d.x + q.y * d.y + q.z * d.z;
        let t = (slope.neg() / curvature).clamp_unit();
        let inside = pu.add(d.scale(t));
        let segment = V::select(curvature.le(zero), end, inside);
        let target = V::select(use_optimum, optimum, segment);
        (target, q.evaluate(target))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_rng::TestRng;

    /// A deterministic stream of numbers in [-1, 1).
    fn next(rng: &mut TestRng) -> f64 {
        rng.unit_f64() * 2.0 - 1.0
    }

    #[test]
    fn lanes_cost_every_candidate_exactly_as_the_scalar_placement() {
        let mut rng = TestRng::new(7);
        let mut pos = Vec::new();
        let mut quadric = Vec::new();
        for k in 0..400 {
            let p = DVec3::new(next(&mut rng), next(&mut rng), next(&mut rng));
            pos.push(p);
            // Quadrics of 0 to 3 planes through points near `p` (rank 0 to 3: no optimum,
            // a segment minimum, or a well-conditioned optimum), some nearly parallel.
            let mut q = Quadric::default();
            for plane in 0..k % 4 {
                let tilt = if k % 7 == 0 { 1e-4 } else { 1.0 };
                let a = p + DVec3::new(next(&mut rng), next(&mut rng), next(&mut rng)) * 0.01;
                let u = DVec3::new(1.0, tilt * next(&mut rng), tilt * next(&mut rng));
                let v = if plane == 1 {
                    DVec3::new(tilt * next(&mut rng), 1.0, tilt * next(&mut rng))
                } else {
                    DVec3::new(tilt * next(&mut rng), tilt * next(&mut rng), 1.0)
                };
                q += Quadric::from_triangle(a, a + u * 0.02, a + v * 0.02);
            }
            quadric.push(q);
        }
        // Coincident ends (a zero-length edge) and a vertex far from its planes.
        pos[5] = pos[4];
        pos[9] += DVec3::splat(3.0);
        let n = pos.len() as u32;
        for count in [1, 2, 3, 63, 200] {
            let mut candidates: Vec<Candidate> = (0..count)
                .map(|i| {
                    let u = (i * 37 + 4) % n;
                    let v = (i * 11 + 5 + i / 3) % n;
                    Candidate {
                        cost: f64::NAN,
                        ..Candidate::edge(0, u, if u == v { (v + 1) % n } else { v })
                    }
                })
                .collect();
            let targets = place_candidates(&pos, &quadric, &mut candidates);
            for (c, target) in candidates.iter().zip(targets) {
                let expected = candidate(&pos, &quadric, c.u, c.v);
                let (expected_target, _) = placement(&pos, &quadric, c.u, c.v);
                assert_eq!(
                    c.cost.to_bits(),
                    expected.cost.to_bits(),
                    "cost of {}-{}",
                    c.u,
                    c.v
                );
                for (got, want) in target.to_array().iter().zip(expected_target.to_array()) {
                    assert_eq!(got.to_bits(), want.to_bits(), "target of {}-{}", c.u, c.v);
                }
            }
        }
    }
}
