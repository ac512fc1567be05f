//! The Solenthaler field against a brute-force oracle: a direct O(N) sum in f64 at random
//! lattice vertices, with the Jacobian taken by central finite differences of vbar and its
//! eigenvalues found by bisection on the characteristic polynomial — none of it shares code
//! with the library's closed forms.

mod support;

use glam::Vec3;
use meniscus::field::{compute_field, FieldOptions};
use meniscus::grid::split_coordinate;
use support::{in_pool, Lcg};

/// A jittered blob of particles (spacing 2r) with a few loose ones around it.
fn blob(r: f64, rng: &mut Lcg) -> Vec<Vec3> {
    let mut pts = Vec::new();
    for k in -6..6 {
        for j in -5..5 {
            for i in -7..7 {
                let p = [i as f64, j as f64, k as f64].map(|c| (c + 0.5) * 2.0 * r);
                if (p[0] / 14.0).powi(2) + (p[1] / 10.0).powi(2) + (p[2] / 12.0).powi(2) > r * r {
                    continue;
                }
                let q = p.map(|c| c + (rng.next_f64() - 0.5) * 0.6 * r + 1.7);
                pts.push(Vec3::new(q[0] as f32, q[1] as f32, q[2] as f32));
            }
        }
    }
    for _ in 0..20 {
        let q = [0, 1, 2].map(|_| 1.7 + (rng.next_f64() - 0.5) * 40.0 * r);
        pts.push(Vec3::new(q[0] as f32, q[1] as f32, q[2] as f32));
    }
    pts
}

fn vbar(v: [f64; 3], pts: &[Vec3], big_r: f64) -> Option<[f64; 3]> {
    let (mut w, mut a) = (0.0, [0.0; 3]);
    for p in pts {
        let x = [p.x as f64, p.y as f64, p.z as f64];
        let s2 = ((v[0] - x[0]).powi(2) + (v[1] - x[1]).powi(2) + (v[2] - x[2]).powi(2))
            / (big_r * big_r);
        if s2 < 1.0 {
            let wi = (1.0 - s2).powi(3);
            w += wi;
            for c in 0..3 {
                a[c] += wi * x[c];
            }
        }
    }
    (w > 0.0).then(|| a.map(|c| c / w))
}

/// Largest real part of the eigenvalues, by scanning the characteristic polynomial.
fn largest_eigenvalue(m: [[f64; 3]; 3]) -> f64 {
    let det3 = |l: f64| {
        let a = [
            [m[0][0] - l, m[0][1], m[0][2]],
            [m[1][0], m[1][1] - l, m[1][2]],
            [m[2][0], m[2][1], m[2][2] - l],
        ];
        a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
            - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
    };
    // det(M − λI) → −∞ as λ → +∞: the largest real root is the last sign change.
    let (mut lo, mut hi) = (-50.0, 50.0);
    let steps = 20000;
    let mut roots = Vec::new();
    let mut prev = det3(lo);
    for s in 1..=steps {
        let l = lo + (hi - lo) * s as f64 / steps as f64;
        let cur = det3(l);
        if prev == 0.0 || prev.signum() != cur.signum() {
            let (mut a, mut b) = (l - (hi - lo) / steps as f64, l);
            for _ in 0..80 {
                let mid = 0.5 * (a + b);
                if det3(a).signum() == det3(mid).signum() {
                    a = mid
                } else {
                    b = mid
                }
            }
            roots.push(0.5 * (a + b));
        }
        prev = cur;
    }
    lo = roots.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    hi = lo;
    let trace = m[0][0] + m[1][1] + m[2][2];
    if roots.len() == 1 {
        // A complex pair with real part (trace − λ_real) / 2.
        hi = hi.max((trace - roots[0]) / 2.0);
    }
    hi
}

