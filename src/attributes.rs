//! Particle attributes carried to the surface (velocity for motion blur, density, any
//! scalar or vector the input holds).
//!
//! **Input:** the particles' selected attributes (the payload the tile engine carries
//! beside the positions) and the final surface. **Output:** one value per surface vertex,
//! the normalized kernel-weighted mean of the particles within the influence radius `R`
//! of the vertex, with the field's kernel `k(s) = max(0, (1 − s²)³)`, `s = |x − x_i| / R`:
//!
//! ```text
//! a(x) = Σ_i k(|x − x_i| / R) · a_i  /  Σ_i k(|x − x_i| / R)
//! ```
//!
//! evaluated at the **final** vertex positions (after decimation and subdivision), so the
//! value is a function of the position alone: the particles within `R` are summed in the
//! engine's canonical order (home half-block, input index) in f64, the same in every
//! tiling and for every thread count, bit for bit. A vertex with no particle within `R`
//! takes the value of its nearest particle (the lowest input index on a tie). An isolated
//! particle's sphere takes its particle's value.
//!
//! A constant attribute is reproduced exactly (to f32 rounding); a linear one,
//! `a(x) = A·x + b`, comes out as `A·x̄ + b` with `x̄` the kernel-weighted mean position,
//! which lies within `R` of the vertex: the error is at most `‖A‖·R`.

/// Per-item values of one named attribute: per particle, per mesh vertex or per sphere
/// instance, `components` floats each.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Attribute {
    /// Name as in the input file (`velocity`, `density`, ...).
    pub name: String,
    /// Components per item (1 for scalars, 3 for vectors).
    pub components: usize,
    /// `components × items` values, item-major.
    pub values: Vec<f32>,
}

impl Attribute {
    /// Number of items (particles, vertices or instances) the attribute holds.
    pub fn len(&self) -> usize {
        self.values.len().checked_div(self.components).unwrap_or(0)
    }

    /// True when the attribute holds no item.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The values of item `i`.
    pub fn item(&self, i: usize) -> &[f32] {
        &self.values[i * self.components..(i + 1) * self.components]
    }
}
