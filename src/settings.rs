//! The reconstruction options as users state them: the flags of `meniscus reconstruct`
//! and the keywords of the Python package, with the same names, defaults and units
//! (lengths in multiples of the particle radius `r`, decimation as a fraction, `adaptive`
//! or off). [`ReconstructSettings::options`] turns them into the pipeline's
//! [`ReconstructOptions`]; every front end goes through it, so none can drift from the
//! others.

use crate::containment::ContainmentOptions;
use crate::decimation::DecimateOptions;
use crate::error::{Error, Result};
use crate::field::Kernel;
use crate::pipeline::{ReconstructOptions, DEFAULT_DECIMATION_ERROR};
use crate::shading::ShadingOptions;
use crate::smoothing::SmoothOptions;
use std::path::{Path, PathBuf};

/// A named set of defaults, which the settings given beside it override.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Preset {
    /// The best still frame ([`ReconstructOptions::new`]): decimated, Taubin-smoothed and
    /// subdivided. The default for one particle file.
    Still,
    /// The surface for animation ([`ReconstructOptions::steady`]): marched finer, no
    /// decimation, bounded Laplacian smoothing and smoothed shading normals, so that the
    /// shading does not flicker from frame to frame. The default for a sequence.
    Steady,
    /// The pipeline of Akinci et al. 2013 exactly ([`ReconstructOptions::paper`]).
    Paper,
}

impl Preset {
    /// Every preset, in the order the front ends list them.
    pub const ALL: [Preset; 3] = [Preset::Still, Preset::Steady, Preset::Paper];

    /// The preset's settings for particles of radius `particle_radius` (world units).
    pub fn settings(self, particle_radius: f32) -> ReconstructSettings {
        match self {
            Preset::Still => ReconstructSettings::new(particle_radius),
            Preset::Steady => ReconstructSettings::steady(particle_radius),
            Preset::Paper => ReconstructSettings::paper(particle_radius),
        }
    }

    /// The preset a run on `input` takes when none is named: [`Preset::Steady`] for a
    /// sequence (a pattern with `{}`, or a ParaView collection `.pvd`), whatever frames
    /// of it are chosen, so that every task of a farm makes the same surface;
    /// [`Preset::Still`] for one particle file.
    pub fn for_input(input: &Path) -> Preset {
        let is_collection = input
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("pvd"));
        match input.to_string_lossy().contains("{}") || is_collection {
            true => Preset::Steady,
            false => Preset::Still,
        }
    }
}

impl std::str::FromStr for Preset {
    type Err = String;

    /// `still`, `steady` or `paper`.
    fn from_str(text: &str) -> std::result::Result<Self, String> {
        Preset::ALL
            .into_iter()
            .find(|p| p.to_string() == text)
            .ok_or_else(|| format!("takes `still`, `steady` or `paper`, got {text:?}"))
    }
}

impl std::fmt::Display for Preset {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Preset::Still => "still",
            Preset::Steady => "steady",
            Preset::Paper => "paper",
        })
    }
}

/// How the smoothing steps move each vertex.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SmoothMethod {
    /// Taubin's λ|μ steps: little shrinkage, but the finest noise stays.
    Taubin,
    /// Plain Laplacian steps (each vertex to its neighbours' mean): removes the noise
    /// and shrinks, which an inward bound (`smooth_max_inward`) holds back.
    Laplacian,
}

impl std::str::FromStr for SmoothMethod {
    type Err = String;

    /// `taubin` or `laplacian`.
    fn from_str(text: &str) -> std::result::Result<Self, String> {
        match text {
            "taubin" => Ok(SmoothMethod::Taubin),
            "laplacian" => Ok(SmoothMethod::Laplacian),
            other => Err(format!("takes `taubin` or `laplacian`, got {other:?}")),
        }
    }
}

impl std::fmt::Display for SmoothMethod {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            SmoothMethod::Taubin => "taubin",
            SmoothMethod::Laplacian => "laplacian",
        })
    }
}

/// How much quadric decimation removes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Decimation {
    /// No decimation.
    Off,
    /// Remove this fraction of the triangles, in `[0, 1)` (0.8 is the paper's, 0.81 the
    /// default).
    Fraction(f32),
    /// Stop on the error bound only (`decimate_error`; without one
    /// [`DEFAULT_DECIMATION_ERROR`]): flat regions simplify, curved ones keep their
    /// triangles.
    Adaptive,
}

