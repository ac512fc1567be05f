//! The eigen-decomposition of a symmetric 3×3 matrix (the anisotropic kernels'
//! covariances, [`super::kernels`]).

use glam::{DMat3, DVec3};

/// Eigenvalues (descending) and unit eigenvectors of a symmetric 3×3 matrix, in closed
/// form: the eigenvalue farthest from the other two from the trigonometric solution of
/// the characteristic cubic (O. K. Smith 1961), its eigenvector as the longest cross
/// product of two rows of `A − λI` (as in D. Eberly, "A Robust Eigensolver for 3 × 3
/// Symmetric Matrices", 2014), then the other two from the symmetric 2×2 problem in the
/// plane orthogonal to it, which keeps them accurate when they are close or equal (where
/// the cubic's roots lose half their digits). The vectors form a right-handed
/// orthonormal frame; no iteration, so the cost is the same for every matrix.
pub(crate) fn symmetric_eigen(m: DMat3) -> ([f64; 3], [DVec3; 3]) {
    let scale = largest_entry(&m);
    let diagonal = m.x_axis.y == 0.0 && m.x_axis.z == 0.0 && m.y_axis.z == 0.0;
    if diagonal || !(scale > 0.0 && scale.is_finite()) {
        let d = [m.x_axis.x, m.y_axis.y, m.z_axis.z];
        return sorted(d, [DVec3::X, DVec3::Y, DVec3::Z]);
    }
    // Conditioned: entries of at most 1 in magnitude.
    let a = m * (1.0 / scale);
    let (a00, a01, a02) = (a.x_axis.x, a.y_axis.x, a.z_axis.x);
    let (a11, a12, a22) = (a.y_axis.y, a.z_axis.y, a.z_axis.z);
    let q = (a00 + a11 + a22) / 3.0;
    let (b00, b11, b22) = (a00 - q, a11 - q, a22 - q);
    let p = ((b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * (a01 * a01 + a02 * a02 + a12 * a12)) / 6.0)
        .sqrt();
    // B = (A − qI) / p has the eigenvalues 2 cos(θ + 2πk/3) with cos 3θ = det(B) / 2; the
    // largest (k = 0) lies farthest from the others when det(B) ≥ 0, else the smallest.
    let c00 = b11 * b22 - a12 * a12;
    let c01 = a01 * b22 - a12 * a02;
    let c02 = a01 * a12 - b11 * a02;
    let half_det = ((b00 * c00 - a01 * c01 + a02 * c02) / (2.0 * p * p * p)).clamp(-1.0, 1.0);
    let angle = half_det.acos() / 3.0;
    let beta = if half_det >= 0.0 {
        2.0 * angle.cos()
    } else {
        2.0 * (angle + 2.0 * std::f64::consts::FRAC_PI_3).cos()
    };
    let first = q + p * beta;
    let u = isolated_vector(&a, first);
    // The plane orthogonal to u, and A restricted to it.
    let e1 = if u.x.abs() > u.y.abs() {
        DVec3::new(-u.z, 0.0, u.x) / (u.x * u.x + u.z * u.z).sqrt()
    } else {
        DVec3::new(0.0, u.z, -u.y) / (u.y * u.y + u.z * u.z).sqrt()
    };
    let e2 = u.cross(e1);
    let (ae1, ae2) = (a * e1, a * e2);
    let (m00, m01, m11) = (e1.dot(ae1), e1.dot(ae2), e2.dot(ae2));
    let half_gap = 0.5 * (m00 - m11);
    let h = half_gap.hypot(m01);
    let mean = 0.5 * (m00 + m11);
    // The eigenvector of the larger value: (λ − m11, m01) or (m01, λ − m00), whichever
    // is free of cancellation.
    let (x, y) = if half_gap >= 0.0 {
        (half_gap + h, m01)
    } else {
        (m01, h - half_gap)
    };
    let length = x.hypot(y);
    let v = if length > 0.0 {
        (e1 * x + e2 * y) / length
    } else {
        e1
    };
    sorted(
        [first, mean + h, mean - h].map(|x| x * scale),
        [u, v, u.cross(v)],
    )
}

/// The largest magnitude of an entry of `m`.
fn largest_entry(m: &DMat3) -> f64 {
    m.to_cols_array()
        .iter()
        .map(|x| x.abs())
        .fold(0.0, f64::max)
}

/// Values in descending order with their vectors, the frame made right-handed.
fn sorted(values: [f64; 3], vectors: [DVec3; 3]) -> ([f64; 3], [DVec3; 3]) {
    let mut idx = [0usize, 1, 2];
    idx.sort_by(|&i, &j| values[j].total_cmp(&values[i]));
    let values = idx.map(|i| values[i]);
    let mut vectors = idx.map(|i| vectors[i]);
    if vectors[0].cross(vectors[1]).dot(vectors[2]) < 0.0 {
        vectors[2] = -vectors[2];
    }
    (values, vectors)
}

/// The unit eigenvector of `a` for the eigenvalue `lambda` farthest from the other two:
/// orthogonal to the rows of `A − λI`, taken as the longest cross product of two of them
/// (any unit vector when all three eigenvalues are equal to rounding).
fn isolated_vector(a: &DMat3, lambda: f64) -> DVec3 {
    let shifted = *a - DMat3::from_diagonal(DVec3::splat(lambda));
    // Symmetric: the columns are the rows.
    let (r0, r1, r2) = (shifted.x_axis, shifted.y_axis, shifted.z_axis);
    let candidates = [r0.cross(r1), r0.cross(r2), r1.cross(r2)];
    let mut best = candidates[0];
    for c in &candidates[1..] {
        if c.length_squared() > best.length_squared() {
            best = *c;
        }
    }
    let length = best.length();
    if length > 0.0 {
        best / length
    } else {
        DVec3::X
    }
}

