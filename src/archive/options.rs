//! The options of a new archive: its error bounds and zstd level, with their defaults.

use super::container::MAX_STEP;
use crate::error::{Error, Result};

/// Options of a new archive.
#[derive(Clone, Debug, PartialEq)]
pub struct ArchiveOptions {
    /// Largest error of any coordinate, world units (> 0). Positions are quantized with a
    /// step of twice this bound.
    pub error_bound: f64,
    /// Largest error of any attribute value (> 0), absolute, in the attribute's own units
    /// (m/s for a velocity). Values are quantized with a step of twice this bound. Default
    /// 1e-3 ([`DEFAULT_ATTRIBUTE_ERROR_BOUND`]).
    pub attribute_error_bound: f64,
    /// zstd level. Default 9.
    pub zstd_level: i32,
}

/// The default [`ArchiveOptions::attribute_error_bound`]: 1e-3 in the attribute's units.
///
/// For a velocity in m/s that is 1 mm/s: motion blur moves a vertex by the velocity
/// times the shutter time (1/48 s for a 180° shutter at 24 frames per second), so the
/// error in the blur is at most 2·10⁻⁵ m per component, well below the position bound
/// of a typical archive (0.01 r = 1.2·10⁻⁴ m for r = 12 mm) and invisible next to the
/// sub-frame motion (the `dambreak_small` fluid moves at up to about 3 m/s: 6 cm per
/// frame). It is absolute: an attribute of large magnitude (a density of 1000 kg/m³)
/// is stored far more finely than it needs (and larger) unless the bound is raised, one
/// of magnitude about 1 (or smaller) less finely than it may need.
pub const DEFAULT_ATTRIBUTE_ERROR_BOUND: f64 = 1e-3;

/// The default [`ArchiveOptions::error_bound`] of an archive of surfaces reconstructed
/// from particles, multiples of the particle radius `r` ([`default_error_bound`]).
pub const DEFAULT_ERROR_BOUND_RADII: f64 = 0.01;

/// The default [`ArchiveOptions::error_bound`] for particles of radius `particle_radius`
/// (world units): 0.01 r, with `r` taken as it is written (`0.012`, not the `f32`'s
/// 0.0120000001…). Every writer given the same radius (the CLI, the Python package, each
/// task of a farm) then uses the same bound, which archives must share to be merged, and
/// `archive info` prints the round number.
pub fn default_error_bound(particle_radius: f32) -> f64 {
    // An f32's Display is the shortest decimal that reads back as the same f32.
    let r: f64 = particle_radius
        .to_string()
        .parse()
        .unwrap_or(particle_radius as f64);
    DEFAULT_ERROR_BOUND_RADII * r
}

impl ArchiveOptions {
    /// Options with an error bound in world units, the default attribute error bound and
    /// the default zstd level.
    pub fn new(error_bound: f64) -> Self {
        ArchiveOptions {
            error_bound,
            attribute_error_bound: DEFAULT_ATTRIBUTE_ERROR_BOUND,
            zstd_level: 9,
        }
    }

    /// Both error bounds positive and small enough that twice them is a usable step.
    pub(crate) fn check(&self) -> Result<()> {
        for (option, value) in [
            ("error_bound", self.error_bound),
            ("attribute_error_bound", self.attribute_error_bound),
        ] {
            if !(value.is_finite() && value > 0.0 && 2.0 * value <= MAX_STEP) {
                return Err(Error::InvalidOption {
                    option,
                    message: format!("must be > 0 and at most {}, got {value}", MAX_STEP / 2.0),
                });
            }
        }
        Ok(())
    }
}