impl std::str::FromStr for Decimation {
    type Err = String;

    /// `0.8` (a fraction in `[0, 1)`), `adaptive`, or `off` (also `none` and `0`).
    fn from_str(text: &str) -> std::result::Result<Self, String> {
        match text {
            "off" | "none" | "0" => Ok(Decimation::Off),
            "adaptive" => Ok(Decimation::Adaptive),
            fraction => fraction
                .parse()
                .ok()
                .filter(|f: &f32| (0.0..1.0).contains(f))
                .map(Decimation::Fraction)
                .ok_or_else(|| {
                    format!("takes a fraction in [0, 1), `adaptive` or `off`, got {fraction:?}")
                }),
        }
    }
}

impl std::fmt::Display for Decimation {
    /// As [`FromStr`](std::str::FromStr) reads it: the fraction, `adaptive` or `off`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Decimation::Off => f.write_str("off"),
            Decimation::Fraction(x) => write!(f, "{x}"),
            Decimation::Adaptive => f.write_str("adaptive"),
        }
    }
}

/// The reconstruction settings as the front ends name them, in the order of the Python
/// stubs (`python/meniscus.pyi`): the fields of [`ReconstructSettings`] but
/// `particle_radius`, which are the Python package's keywords and, with `-` for `_`, the
/// flags of `meniscus reconstruct` (every one but `defer_subdivision`, which the CLI sets
/// by itself for a `.mseq` output). A new setting is a field, its line here, its flag and
/// its keyword: the CLI's test (every setting is a flag) and the Python package's
/// `test_settings_agree.py` (the same names, defaults and units in the CLI, the package,
/// the stubs and the README) fail until they all agree.
pub const SETTINGS: &[&str] = &[
    "influence_radius",
    "cell_size",
    "t_low",
    "t_high",
    "particle_coverage",
    "iso_offset",
    "kernel",
    "kernel_radius",
    "max_stretch",
    "min_neighbours",
    "centre_smoothing",
    "isolated_spheres",
    "decimate",
    "decimate_error",
    "smooth",
    "smooth_method",
    "smooth_max_inward",
    "smooth_feature_angle",
    "subdivide",
    "defer_subdivision",
    "keep_inside",
    "normal_smoothing",
    "tile_size",
    "memory_budget",
    "temp_dir",
];

/// A memory budget as users write it (`512MiB`, `2GiB`, `2GB`, bytes; see
/// [`crate::tiles::parse_memory_size`]), in bytes, for
/// [`ReconstructSettings::memory_budget`] ([`Error::InvalidOption`] `memory_budget`).
pub fn parse_memory_budget(text: &str) -> Result<u64> {
    crate::tiles::parse_memory_size(text).map_err(|message| Error::InvalidOption {
        option: "memory_budget",
        message,
    })
}

