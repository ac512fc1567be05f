//! Particle readers.
use glam::Vec3;

/// A per-particle attribute kept from the input (for example `velocity`).
#[derive(Clone, Debug, PartialEq)]
pub struct PointAttribute {
    /// Attribute name as in the file (`velocity`, `id`, ...).
    pub name: String,
    /// Components per particle (1 for scalars, 3 for vectors).
    pub components: usize,
    /// `components * particle_count` values, particle-major.
    pub values: Vec<f32>,
}

/// The particles of one frame: positions in world units plus optional attributes.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Particles {
    /// Particle centres, world units.
    pub positions: Vec<Vec3>,
    /// Other point attributes found in the file, in file order.
    pub attributes: Vec<PointAttribute>,
}