fn oracle_phi(v: [f64; 3], pts: &[Vec3], r: f64, big_r: f64) -> Option<f64> {
    let vb = vbar(v, pts, big_r)?;
    let eps = 1e-5 * r;
    let mut jac = [[0.0; 3]; 3];
    for b in 0..3 {
        let (mut vp, mut vm) = (v, v);
        vp[b] += eps;
        vm[b] -= eps;
        let (p, m) = (vbar(vp, pts, big_r)?, vbar(vm, pts, big_r)?);
        for a in 0..3 {
            jac[a][b] = (p[a] - m[a]) / (2.0 * eps);
        }
    }
    let ev = largest_eigenvalue(jac).clamp(0.4, 3.5);
    let f = if ev <= 0.4 {
        1.0
    } else {
        let g = (3.5 - ev) / 3.1;
        g * g * g - 3.0 * g * g + 3.0 * g
    };
    let d = ((v[0] - vb[0]).powi(2) + (v[1] - vb[1]).powi(2) + (v[2] - vb[2]).powi(2)).sqrt();
    Some(d - r * f)
}

fn check_against_oracle(coverage: f32) {
    let r = 0.05f64;
    let mut rng = Lcg(2024);
    let pts = blob(r, &mut rng);
    let mut options = FieldOptions::new(r as f32);
    options.particle_coverage = coverage;
    // Uncovered particles: the oracle field, trilinearly interpolated from the particle's
    // cell corners, is above −r/4.
    let c = coverage as f64 * r;
    let h = r;
    let interpolated = |x: [f64; 3]| -> Option<f64> {
        let g = x.map(|v| v / h);
        let base = g.map(f64::floor);
        let mut value = 0.0;
        for corner in 0..8 {
            let o = [corner & 1, (corner >> 1) & 1, (corner >> 2) & 1].map(|b| b as f64);
            let v = [0, 1, 2].map(|a| (base[a] + o[a]) * h);
            let weight: f64 = (0..3)
                .map(|a| {
                    if o[a] == 1.0 {
                        g[a] - base[a]
                    } else {
                        1.0 - (g[a] - base[a])
                    }
                })
                .product();
            value += weight * oracle_phi(v, &pts, r, 4.0 * r)?;
        }
        Some(value)
    };
    let uncovered: Vec<[f64; 3]> = pts
        .iter()
        .map(|p| [p.x as f64, p.y as f64, p.z as f64])
        .filter(|&x| coverage > 0.0 && interpolated(x).is_some_and(|phi| phi > -0.25 * r))
        .collect();
    if coverage > 0.0 {
        assert!(
            uncovered.len() >= 5,
            "the blob's loose particles must be uncovered"
        );
    }
    let (field, stats) = compute_field(&pts, &options).unwrap();
    assert!(stats.vertices_in_band > 1000);
    let h = options.cell_size_world();
    let keys = field.sorted_keys();
    let mut checked = 0;
    let mut inside = 0;
    let mut lowered = 0;
    let mut tries = 0;
    while checked < 300 {
        tries += 1;
        assert!(tries < 100_000);
        let key = keys[(rng.next_f64() * keys.len() as f64) as usize];
        let local = [0, 1, 2].map(|_| (rng.next_f64() * 8.0) as i32);
        let g = [0, 1, 2].map(|a| key[a] * 8 + local[a]);
        assert_eq!(split_coordinate(g[0]).0, key[0]);
        let value = field.value(g[0], g[1], g[2]) as f64;
        let v = g.map(|c| c as f64 * h);
        // Coverage lowers vertices within c·r + h of an uncovered particle.
        let covered = |phi: f64| {
            uncovered
                .iter()
                .map(|x| {
                    ((v[0] - x[0]).powi(2) + (v[1] - x[1]).powi(2) + (v[2] - x[2]).powi(2)).sqrt()
                })
                .filter(|&d| d < c + h)
                .map(|d| d - c)
                .fold(phi, f64::min)
        };
        // Vertices near uncovered particles are sampled on purpose too.
        let raw = oracle_phi(v, &pts, r, 4.0 * r);
        match raw.map(covered) {
            None => assert_eq!(
                value as f32, field.outside_value,
                "vertex {g:?} has no particle in range"
            ),
            Some(phi) => {
                // f32 sums and finite differences: agreement to 1e-3 r.
                assert!(
                    (value - phi).abs() < 1e-3 * r,
                    "vertex {g:?}: field {value}, oracle {phi}"
                );
                checked += 1;
                inside += (phi < 0.0) as usize;
                lowered += (phi < raw.unwrap()) as usize;
            }
        }
    }
    if coverage > 0.0 {
        assert!(
            lowered >= 3,
            "only {lowered} sampled vertices are lowered by coverage"
        );
    }
    assert!(
        inside > 20 && inside < 280,
        "the sample must cover both signs ({inside} inside)"
    );
}

