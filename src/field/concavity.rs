//! The concavity factor `f` of Solenthaler et al. 2007 and the largest real part of the
//! eigenvalues of the 3×3 Jacobian `∇vbar` it is computed from (closed form of the
//! characteristic cubic, in f64).

/// The factor `f` of Solenthaler et al. 2007 for the largest eigenvalue `ev`.
pub(crate) fn concavity_factor(ev: f64, t_low: f64, t_high: f64) -> f64 {
    if ev.is_nan() || ev < t_low {
        // Also catches NaN: treat an undefined eigenvalue as a flat neighbourhood.
        return 1.0;
    }
    let ev = ev.min(t_high);
    let g = (t_high - ev) / (t_high - t_low);
    g * g * g - 3.0 * g * g + 3.0 * g
}

/// Largest real part among the eigenvalues of a row-major 3×3 matrix, from the
/// characteristic cubic `λ³ + a λ² + b λ + c = 0` in closed form.
///
/// With three real roots the largest is `ρ·cos(acos(x)/3) + shift`. `cos(acos(x)/3)` is
/// `g(s) = cos(⅔·acos(s))` with `s = √((1 + x)/2)`, which is analytic on `[0, 1]`; a
/// degree-8 polynomial fit (Chebyshev, in `s`) gets it within 9e-9, so the root is within
/// `1e-8·ρ` — below the f32 precision of the field — for a sixth of the time of the libm
/// `acos` and `cos` (which took a quarter of the field stage).
#[cfg(test)]
pub(crate) fn largest_eigenvalue_real_part(m: &[f64; 9]) -> f64 {
    let c = Cubic::of(*m);
    if c.disc > 0.0 {
        c.largest_with_one_real_root()
    } else if c.p < 0.0 {
        c.largest_of_three_real_roots()
    } else {
        c.shift
    }
}

/// [`largest_eigenvalue_real_part`] of `N` matrices at once, given entry by entry
/// (`m[k][lane]`): the same operations lane by lane, so the same values bit for bit. The
/// common case (three real roots) has no branch and no call, so the lanes run as vector
/// instructions; the cube roots of the one-real-root case are taken lane by lane.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
pub(crate) fn largest_eigenvalue_real_part_lanes<const N: usize>(m: &[[f64; N]; 9]) -> [f64; N] {
    // Plain loops rather than closures, so that everything inlines into the caller's
    // (possibly AVX2) code.
    let mut cubics = [Cubic::default(); N];
    for l in 0..N {
        let mut lane = [0.0; 9];
        for k in 0..9 {
            lane[k] = m[k][l];
        }
        cubics[l] = Cubic::of(lane);
    }
    let mut largest = [0.0; N];
    for l in 0..N {
        largest[l] = cubics[l].largest_of_three_real_roots();
    }
    for l in 0..N {
        let c = &cubics[l];
        if c.disc > 0.0 {
            largest[l] = c.largest_with_one_real_root();
        } else if c.p.is_nan() || c.p >= 0.0 {
            // (A NaN `p` takes the shift, as in the scalar version.)
            largest[l] = c.shift;
        }
    }
    largest
}

/// The characteristic cubic of a 3×3 matrix in depressed form `t³ + p t + q = 0`,
/// `λ = t + shift`.
#[derive(Clone, Copy, Default)]
struct Cubic {
    trace: f64,
    shift: f64,
    p: f64,
    half_q: f64,
    third_p: f64,
    disc: f64,
}

