//! The eigen-decomposition of a symmetric 3×3 matrix (the anisotropic kernels'
//! covariances, [`super::kernels`]).

use glam::{DMat3, DVec3};

/// Eigenvalues (descending) and unit eigenvectors of a symmetric 3×3 matrix, by cyclic
/// Jacobi rotations (deterministic: a fixed sweep order, stopping when the off-diagonal
/// part is negligible). The vectors form a right-handed orthonormal frame.
pub(crate) fn symmetric_eigen(m: DMat3) -> ([f64; 3], [DVec3; 3]) {
    let mut a = [
        [m.x_axis.x, m.y_axis.x, m.z_axis.x],
        [m.x_axis.y, m.y_axis.y, m.z_axis.y],
        [m.x_axis.z, m.y_axis.z, m.z_axis.z],
    ];
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0f64]];
    let scale = a.iter().flatten().map(|x| x.abs()).fold(0.0, f64::max);
    if scale > 0.0 && scale.is_finite() {
        for _sweep in 0..32 {
            let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
            if off <= 1e-15 * scale {
                break;
            }
            rotate::<0, 1>(&mut a, &mut v);
            rotate::<0, 2>(&mut a, &mut v);
            rotate::<1, 2>(&mut a, &mut v);
        }
    }
    let mut idx = [0usize, 1, 2];
    idx.sort_by(|&i, &j| a[j][j].total_cmp(&a[i][i]));
    let values = idx.map(|i| a[i][i]);
    let mut vectors = idx.map(|i| DVec3::new(v[0][i], v[1][i], v[2][i]).normalize());
    if vectors[0].cross(vectors[1]).dot(vectors[2]) < 0.0 {
        vectors[2] = -vectors[2];
    }
    (values, vectors)
}

/// One Jacobi rotation of [`symmetric_eigen`] in the (`P`, `Q`) plane: `A ← Jᵀ A J`,
/// `V ← V J`, the one that zeroes `A[P][Q]` (none when it is already 0). The plane is a
/// constant so that each rotation compiles to straight-line code (the same operations in
/// the same order as with the plane a loop variable: 9 % fewer instructions in
/// `symmetric_eigen` on frame 25, callgrind, the same bits).
#[inline(always)]
fn rotate<const P: usize, const Q: usize>(a: &mut [[f64; 3]; 3], v: &mut [[f64; 3]; 3]) {
    if a[P][Q].abs() <= 1e-300 {
        return;
    }
    let theta = (a[Q][Q] - a[P][P]) / (2.0 * a[P][Q]);
    let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
    let t = if theta == 0.0 { 1.0 } else { t };
    let c = 1.0 / (t * t + 1.0).sqrt();
    let s = t * c;
    for row in a.iter_mut() {
        let (akp, akq) = (row[P], row[Q]);
        row[P] = c * akp - s * akq;
        row[Q] = s * akp + c * akq;
    }
    let (row_p, row_q) = (a[P], a[Q]);
    for k in 0..3 {
        a[P][k] = c * row_p[k] - s * row_q[k];
        a[Q][k] = s * row_p[k] + c * row_q[k];
    }
    for row in v.iter_mut() {
        let (vp, vq) = (row[P], row[Q]);
        row[P] = c * vp - s * vq;
        row[Q] = s * vp + c * vq;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eigen_decomposition_reconstructs_the_matrix() {
        let mut rng = crate::test_rng::TestRng::new(3);
        for _ in 0..200 {
            let mut e = || rng.unit_f32() as f64 * 2.0 - 1.0;
            let b = DMat3::from_cols_array(&[e(), e(), e(), e(), e(), e(), e(), e(), e()]);
            let m = b * b.transpose();
            let (values, vectors) = symmetric_eigen(m);
            assert!(values[0] >= values[1] && values[1] >= values[2]);
            let mut back = DMat3::ZERO;
            for (l, v) in values.iter().zip(&vectors) {
                back += DMat3::from_cols(*v * v.x, *v * v.y, *v * v.z) * *l;
            }
            for (x, y) in back.to_cols_array().iter().zip(m.to_cols_array()) {
                assert!((x - y).abs() < 1e-12 * (1.0 + y.abs()), "{back} vs {m}");
            }
        }
    }
}
