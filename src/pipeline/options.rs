//! The options of one reconstruction: one tree of the stages' own options, each type with
//! its documented defaults and its own checks ([`ReconstructOptions::validate`] runs them
//! all), and four presets spelled out field by field: [`ReconstructOptions::new`]
//! (meniscus's defaults for a still), [`ReconstructOptions::steady`] (the surface for
//! animations: steady from frame to frame), [`ReconstructOptions::paper`] (Akinci et al.
//! 2013 exactly) and [`ReconstructOptions::raw`] (marching cubes alone). The settings of the command line and
//! the Python package ([`crate::settings`]) read their defaults from here.

use crate::containment::ContainmentOptions;
use crate::decimation::DecimateOptions;
use crate::error::Result;
use crate::field::{FieldOptions, Kernel};
use crate::marching_cubes::STITCH_BYTES_PER_TRIANGLE;
use crate::mesh::MESH_BYTES_PER_TRIANGLE;
use crate::shading::ShadingOptions;
use crate::smoothing::SmoothOptions;
use crate::subdivision::SubdivideOptions;
use crate::tiles::{OutputCost, TileOptions};

/// Fraction of the triangles the default decimation removes. Above the paper's 0.8: the
/// default anisotropic surface sits on the outer particles instead of inside them, so it
/// is larger and marching cubes gives it about 2 % more triangles; 0.81 keeps the default
/// output at most as large as the isotropic 0.8 surface on the shipped frames
/// (`docs/quality.md`).
pub const DEFAULT_DECIMATION: f32 = 0.81;

/// Error bound of the default decimation, multiples of the particle radius: no collapse
/// moves the surface by more than this (RMS distance to the original planes), so where
/// the fraction would take more (thin sheets and filaments of violent splashes),
/// decimation stops short of it. Unbounded, decimation collapses one-particle sheets into
/// fins that cross the surface elsewhere; particle centres then end up outside where no
/// local measure can tell (see [`crate::containment`]). On calm frames it does not bind:
/// dam break frame 25, the analytic sphere and box come out the same.
pub const DEFAULT_DECIMATION_ERROR: f32 = 0.1;

/// Marching-cubes cell of the steady surface ([`ReconstructOptions::steady`]), multiples
/// of `r`: fine enough that the lattice's own noise is small and regular, so that a few
/// plain smoothing steps remove it (`docs/quality.md`, "Steady in motion").
pub const STEADY_CELL_SIZE: f32 = 0.71;

/// Plain Laplacian steps of the steady surface, on the marching-cubes mesh.
pub const STEADY_SMOOTHING_STEPS: u32 = 10;

/// Farthest the steady surface's smoothing moves a vertex inwards, multiples of `r`:
/// the marching-cubes surface holds every centre about a coverage radius (0.9 r) deep,
/// so the containment depth (0.25 r) is kept where the steps would shrink a tip, a thin
/// sheet or a small drop further. 0.2 (0.35 until 2026-12-02): the blocks' edges and the
/// crests stay nearer the particles (|d − r| within 0.9× splashsurf smoothed's on 9
/// of the 11 shipped frames instead of 4) while the sphere's lattice bumps still go
/// (normal error 5.3°; a tighter bound leaves them: `docs/quality.md`).
pub const STEADY_MAX_INWARD: f32 = 0.2;

/// Feature angle of the steady surface's smoothing, degrees
/// ([`SmoothOptions::feature_angle`]): its inward moves fade across the edges of resting
/// blocks and crests, whose normals differ by more than this on the guidance copy, and
/// the flat faces' noise still goes (dam break frame 1's block edges and the sphere's
/// lattice bumps together: `docs/quality.md`, "Guided feature weights").
pub const STEADY_FEATURE_ANGLE: f32 = 7.0;

/// Iso-surface offset of the steady surface, multiples of `r`: the smoothed surface sits
/// about 0.04 r further out than the particles' shell (it flattens the crests between
/// them less than their tops), so the field's level is taken this much further in.
pub const STEADY_ISO_OFFSET: f32 = -0.05;

/// Smoothing steps of the steady surface's shading normals.
pub const STEADY_NORMAL_SMOOTHING: u32 = 3;