impl Cubic {
    #[inline(always)]
    fn of(m: [f64; 9]) -> Cubic {
        const THIRD: f64 = 1.0 / 3.0;
        let tr = m[0] + m[4] + m[8];
        let minors =
            m[0] * m[4] - m[1] * m[3] + m[0] * m[8] - m[2] * m[6] + m[4] * m[8] - m[5] * m[7];
        let det = m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6])
            + m[2] * (m[3] * m[7] - m[4] * m[6]);
        let (a, b, c) = (-tr, minors, -det);
        let p = b - a * a * THIRD;
        let q = (2.0 / 27.0) * a * a * a - a * b * THIRD + c;
        let half_q = 0.5 * q;
        let third_p = p * THIRD;
        Cubic {
            trace: tr,
            shift: -a * THIRD,
            p,
            half_q,
            third_p,
            disc: half_q * half_q + third_p * third_p * third_p,
        }
    }

    /// One real root and a complex pair (`disc > 0`): the larger of the root and the
    /// pair's real part.
    fn largest_with_one_real_root(&self) -> f64 {
        let s = self.disc.sqrt();
        let t = (-self.half_q + s).cbrt() + (-self.half_q - s).cbrt();
        let real_root = t + self.shift;
        let pair_real = (self.trace - real_root) * 0.5;
        real_root.max(pair_real)
    }

    /// Three real roots (`disc ≤ 0`, `p < 0`); `k = 0` gives the largest:
    /// `ρ·cos(acos(x)/3) + shift`. Meaningless (but harmless) in the other cases.
    #[inline(always)]
    fn largest_of_three_real_roots(&self) -> f64 {
        let root = (-self.third_p).sqrt();
        let rho = 2.0 * root;
        // x = 3q / (p·ρ) = (q/2) / (p/3 · root).
        let x = (self.half_q / (self.third_p * root)).clamp(-1.0, 1.0);
        rho * cos_third_of_acos(x) + self.shift
    }
}

