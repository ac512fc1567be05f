//! Plane quadrics (Garland & Heckbert 1997): `Q(p) = pᵀ A p + 2 bᵀ p + c`, the sum of
//! area-weighted squared distances from `p` to the planes of a vertex's triangles.

use glam::DVec3;

/// A symmetric 4×4 quadric stored as its 10 distinct entries, plus the total area weight.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Quadric {
    // A = [[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]], b = (x, y, z), c
    pub(super) xx: f64,
    pub(super) xy: f64,
    pub(super) xz: f64,
    pub(super) yy: f64,
    pub(super) yz: f64,
    pub(super) zz: f64,
    pub(super) x: f64,
    pub(super) y: f64,
    pub(super) z: f64,
    pub(super) c: f64,
    /// Total area of the planes added (for errors as distances).
    pub weight: f64,
}

/// The area-weighted plane of a triangle (unit normal `n`, offset `d` with `n·p + d = 0`),
/// 40 bytes instead of the quadric's 88: what [`Quadric::from_plane`] expands.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Plane {
    n: DVec3,
    d: f64,
    area: f64,
}

impl Plane {
    /// The plane through `a, b, c`, weighted by the triangle's area; zero weight for a
    /// degenerate triangle.
    pub fn from_triangle(a: DVec3, b: DVec3, c: DVec3) -> Plane {
        let n = (b - a).cross(c - a);
        let len = n.length();
        if len == 0.0 || !len.is_finite() {
            return Plane::default();
        }
        let n = n / len;
        Plane {
            n,
            d: -n.dot(a),
            area: 0.5 * len,
        }
    }
}

impl Quadric {
    /// The quadric of the plane through `a, b, c`, weighted by the triangle's area; zero
    /// for a degenerate triangle.
    #[cfg(test)]
    pub fn from_triangle(a: DVec3, b: DVec3, c: DVec3) -> Quadric {
        Quadric::from_plane(&Plane::from_triangle(a, b, c))
    }

    /// The quadric of an area-weighted plane; zero for a zero weight.
    pub fn from_plane(plane: &Plane) -> Quadric {
        let Plane { n, d, area } = *plane;
        if area == 0.0 {
            return Quadric::default();
        }
        Quadric {
            xx: area * n.x * n.x,
            xy: area * n.x * n.y,
            xz: area * n.x * n.z,
            yy: area * n.y * n.y,
            yz: area * n.y * n.z,
            zz: area * n.z * n.z,
            x: area * n.x * d,
            y: area * n.y * d,
            z: area * n.z * d,
            c: area * d * d,
            weight: area,
        }
    }

    #[cfg_attr(all(target_arch = "x86_64", not(test)), allow(dead_code))]
    /// `Q(p)`, clamped at zero against rounding.
    pub fn evaluate(&self, p: DVec3) -> f64 {
        let ap = self.mul_a(p);
        (p.dot(ap) + 2.0 * (self.x * p.x + self.y * p.y + self.z * p.z) + self.c).max(0.0)
    }

    #[cfg_attr(all(target_arch = "x86_64", not(test)), allow(dead_code))]
    fn mul_a(&self, p: DVec3) -> DVec3 {
        DVec3::new(
            self.xx * p.x + self.xy * p.y + self.xz * p.z,
            self.xy * p.x + self.yy * p.y + self.yz * p.z,
            self.xz * p.x + self.yz * p.y + self.zz * p.z,
        )
    }

    #[cfg_attr(all(target_arch = "x86_64", not(test)), allow(dead_code))]
    /// The minimiser of `Q` when `A` is well conditioned (its determinant is not tiny next
    /// to the cube of its mean eigenvalue), else `None`.
    pub fn optimum(&self) -> Option<DVec3> {
        let det = self.xx * (self.yy * self.zz - self.yz * self.yz)
            - self.xy * (self.xy * self.zz - self.yz * self.xz)
            + self.xz * (self.xy * self.yz - self.yy * self.xz);
        let mean = (self.xx + self.yy + self.zz) / 3.0;
        if mean.is_nan() || mean <= 0.0 || det.abs() < 1e-3 * mean * mean * mean {
            return None;
        }
        let b = DVec3::new(-self.x, -self.y, -self.z);
        // Cramer's rule on the symmetric system A p = −b.
        let cols = [
            DVec3::new(self.xx, self.xy, self.xz),
            DVec3::new(self.xy, self.yy, self.yz),
            DVec3::new(self.xz, self.yz, self.zz),
        ];
        let d = |c0: DVec3, c1: DVec3, c2: DVec3| c0.dot(c1.cross(c2));
        let p = DVec3::new(
            d(b, cols[1], cols[2]),
            d(cols[0], b, cols[2]),
            d(cols[0], cols[1], b),
        ) / det;
        p.is_finite().then_some(p)
    }

    #[cfg_attr(all(target_arch = "x86_64", not(test)), allow(dead_code))]
    /// The minimiser of `Q` on the segment `a..b`.
    pub fn segment_minimum(&self, a: DVec3, b: DVec3) -> DVec3 {
        let d = b - a;
        let ad = self.mul_a(d);
        let curvature = d.dot(ad);
        if curvature <= 0.0 {
            return if self.evaluate(a) <= self.evaluate(b) {
                a
            } else {
                b
            };
        }
        let slope = d.dot(self.mul_a(a)) + self.x * d.x + self.y * d.y + self.z * d.z;
        a + d * (-slope / curvature).clamp(0.0, 1.0)
    }
}

impl std::ops::Add for Quadric {
    type Output = Quadric;
    fn add(self, o: Quadric) -> Quadric {
        Quadric {
            xx: self.xx + o.xx,
            xy: self.xy + o.xy,
            xz: self.xz + o.xz,
            yy: self.yy + o.yy,
            yz: self.yz + o.yz,
            zz: self.zz + o.zz,
            x: self.x + o.x,
            y: self.y + o.y,
            z: self.z + o.z,
            c: self.c + o.c,
            weight: self.weight + o.weight,
        }
    }
}

impl std::ops::AddAssign for Quadric {
    fn add_assign(&mut self, o: Quadric) {
        *self = *self + o;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corner_of_three_planes_is_the_optimum() {
        let o = DVec3::new(0.3, -0.2, 0.5);
        let q = Quadric::from_triangle(o, o + DVec3::X, o + DVec3::Y)
            + Quadric::from_triangle(o, o + DVec3::Y, o + DVec3::Z)
            + Quadric::from_triangle(o, o + DVec3::Z, o + DVec3::X);
        let p = q.optimum().unwrap();
        assert!((p - o).length() < 1e-12);
        assert!(q.evaluate(o) < 1e-15);
        assert!(
            (q.evaluate(o + DVec3::X) - 0.5).abs() < 1e-12,
            "distance 1 to the x plane, weight 0.5"
        );
    }

    #[test]
    fn a_single_plane_has_no_stable_optimum_but_a_segment_minimum() {
        let q = Quadric::from_triangle(DVec3::ZERO, DVec3::X, DVec3::Y);
        assert!(q.optimum().is_none());
        let p = q.segment_minimum(DVec3::new(0.0, 0.0, 1.0), DVec3::new(1.0, 0.0, -1.0));
        assert!(p.z.abs() < 1e-12);
    }
}