/// The options of one reconstruction in the units users give them. [`Self::new`] holds
/// the defaults of the CLI and the Python package, [`Self::paper`] the pipeline of
/// Akinci et al. 2013 exactly.
#[derive(Clone, Debug, PartialEq)]
pub struct ReconstructSettings {
    /// Particle radius `r`, world units (half the rest spacing).
    pub particle_radius: f32,
    /// Influence radius `R`, multiples of `r`. Default 4.
    pub influence_radius: f32,
    /// Marching-cubes cell size `h`, multiples of `r`. Default 1.
    pub cell_size: f32,
    /// Lower eigenvalue threshold of the concavity factor. Default 0.4.
    pub t_low: f32,
    /// Upper eigenvalue threshold of the concavity factor. Default 3.5.
    pub t_high: f32,
    /// Coverage radius, multiples of `r` (0: off). Default 0.9.
    pub particle_coverage: f32,
    /// Iso-surface offset, multiples of `r`. Default 0.
    pub iso_offset: f32,
    /// Particle kernel. Default [`Kernel::Anisotropic`] ([`Kernel::Isotropic`] is the
    /// paper's).
    pub kernel: Kernel,
    /// Anisotropic kernels: radius `h_a` of an unstretched kernel, multiples of `r`.
    /// Default 3.5.
    pub kernel_radius: f32,
    /// Anisotropic kernels: largest ratio of the longest to the shortest axis. Default 1.75.
    pub max_stretch: f32,
    /// Anisotropic kernels: fewest neighbours within `R` for a stretched kernel. Default 8.
    pub min_neighbours: u32,
    /// Anisotropic kernels: centre smoothing `λ` in `[0, 1]`. Default 0.
    pub centre_smoothing: f32,
    /// Icosphere level of the spheres of isolated particles, or `None` to leave them in
    /// the field. Default `Some(2)`.
    pub isolated_spheres: Option<u32>,
    /// Decimation. Default a fraction of [`DEFAULT_DECIMATION`](crate::pipeline::DEFAULT_DECIMATION) (0.81; the paper's is 0.8).
    pub decimate: Decimation,
    /// Error bound of decimation, multiples of `r`: no collapse moves the surface by more;
    /// with a fraction, whichever is reached first stops it. `None`: no bound. Default
    /// [`DEFAULT_DECIMATION_ERROR`] (0.1).
    pub decimate_error: Option<f32>,
    /// Smoothing steps after decimation (0: none). Default 2
    /// ([`crate::smoothing::SmoothOptions`]); the steady preset's 10.
    pub smooth: u32,
    /// How the smoothing steps move the vertices. Default [`SmoothMethod::Taubin`]; the
    /// steady preset's [`SmoothMethod::Laplacian`].
    pub smooth_method: SmoothMethod,
    /// Farthest smoothing may move a vertex inwards, multiples of `r`, or `None` for no
    /// bound. Default `None`; the steady preset's 0.2.
    pub smooth_max_inward: Option<f32>,
    /// Feature weights of the smoothing's inward moves, degrees, or `None` for plain
    /// steps ([`SmoothOptions::feature_angle`]; Laplacian steps only): a smaller angle
    /// keeps more of the edges and crests. Default `None`; the steady preset's 7.
    pub smooth_feature_angle: Option<f32>,
    /// Loop subdivision steps after decimation. Default 1.
    pub subdivide: u32,
    /// Leave the Loop subdivision to whoever reads the surface (a `.mseq` archive's
    /// decoder, which runs `subdivide` steps): the surface comes back as the control mesh,
    /// and containment judges it as it will be subdivided. Default false.
    pub defer_subdivision: bool,
    /// Least depth of every non-isolated particle centre under the final surface,
    /// multiples of `r`, or `None` to leave the surface as decimation and subdivision made
    /// it. Default `Some(0.25)`.
    pub keep_inside: Option<f32>,
    /// Smoothing steps of the written vertex normals (0: the area-weighted normals).
    /// Default 0; the steady preset's 3 ([`ShadingOptions`]).
    pub normal_smoothing: u32,
    /// Tile edge, marching-cubes cells. Default: from the memory budget.
    pub tile_size: Option<u32>,
    /// Memory the run may use, bytes. Default `None`: half the available memory
    /// ([`crate::tiles::default_memory_budget`]).
    pub memory_budget: Option<u64>,
    /// Directory of a tiled run's spill file. Default: the system's temporary directory.
    pub temp_dir: Option<PathBuf>,
}

impl ReconstructSettings {
    /// The defaults ([`ReconstructOptions::new`]), for particles of radius
    /// `particle_radius` (world units).
    pub fn new(particle_radius: f32) -> Self {
        Self::of(&ReconstructOptions::new(1.0), particle_radius)
    }

    /// The pipeline of Akinci et al. 2013 exactly ([`ReconstructOptions::paper`]):
    /// isotropic kernels, no coverage balls, decimation by 0.8 without an error bound, no
    /// smoothing, no containment; the other settings as [`Self::new`].
    pub fn paper(particle_radius: f32) -> Self {
        Self::of(&ReconstructOptions::paper(1.0), particle_radius)
    }

    /// The surface for animation ([`ReconstructOptions::steady`]): the field marched at
    /// 0.71 r with the level 0.05 r further in, no decimation, 10 Laplacian steps that
    /// move no vertex more than 0.2 r inwards, their inward moves weighted by a feature
    /// angle of 7°, no subdivision, the normals smoothed by 3 steps; the other settings
    /// as [`Self::new`].
    pub fn steady(particle_radius: f32) -> Self {
        Self::of(&ReconstructOptions::steady(1.0), particle_radius)
    }

