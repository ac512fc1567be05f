//! A 3-frame particle sequence with a gap in its numbers, for the USD output's checks:
//! frames 1, 2 and 4 (`f_N.vtk`), the particles of the double dam break's frames 1, 6
//! and 9 (so the surface's topology changes every frame), each with attributes of 1 to 4
//! components: `density`, `uv`, `velocity` (mostly +Y: 2 units per second up, a little
//! along x and z, varying with the position) and `color`. Shared by the tests
//! (`support::particle_sequence`) and `examples/particle_sequence.rs` (the CI scripts).

use glam::Vec3;
use meniscus::attributes::Attribute;
use meniscus::io::particles::{read_particles, write_particles, ParticleFormat, Particles};
use std::path::{Path, PathBuf};

/// Frame numbers of the sequence, and the dataset frame each one's particles come from.
pub const FRAMES: [(i64, i64); 3] = [(1, 1), (2, 6), (4, 9)];

/// The velocity the fixture gives a particle at `p`: mostly +Y.
pub fn fixture_velocity(p: Vec3) -> Vec3 {
    Vec3::new(0.25 + 0.1 * p.x, 2.0 + 0.1 * p.y, -0.125 + 0.1 * p.z)
}

/// An attribute of `components` floats per particle, from `f` of its position.
fn field(
    name: &str,
    components: usize,
    positions: &[Vec3],
    f: impl Fn(Vec3) -> Vec<f32>,
) -> Attribute {
    let values: Vec<f32> = positions.iter().flat_map(|p| f(*p)).collect();
    assert_eq!(values.len(), components * positions.len());
    Attribute {
        name: name.into(),
        components,
        values,
    }
}

/// Writes the sequence into `dir` and returns its `{}` pattern (`DIR/f_{}.vtk`).
pub fn write_particle_sequence(dir: &Path) -> String {
    let data = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("datasets/double_dambreak");
    for (number, source) in FRAMES {
        let path = data.join(format!("ParticleData_Fluid_{source}.xyz"));
        let positions = read_particles(&path, None)
            .unwrap_or_else(|e| panic!("{e}"))
            .positions;
        let attributes = vec![
            field("density", 1, &positions, |p| vec![1000.0 + p.y]),
            field("uv", 2, &positions, |p| vec![p.x, p.z]),
            field("velocity", 3, &positions, |p| {
                fixture_velocity(p).to_array().to_vec()
            }),
            field("color", 4, &positions, |p| {
                vec![p.x, p.y, p.z, number as f32]
            }),
        ];
        let particles = Particles {
            positions,
            attributes,
        };
        let out = dir.join(format!("f_{number}.vtk"));
        write_particles(&out, &particles, ParticleFormat::Vtk).unwrap_or_else(|e| panic!("{e}"));
    }
    format!("{}/f_{{}}.vtk", dir.display())
}