/// The reference of the tests: cyclic Jacobi rotations until the off-diagonal part is
/// negligible (the solver of the kernels until 2026-11-29), eigenvalues descending.
#[cfg(test)]
fn jacobi_eigen(m: DMat3) -> ([f64; 3], [DVec3; 3]) {
    let mut a = m.transpose().to_cols_array_2d();
    let mut v = DMat3::IDENTITY.to_cols_array_2d();
    let scale = largest_entry(&m);
    for _sweep in 0..64 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        if off <= 1e-15 * scale {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q].abs() <= 1e-300 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for row in a.iter_mut() {
                let (akp, akq) = (row[p], row[q]);
                row[p] = c * akp - s * akq;
                row[q] = s * akp + c * akq;
            }
            let (row_p, row_q) = (a[p], a[q]);
            for k in 0..3 {
                a[p][k] = c * row_p[k] - s * row_q[k];
                a[q][k] = s * row_p[k] + c * row_q[k];
            }
            for row in v.iter_mut() {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    let values = [a[0][0], a[1][1], a[2][2]];
    let vectors = [0, 1, 2].map(|i| DVec3::new(v[0][i], v[1][i], v[2][i]).normalize());
    sorted(values, vectors)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Checks a decomposition of `m`: values descending and within `tol` (relative to the
    /// largest entry) of the Jacobi rotations', vectors a right-handed orthonormal frame,
    /// `Σ λ v vᵀ = m` to `tol`.
    fn check(m: DMat3, tol: f64) {
        let (values, vectors) = symmetric_eigen(m);
        let (reference, _) = jacobi_eigen(m);
        let scale = largest_entry(&m);
        assert!(
            values[0] >= values[1] && values[1] >= values[2],
            "{values:?}"
        );
        for (v, r) in values.iter().zip(&reference) {
            assert!(
                (v - r).abs() <= tol * scale,
                "{values:?} against {reference:?} for {m}"
            );
        }
        let frame = DMat3::from_cols(vectors[0], vectors[1], vectors[2]);
        let gram = frame.transpose() * frame;
        for (x, y) in gram
            .to_cols_array()
            .iter()
            .zip(DMat3::IDENTITY.to_cols_array())
        {
            assert!((x - y).abs() < 1e-12, "not orthonormal: {gram} for {m}");
        }
        assert!(frame.determinant() > 0.0, "left-handed for {m}");
        let back = frame * DMat3::from_diagonal(DVec3::from_array(values)) * frame.transpose();
        for (x, y) in back.to_cols_array().iter().zip(m.to_cols_array()) {
            assert!((x - y).abs() <= tol * scale, "{back} against {m}");
        }
    }

    /// A rotation about a generic axis.
    fn rotation(angle: f64) -> DMat3 {
        DMat3::from_axis_angle(DVec3::new(0.3, -0.5, 0.81).normalize(), angle)
    }

    #[test]
    fn random_covariances_decompose_like_the_jacobi_rotations() {
        let mut rng = crate::test_rng::TestRng::new(3);
        for _ in 0..2000 {
            let mut e = || rng.unit_f32() as f64 * 2.0 - 1.0;
            let b = DMat3::from_cols_array(&[e(), e(), e(), e(), e(), e(), e(), e(), e()]);
            check(b * b.transpose(), 1e-12);
            // Symmetric, not definite.
            check(b + b.transpose(), 1e-12);
        }
    }

    /// Equal, nearly equal and vanishing eigenvalues, in a rotated frame and along the
    /// axes, at scales far from 1: where the cubic's roots lose digits and where a cross
    /// product of rows vanishes.
    #[test]
    fn degenerate_spectra_decompose_exactly() {
        let spectra = [
            [1.0, 1.0, 1.0],
            [2.0, 1.0, 1.0],
            [2.0, 2.0, 1.0],
            [3.0, 1.0 + 1e-9, 1.0],
            [1.0 + 1e-12, 1.0, 1.0 - 1e-12],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [5.0, -2.0, -2.0],
            [0.0, 0.0, 0.0],
        ];
        for spectrum in spectra {
            for scale in [1e-30, 1e-3, 1.0, 1e30] {
                let d = DMat3::from_diagonal(DVec3::from_array(spectrum) * scale);
                check(d, 1e-12);
                for angle in [1e-9, 0.3, 2.0] {
                    let r = rotation(angle);
                    check(r * d * r.transpose(), 1e-12);
                }
            }
        }
    }

    /// A flat neighbourhood: points on a plane give a zero eigenvalue whose vector is the
    /// plane's normal.
    #[test]
    fn a_flat_covariance_gives_the_normal_last() {
        let normal = DVec3::new(1.0, 2.0, 2.0) / 3.0;
        let r = rotation(0.7);
        let (a, b) = (r * DVec3::X, r * DVec3::Y);
        let (a, b) = (a - normal * a.dot(normal), b - normal * b.dot(normal));
        let mut m = DMat3::ZERO;
        for i in 0..40 {
            let t = i as f64 * 0.37;
            let p = a * t.cos() * 2.0 + b * (1.7 * t).sin();
            m += DMat3::from_cols(p * p.x, p * p.y, p * p.z);
        }
        check(m, 1e-12);
        let (values, vectors) = symmetric_eigen(m);
        assert!(values[2].abs() < 1e-12 * values[0]);
        assert!(vectors[2].dot(normal).abs() > 1.0 - 1e-12);
    }
}