/// Options of the whole pipeline, one field per stage. [`Self::new`] gives meniscus's
/// defaults, [`Self::paper`] the pipeline of Akinci et al. 2013 exactly, [`Self::raw`] the
/// marching-cubes surface alone; change fields of one of them.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
#[non_exhaustive]
pub struct ReconstructOptions {
    /// Field parameters (particle radius, influence radius, cell size, kernel, coverage).
    pub field: FieldOptions,
    /// Icosphere subdivision level for isolated particles, or `None` to keep isolated
    /// particles in the field like any other. Default `Some(2)` (320 triangles).
    pub isolated_sphere_level: Option<u32>,
    /// How the lattice is cut into tiles. Default: one tile.
    pub tiles: TileOptions,
    /// Quadric decimation, or `None` to skip it. Default: remove [`DEFAULT_DECIMATION`]
    /// of the triangles, no collapse beyond [`DEFAULT_DECIMATION_ERROR`].
    pub decimate: Option<DecimateOptions>,
    /// Taubin smoothing after decimation, or `None` to skip it. Default: 2 steps of
    /// λ 0.3, μ −0.31 ([`SmoothOptions::default`]).
    pub smooth: Option<SmoothOptions>,
    /// Loop subdivision steps after decimation. Default 1 (0 skips it).
    pub subdivide: SubdivideOptions,
    /// Loop subdivision steps left to whoever decodes the surface (a `.mseq` archive
    /// stores the control mesh and subdivides on decoding): not run here, but the
    /// containment stage measures the surface as it will be decoded. Default 0.
    pub deferred_subdivision: u32,
    /// Keeping every non-isolated particle centre under the surface after decimation,
    /// smoothing and subdivision, or `None` to leave the surface as they made it.
    /// Default: at least 0.25 r deep ([`ContainmentOptions::default`]).
    pub containment: Option<ContainmentOptions>,
    /// The shading normals written with the surface. Default: area-weighted
    /// ([`ShadingOptions::default`]).
    pub shading: ShadingOptions,
}

/// The fraction of triangles the memory estimate assumes a decimation without a triangle
/// target (an error bound alone) removes: its result is not known before it runs.
const ASSUMED_BOUNDED_REDUCTION: f32 = 0.8;

impl ReconstructOptions {
    /// meniscus's defaults for particle radius `r` (world units): the paper's stages, with
    /// anisotropic kernels ([`Kernel::Anisotropic`]) and the coverage balls of
    /// [`FieldOptions::new`], decimation by [`DEFAULT_DECIMATION`] within
    /// [`DEFAULT_DECIMATION_ERROR`], Taubin smoothing ([`SmoothOptions::default`]), every
    /// non-isolated centre kept inside ([`ContainmentOptions::default`]), one Loop step,
    /// icospheres of level 2.
    pub fn new(particle_radius: f32) -> Self {
        let mut field = FieldOptions::new(particle_radius);
        field.kernel = Kernel::Anisotropic;
        let decimate = DecimateOptions {
            target_reduction: Some(DEFAULT_DECIMATION),
            max_error: Some(DEFAULT_DECIMATION_ERROR * particle_radius),
            ..DecimateOptions::default()
        };
        ReconstructOptions {
            field,
            isolated_sphere_level: Some(2),
            tiles: TileOptions::default(),
            decimate: Some(decimate),
            smooth: Some(SmoothOptions::default()),
            subdivide: SubdivideOptions::default(),
            deferred_subdivision: 0,
            containment: Some(ContainmentOptions::default()),
            shading: ShadingOptions::default(),
        }
    }

    /// The surface for animations, steady from frame to frame, for particle radius `r`:
    /// [`Self::new`]'s field marched at the finer cell [`STEADY_CELL_SIZE`], no decimation
    /// (its triangulation changes from frame to frame, and smoothing cannot remove what
    /// that changes), the level [`STEADY_ISO_OFFSET`] further in,
    /// [`STEADY_SMOOTHING_STEPS`] plain Laplacian steps on the regular marching-cubes mesh
    /// (no vertex moved inwards by more than [`STEADY_MAX_INWARD`], the inward moves
    /// weighted by [`STEADY_FEATURE_ANGLE`]), every non-isolated
    /// centre kept inside, no subdivision,
    /// shading normals smoothed by [`STEADY_NORMAL_SMOOTHING`] steps, icospheres of
    /// level 2. Measured in `docs/quality.md` ("Steady in motion").
    pub fn steady(particle_radius: f32) -> Self {
        let mut options = Self::new(particle_radius);
        options.field.cell_size = STEADY_CELL_SIZE;
        options.field.iso_offset = STEADY_ISO_OFFSET;
        options.decimate = None;
        options.smooth = Some(SmoothOptions {
            max_inward: Some(STEADY_MAX_INWARD * particle_radius),
            feature_angle: Some(STEADY_FEATURE_ANGLE),
            ..SmoothOptions::laplacian(STEADY_SMOOTHING_STEPS)
        });
        options.subdivide = SubdivideOptions { levels: 0 };
        options.shading = ShadingOptions {
            normal_smoothing: STEADY_NORMAL_SMOOTHING,
        };
        options
    }

    /// The pipeline of Akinci et al. 2013 exactly: the Solenthaler field with isotropic
    /// kernels and no coverage balls, decimation by 80 % without an error bound, no
    /// smoothing, one Loop step, icospheres of level 2 for isolated particles, no
    /// containment.
    pub fn paper(particle_radius: f32) -> Self {
        let mut field = FieldOptions::new(particle_radius);
        field.particle_coverage = 0.0;
        ReconstructOptions {
            field,
            isolated_sphere_level: Some(2),
            tiles: TileOptions::default(),
            decimate: Some(DecimateOptions::default()),
            smooth: None,
            subdivide: SubdivideOptions::default(),
            deferred_subdivision: 0,
            containment: None,
            shading: ShadingOptions::default(),
        }
    }