#[test]
fn field_does_not_depend_on_thread_count() {
    let mut rng = Lcg(7);
    let pts = blob(0.05, &mut rng);
    let options = FieldOptions::new(0.05);
    let run = |threads: usize| in_pool(threads, || compute_field(&pts, &options).unwrap().0);
    let one = run(1);
    let two = run(3);
    assert_eq!(one.block_count(), two.block_count());
    for (key, values) in one.blocks() {
        let other = two.block(key).unwrap();
        assert!(
            values
                .iter()
                .zip(other.iter())
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "block {key:?}"
        );
    }
}

#[test]
fn bad_options_are_rejected_with_the_option_name() {
    let pts = vec![Vec3::ZERO, Vec3::X];
    for (options, name) in [
        (FieldOptions::new(0.0), "invalid particle_radius"),
        (FieldOptions::new(-1.0), "invalid particle_radius"),
        (FieldOptions::new(f32::NAN), "invalid particle_radius"),
        (
            {
                let mut o = FieldOptions::new(0.1);
                o.cell_size = 0.0;
                o
            },
            "invalid cell_size",
        ),
        (
            {
                let mut o = FieldOptions::new(0.1);
                o.influence_radius = -2.0;
                o
            },
            "invalid influence_radius",
        ),
    ] {
        let err = compute_field(&pts, &options).unwrap_err().to_string();
        assert!(err.contains(name), "{err}");
        // The library names its own option, never a command-line flag.
        assert!(!err.contains("--"), "{err}");
    }
}

#[test]
fn field_matches_direct_sum_at_random_vertices() {
    check_against_oracle(0.0);
}

#[test]
fn covered_field_matches_direct_sum_at_random_vertices() {
    check_against_oracle(0.9);
}

/// The field with other cell sizes and influence radii against the oracle: a block scans
/// the particles of the half-blocks within reach, `⌈R / 4h⌉` of them beyond its own, and
/// misses none (a missed particle would move vbar and the value).
#[test]
fn field_matches_direct_sum_for_other_cell_sizes_and_radii() {
    let r = 0.05f64;
    let mut rng = Lcg(77);
    let pts = blob(r, &mut rng);
    // (cell size, influence radius) in multiples of r: R/h = 8 cells (two half-blocks of
    // reach), 3.85 (one) and 4.29 (two, not a whole number).
    for (cell_size, influence_radius) in [(0.5f32, 4.0f32), (1.3, 5.0), (0.7, 3.0)] {
        let mut options = FieldOptions::new(r as f32);
        options.cell_size = cell_size;
        options.influence_radius = influence_radius;
        options.particle_coverage = 0.0;
        let (field, _) = compute_field(&pts, &options).unwrap();
        let h = options.cell_size_world();
        let keys = field.sorted_keys();
        let (mut checked, mut tries) = (0, 0);
        while checked < 120 {
            tries += 1;
            assert!(tries < 100_000);
            let key = keys[(rng.next_f64() * keys.len() as f64) as usize];
            let g = [0, 1, 2].map(|a| key[a] * 8 + (rng.next_f64() * 8.0) as i32);
            let value = field.value(g[0], g[1], g[2]) as f64;
            let v = g.map(|c| c as f64 * h);
            match oracle_phi(v, &pts, r, influence_radius as f64 * r) {
                None => assert_eq!(value as f32, field.outside_value, "vertex {g:?}"),
                Some(phi) => {
                    assert!(
                        (value - phi).abs() < 1e-3 * r,
                        "h = {cell_size} r, R = {influence_radius} r, vertex {g:?}: field \
                         {value}, oracle {phi}"
                    );
                    checked += 1;
                }
            }
        }
    }
}