    /// The settings of `unit`, options for particles of radius 1 (so that its lengths
    /// are multiples of `r`), for particles of radius `particle_radius`.
    fn of(unit: &ReconstructOptions, particle_radius: f32) -> Self {
        let field = &unit.field;
        let anisotropy = &field.anisotropy;
        ReconstructSettings {
            particle_radius,
            influence_radius: field.influence_radius,
            cell_size: field.cell_size,
            t_low: field.t_low,
            t_high: field.t_high,
            particle_coverage: field.particle_coverage,
            iso_offset: field.iso_offset,
            kernel: field.kernel,
            kernel_radius: anisotropy.kernel_radius,
            max_stretch: anisotropy.max_stretch,
            min_neighbours: anisotropy.min_neighbours,
            centre_smoothing: anisotropy.centre_smoothing,
            isolated_spheres: unit.isolated_sphere_level,
            decimate: match &unit.decimate {
                None => Decimation::Off,
                Some(d) => d
                    .target_reduction
                    .map_or(Decimation::Adaptive, Decimation::Fraction),
            },
            decimate_error: unit.decimate.as_ref().and_then(|d| d.max_error),
            smooth: unit.smooth.as_ref().map_or(0, |s| s.steps),
            smooth_method: match &unit.smooth {
                Some(s) if s.mu == 0.0 => SmoothMethod::Laplacian,
                _ => SmoothMethod::Taubin,
            },
            smooth_max_inward: unit.smooth.as_ref().and_then(|s| s.max_inward),
            smooth_feature_angle: unit.smooth.as_ref().and_then(|s| s.feature_angle),
            subdivide: unit.subdivide.levels + unit.deferred_subdivision,
            defer_subdivision: unit.deferred_subdivision > 0,
            keep_inside: unit.containment.as_ref().map(|c| c.min_depth),
            normal_smoothing: unit.shading.normal_smoothing,
            tile_size: unit.tiles.tile_size_cells,
            memory_budget: unit.tiles.memory_budget_bytes,
            temp_dir: unit.tiles.temp_dir.clone(),
        }
    }

    /// The pipeline's options, checked ([`ReconstructOptions::validate`]):
    /// [`Error::InvalidOption`] names the setting (`decimate_error`,
    /// `influence_radius/cell_size`, `keep_inside`, ...).
    pub fn options(&self) -> Result<ReconstructOptions> {
        let r = self.particle_radius;
        // The one setting in other units than the option it sets: checked as given.
        if let Some(e) = self.decimate_error {
            if !(e.is_finite() && e > 0.0) {
                return Err(Error::InvalidOption {
                    option: "decimate_error",
                    message: format!("must be > 0 (multiples of r), got {e}"),
                });
            }
        }
        let mut options = ReconstructOptions::new(r);
        let field = &mut options.field;
        field.influence_radius = self.influence_radius;
        field.cell_size = self.cell_size;
        field.t_low = self.t_low;
        field.t_high = self.t_high;
        field.particle_coverage = self.particle_coverage;
        field.iso_offset = self.iso_offset;
        field.kernel = self.kernel;
        field.anisotropy.kernel_radius = self.kernel_radius;
        field.anisotropy.max_stretch = self.max_stretch;
        field.anisotropy.min_neighbours = self.min_neighbours;
        field.anisotropy.centre_smoothing = self.centre_smoothing;
        options.isolated_sphere_level = self.isolated_spheres;
        options.tiles.tile_size_cells = self.tile_size;
        options.tiles.memory_budget_bytes = self
            .memory_budget
            .or_else(crate::tiles::default_memory_budget);
        options.tiles.temp_dir = self.temp_dir.clone();
        if let Some(d) = self.smooth_max_inward {
            if !(d.is_finite() && d > 0.0) {
                return Err(Error::InvalidOption {
                    option: "smooth_max_inward",
                    message: format!("must be > 0 (multiples of r), got {d}"),
                });
            }
        }
        // Checked as given: with no smoothing steps there is no smoothing to check it.
        if let Some(angle) = self.smooth_feature_angle {
            let method = self.smooth_method.to_string();
            crate::smoothing::check_feature_angle(angle, &method).map_err(|message| {
                Error::InvalidOption {
                    option: "smooth_feature_angle",
                    message,
                }
            })?;
        }
        options.smooth = (self.smooth > 0).then(|| SmoothOptions {
            max_inward: self.smooth_max_inward.map(|d| d * r),
            feature_angle: self.smooth_feature_angle,
            ..match self.smooth_method {
                SmoothMethod::Taubin => SmoothOptions::steps(self.smooth),
                SmoothMethod::Laplacian => SmoothOptions::laplacian(self.smooth),
            }
        });
        options.shading = ShadingOptions {
            normal_smoothing: self.normal_smoothing,
        };
        options.subdivide.levels = self.subdivide;
        if self.defer_subdivision {
            options.deferred_subdivision = self.subdivide;
            options.subdivide.levels = 0;
        }
        options.containment = self.keep_inside.map(|depth| ContainmentOptions {
            min_depth: depth,
            ..Default::default()
        });
        let max_error = self.decimate_error.map(|e| e * r);
        options.decimate = match self.decimate {
            Decimation::Off => None,
            Decimation::Adaptive => Some(DecimateOptions {
                target_reduction: None,
                max_error: Some(max_error.unwrap_or(DEFAULT_DECIMATION_ERROR * r)),
                ..Default::default()
            }),
            Decimation::Fraction(f) => Some(DecimateOptions {
                target_reduction: Some(f),
                max_error,
                ..Default::default()
            }),
        };
        options.validate().map_err(|e| match e {
            Error::InvalidOption { option, message } => Error::InvalidOption {
                option: setting_of(option),
                message,
            },
            e => e,
        })?;
        Ok(options)
    }
}