    /// The marching-cubes surface of meniscus's default field ([`Self::new`]'s) and the
    /// spheres of isolated particles, with no mesh post-processing: no decimation, no
    /// smoothing, no containment, no subdivision.
    pub fn raw(particle_radius: f32) -> Self {
        ReconstructOptions {
            field: Self::new(particle_radius).field,
            isolated_sphere_level: Some(2),
            tiles: TileOptions::default(),
            decimate: None,
            smooth: None,
            subdivide: SubdivideOptions { levels: 0 },
            deferred_subdivision: 0,
            containment: None,
            shading: ShadingOptions::default(),
        }
    }

    /// Checks every stage's options ([`crate::Error::InvalidOption`] names the first
    /// wrong one by its path in this tree, e.g. `decimate.target_reduction`).
    pub fn validate(&self) -> Result<()> {
        self.field.validate()?;
        if let Some(decimate) = &self.decimate {
            decimate.validate()?;
        }
        if let Some(smooth) = &self.smooth {
            smooth.validate()?;
        }
        if let Some(containment) = &self.containment {
            containment.validate()?;
        }
        self.shading.validate()?;
        Ok(())
    }

    /// Whether the smoothing's vertex rings are held until the shading normals, which
    /// smooth over the same triangles (no subdivision between).
    pub(crate) fn keeps_rings(&self) -> bool {
        self.smooth.as_ref().is_some_and(|s| s.steps > 0)
            && self.subdivide.levels == 0
            && self.shading.normal_smoothing > 0
    }

    /// Memory the surface needs after the tiles, per marching-cubes triangle: the largest
    /// of the stages' own working sets, each at the triangle count it meets (an
    /// error-bounded decimation counts as [`ASSUMED_BOUNDED_REDUCTION`]), and what would
    /// lower it.
    pub(crate) fn post_processing_cost(&self) -> OutputCost {
        let mut triangles = 1.0;
        let mut peak = match &self.decimate {
            None => (STITCH_BYTES_PER_TRIANGLE, "decimation"),
            Some(d) => {
                triangles *= 1.0
                    - d.target_reduction
                        .unwrap_or(ASSUMED_BOUNDED_REDUCTION)
                        .clamp(0.0, 1.0) as f64;
                (triangles * MESH_BYTES_PER_TRIANGLE, "more decimation")
            }
        };
        let mut raise = |bytes: f64, advice| {
            if bytes > peak.0 {
                peak = (bytes, advice);
            }
        };
        if let Some(smooth) = &self.smooth {
            let features = match smooth.feature_angle {
                Some(_) => crate::smoothing::FEATURE_BYTES_PER_INPUT_TRIANGLE,
                None => 0.0,
            };
            raise(
                triangles * (crate::smoothing::BYTES_PER_INPUT_TRIANGLE + features),
                "no smoothing",
            );
        }
        // The smoothing's rings, held for the shading normals through containment.
        let rings = if self.keeps_rings() {
            crate::smoothing::RINGS_BYTES_PER_TRIANGLE
        } else {
            0.0
        };
        if self.containment.is_some() {
            raise(
                triangles * (crate::containment::BYTES_PER_INPUT_TRIANGLE + rings),
                "no containment",
            );
        }
        for _ in 0..self.subdivide.levels {
            raise(
                triangles * crate::subdivision::BYTES_PER_INPUT_TRIANGLE,
                "fewer subdivision steps",
            );
            triangles *= 4.0;
        }
        raise(
            triangles * MESH_BYTES_PER_TRIANGLE,
            "fewer subdivision steps",
        );
        if self.shading.normal_smoothing > 0 {
            raise(
                triangles * (MESH_BYTES_PER_TRIANGLE + crate::shading::BYTES_PER_TRIANGLE),
                "no normal smoothing",
            );
        }
        OutputCost {
            bytes_per_triangle: peak.0,
            advice: peak.1,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_advice_names_the_stage_with_the_peak() {
        let advice = |smooth: bool, contain: bool, levels: u32| {
            let mut options = ReconstructOptions::new(0.01);
            options.smooth = smooth.then(SmoothOptions::default);
            options.containment = contain.then(ContainmentOptions::default);
            options.subdivide.levels = levels;
            options.post_processing_cost()
        };
        assert!(advice(true, true, 1).advice.contains("subdivi"));
        assert!(advice(true, true, 0).advice.contains("containment"));
        assert!(advice(true, false, 0).advice.contains("smooth"));
        assert!(advice(false, false, 0).advice.contains("decimat"));
        let raw = ReconstructOptions::raw(0.01);
        assert!(raw.post_processing_cost().advice.contains("decimat"));
        // Containment below subdivision: turning it off would not help a subdivided run.
        assert_eq!(
            advice(true, true, 1).bytes_per_triangle,
            advice(true, false, 1).bytes_per_triangle
        );
    }
}