/// `cos(acos(x) / 3)` for `x` in `[−1, 1]`: within 9e-9, and to rounding for `x` above
/// −0.936 (c > 0.6; see [`largest_eigenvalue_real_part`]).
#[inline(always)]
fn cos_third_of_acos(x: f64) -> f64 {
    const G: [f64; 9] = [
        5.000_000_087_591_784e-1,
        5.773_494_483_957_637e-1,
        -1.110_920_901_837_136e-1,
        5.326_809_907_745_968e-2,
        -3.190_065_837_829_047e-2,
        1.957_704_234_521_999e-2,
        -1.023_702_504_243_851e-2,
        3.667_459_595_277_825e-3,
        -6.322_909_999_796_837e-4,
    ];
    let s = (0.5 * (1.0 + x)).max(0.0).sqrt();
    // Estrin's scheme: four levels of dependent operations instead of Horner's eight.
    let s2 = s * s;
    let s4 = s2 * s2;
    let low = (G[0] + G[1] * s) + s2 * (G[2] + G[3] * s);
    let high = (G[4] + G[5] * s) + s2 * (G[6] + G[7] * s);
    let c = low + s4 * (high + s4 * G[8]);
    // One Newton step on 4c³ − 3c = x (cos 3φ = 4cos³φ − 3cos φ) takes the error to the
    // f64 rounding level, except near c = 1/2 where the derivative 12c² − 3 vanishes.
    // Computed either way and then chosen, so that lanes of a vector need no branch.
    let newton = c - (4.0 * c * c * c - 3.0 * c - x) / (12.0 * c * c - 3.0);
    if c > 0.6 {
        newton
    } else {
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eigenvalue_of_diagonal_and_rotation_matrices() {
        assert!(
            (largest_eigenvalue_real_part(&[1.0, 0.0, 0.0, 0.0, 3.0, 0.0, 0.0, 0.0, 2.0]) - 3.0)
                .abs()
                < 1e-9
        );
        assert!(
            (largest_eigenvalue_real_part(&[-1.0, 0.0, 0.0, 0.0, -3.0, 0.0, 0.0, 0.0, -2.0]) + 1.0)
                .abs()
                < 1e-9
        );
        // Rotation by 90° about z scaled by 2, plus 0.5 on z: eigenvalues ±2i and 0.5.
        let ev = largest_eigenvalue_real_part(&[0.0, -2.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.5]);
        assert!((ev - 0.5).abs() < 1e-9, "{ev}");
        // Identity: triple root.
        assert!(
            (largest_eigenvalue_real_part(&[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]) - 1.0)
                .abs()
                < 1e-6
        );
        // Non-symmetric with real eigenvalues 1, 2, 4 (upper triangular).
        let ev = largest_eigenvalue_real_part(&[1.0, 5.0, -3.0, 0.0, 2.0, 7.0, 0.0, 0.0, 4.0]);
        assert!((ev - 4.0).abs() < 1e-7, "{ev}");
    }

    /// Pseudo-random numbers uniform in [−2, 2) (a 64-bit LCG seeded with `seed`).
    fn uniform(seed: u64) -> impl FnMut() -> f64 {
        let mut rng = crate::test_rng::TestRng::new(seed);
        move || rng.unit_f64() * 4.0 - 2.0
    }

    #[test]
    fn cos_third_of_acos_matches_libm() {
        for k in 0..=20_000 {
            let x = -1.0 + k as f64 / 10_000.0;
            let exact = (x.acos() / 3.0).cos();
            let fast = cos_third_of_acos(x);
            assert!((fast - exact).abs() < 1e-8, "x = {x}: {fast} vs {exact}");
        }
    }

    #[test]
    fn eigenvalues_of_random_symmetric_like_matrices_match_a_power_iteration() {
        // Symmetric matrices (real eigenvalues, the three-root branch): the largest
        // eigenvalue from the closed form against the Rayleigh quotient of a long power
        // iteration on the matrix shifted to be positive definite.
        let mut next = uniform(11);
        for _ in 0..200 {
            let (d, e, f, g, h, i) = (next(), next(), next(), next(), next(), next());
            let m = [d, e, f, e, g, h, f, h, i];
            let shifted = |v: [f64; 3]| {
                let mut out = [0.0; 3];
                for r in 0..3 {
                    out[r] = (0..3).map(|c| m[r * 3 + c] * v[c]).sum::<f64>() + 20.0 * v[r];
                }
                out
            };
            let mut v = [1.0, 0.3, -0.7];
            for _ in 0..5000 {
                let w = shifted(v);
                let n = w.iter().map(|x| x * x).sum::<f64>().sqrt();
                v = w.map(|x| x / n);
            }
            let w = shifted(v);
            let rayleigh = (0..3).map(|k| v[k] * w[k]).sum::<f64>() - 20.0;
            let ev = largest_eigenvalue_real_part(&m);
            assert!((ev - rayleigh).abs() < 1e-6, "{m:?}: {ev} vs {rayleigh}");
        }
    }

    #[test]
    fn lanes_give_the_scalar_eigenvalue_bit_for_bit() {
        // Random non-symmetric matrices (both the one- and the three-real-root case),
        // a triple root, zero, and non-finite entries.
        let mut next = uniform(3);
        let mut matrices: Vec<[f64; 9]> =
            (0..400).map(|_| std::array::from_fn(|_| next())).collect();
        matrices.push([1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
        matrices.push([0.0; 9]);
        matrices.push([f64::NAN, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
        matrices.push([f64::INFINITY, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
        let (mut one_root, mut three_roots) = (0, 0);
        for group in matrices.chunks(8) {
            let mut lanes = [[0.0f64; 8]; 9];
            for (l, m) in group.iter().enumerate() {
                for k in 0..9 {
                    lanes[k][l] = m[k];
                }
            }
            let got = largest_eigenvalue_real_part_lanes(&lanes);
            for (l, m) in group.iter().enumerate() {
                let c = Cubic::of(*m);
                if c.disc > 0.0 {
                    one_root += 1;
                } else if c.p < 0.0 {
                    three_roots += 1;
                }
                let want = largest_eigenvalue_real_part(m);
                assert!(
                    got[l].to_bits() == want.to_bits() || (got[l].is_nan() && want.is_nan()),
                    "{m:?}: {} vs {want}",
                    got[l]
                );
            }
        }
        assert!(
            one_root > 50 && three_roots > 50,
            "{one_root} / {three_roots}"
        );
    }

    #[test]
    fn concavity_factor_is_one_below_t_low_and_zero_at_t_high() {
        assert_eq!(concavity_factor(0.1, 0.4, 3.5), 1.0);
        assert!((concavity_factor(0.4, 0.4, 3.5) - 1.0).abs() < 1e-12);
        assert!(concavity_factor(3.5, 0.4, 3.5).abs() < 1e-12);
        assert!(concavity_factor(10.0, 0.4, 3.5).abs() < 1e-12);
        let mid = concavity_factor(2.0, 0.4, 3.5);
        assert!(mid > 0.0 && mid < 1.0);
    }
}