/// The setting that sets the option at `path` in [`ReconstructOptions`] (the same name
/// where they agree).
fn setting_of(path: &'static str) -> &'static str {
    match path {
        "decimate.target_reduction" | "decimate" => "decimate",
        "decimate.max_error" => "decimate_error",
        "containment.min_depth" => "keep_inside",
        other => other,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_defaults_are_the_pipelines() {
        let mut expected = ReconstructOptions::new(0.012);
        expected.tiles.memory_budget_bytes = crate::tiles::default_memory_budget();
        assert_eq!(ReconstructSettings::new(0.012).options().unwrap(), expected);
        let mut paper = ReconstructOptions::paper(0.012);
        paper.tiles.memory_budget_bytes = crate::tiles::default_memory_budget();
        assert_eq!(ReconstructSettings::paper(0.012).options().unwrap(), paper);
        let mut steady = ReconstructOptions::steady(0.012);
        steady.tiles.memory_budget_bytes = crate::tiles::default_memory_budget();
        assert_eq!(
            ReconstructSettings::steady(0.012).options().unwrap(),
            steady
        );
        assert_eq!(paper.field.kernel, Kernel::Isotropic);
        assert_eq!(expected.field.kernel, Kernel::Anisotropic);
    }

    #[test]
    fn decimation_is_a_fraction_adaptive_or_off() {
        assert_eq!("0.5".parse(), Ok(Decimation::Fraction(0.5)));
        assert_eq!("adaptive".parse(), Ok(Decimation::Adaptive));
        for off in ["off", "none", "0"] {
            assert_eq!(off.parse(), Ok(Decimation::Off));
        }
        for bad in ["1", "-0.1", "most", ""] {
            let e = bad.parse::<Decimation>().unwrap_err();
            assert!(
                e.contains("fraction") && e.contains(&format!("{bad:?}")),
                "{e}"
            );
        }
        let mut s = ReconstructSettings::new(0.5);
        s.decimate = Decimation::Adaptive;
        let d = s.options().unwrap().decimate.unwrap();
        assert_eq!((d.target_reduction, d.max_error), (None, Some(0.05)));
        s.decimate_error = Some(0.2);
        assert_eq!(s.options().unwrap().decimate.unwrap().max_error, Some(0.1));
        s.decimate = Decimation::Fraction(0.7);
        let d = s.options().unwrap().decimate.unwrap();
        assert_eq!((d.target_reduction, d.max_error), (Some(0.7), Some(0.1)));
        s.decimate_error = None;
        let d = s.options().unwrap().decimate.unwrap();
        assert_eq!((d.target_reduction, d.max_error), (Some(0.7), None));
        s.decimate = Decimation::Off;
        assert_eq!(s.options().unwrap().decimate, None);
    }

    /// Each field of `settings` with its value, as the pretty Debug form writes them
    /// (a field starts a line indented by four).
    fn fields(settings: &ReconstructSettings) -> Vec<(String, String)> {
        let mut fields: Vec<(String, String)> = Vec::new();
        for line in format!("{settings:#?}").lines() {
            match (line.strip_prefix("    "), fields.last_mut()) {
                (Some(field), _) if field.starts_with(|c: char| c.is_ascii_lowercase()) => {
                    let (name, value) = field.split_once(':').expect("name: value");
                    fields.push((name.to_string(), value.to_string()));
                }
                (_, Some((_, value))) => value.push_str(line.trim()),
                (_, None) => {}
            }
        }
        fields
    }

    #[test]
    fn the_settings_list_is_the_structs_fields() {
        let names: Vec<String> = fields(&ReconstructSettings::new(1.0))
            .into_iter()
            .map(|(name, _)| name)
            .filter(|name| name != "particle_radius")
            .collect();
        assert_eq!(names, SETTINGS);
    }

    #[test]
    fn every_setting_survives_the_trip_to_the_options_and_back() {
        // Each field changed from its default: one that `options` or `of` forgot comes
        // back as the default.
        let changed = ReconstructSettings {
            particle_radius: 1.0,
            influence_radius: 3.5,
            cell_size: 1.25,
            t_low: 0.5,
            t_high: 3.0,
            particle_coverage: 0.8,
            iso_offset: 0.05,
            kernel: Kernel::Isotropic,
            kernel_radius: 3.0,
            max_stretch: 1.5,
            min_neighbours: 6,
            centre_smoothing: 0.2,
            isolated_spheres: Some(1),
            decimate: Decimation::Fraction(0.5),
            decimate_error: Some(0.2),
            smooth: 1,
            smooth_method: SmoothMethod::Laplacian,
            smooth_max_inward: Some(0.3),
            smooth_feature_angle: Some(9.0),
            subdivide: 2,
            defer_subdivision: true,
            keep_inside: Some(0.5),
            normal_smoothing: 2,
            tile_size: Some(16),
            memory_budget: Some(1 << 30),
            temp_dir: Some("spill".into()),
        };
        let defaults = fields(&ReconstructSettings::new(1.0));
        for ((name, value), (_, default)) in fields(&changed).iter().zip(&defaults).skip(1) {
            assert_ne!(value, default, "{name} is changed");
        }
        let back = ReconstructSettings::of(&changed.options().unwrap(), 1.0);
        assert_eq!(back, changed);
    }

    #[test]
    fn bad_settings_are_named() {
        let name = |s: ReconstructSettings| match s.options() {
            Err(Error::InvalidOption { option, .. }) => option,
            other => panic!("{other:?}"),
        };
        let mut s = ReconstructSettings::new(0.01);
        s.decimate_error = Some(0.0);
        assert_eq!(name(s), "decimate_error");
        let mut s = ReconstructSettings::new(0.01);
        s.decimate = Decimation::Fraction(1.0);
        assert_eq!(name(s), "decimate");
        assert_eq!(name(ReconstructSettings::new(-1.0)), "particle_radius");
        let mut s = ReconstructSettings::new(0.01);
        s.smooth_max_inward = Some(-0.1);
        assert_eq!(name(s), "smooth_max_inward");
        for (angle, method) in [
            (0.0, SmoothMethod::Laplacian),
            (f32::NAN, SmoothMethod::Laplacian),
            (7.0, SmoothMethod::Taubin),
        ] {
            let mut s = ReconstructSettings::new(0.01);
            s.smooth_feature_angle = Some(angle);
            s.smooth_method = method;
            assert_eq!(name(s), "smooth_feature_angle");
        }
        let e = parse_memory_budget("2g").unwrap_err();
        assert!(e.to_string().starts_with("invalid memory_budget: "), "{e}");
        assert_eq!(parse_memory_budget("2KiB").unwrap(), 2048);
    }

    #[test]
    fn a_sequence_takes_the_steady_preset_and_one_file_the_still() {
        for (input, preset) in [
            ("frames/fluid_{}.bgeo", Preset::Steady),
            ("run/collection.PVD", Preset::Steady),
            ("frames/fluid_0040.bgeo", Preset::Still),
            ("pvd/fluid.vtu", Preset::Still),
        ] {
            assert_eq!(Preset::for_input(Path::new(input)), preset, "{input}");
        }
        for preset in Preset::ALL {
            assert_eq!(preset.to_string().parse(), Ok(preset));
        }
        let e = "smooth".parse::<Preset>().unwrap_err();
        assert!(e.contains("steady") && e.contains("\"smooth\""), "{e}");
        assert_eq!(
            Preset::Steady.settings(0.5),
            ReconstructSettings::steady(0.5)
        );
    }
}
