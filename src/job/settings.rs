//! The job-level settings as users state them: what the CLI's `reconstruct` flags and
//! the Python package's `reconstruct_file` keywords say about a run over files besides
//! the reconstruction itself (that is [`crate::settings::ReconstructSettings`]). Both
//! front ends take their defaults from here, check with [`JobSettings::validate`] (and
//! [`check_threads`], [`parse_up_axis`], [`parse_usd_droplets`]) and build the run's [`JobOptions`] with
//! [`JobSettings::options`]; they only print or raise. The particle radius a run takes is
//! [`crate::radius::choose_radius`]'s; the memory budget, a reconstruction setting, is
//! read by [`crate::settings::parse_memory_budget`].

use super::JobOptions;
use crate::attributes::AttributeSelection;
use crate::cancel::CancelToken;
use crate::error::{Error, Result};
use crate::io::mesh::MeshWriteOptions;
use crate::io::particles::ParticleFormat;
use crate::io::usd::{UpAxis, UsdDroplets};
use crate::radius::RadiusAttribute;

/// Default playback rate of a sequence in one glTF or USD stage, frames per second.
pub const DEFAULT_FPS: f64 = 24.0;
/// Default meters in one world unit of a USD stage.
pub const DEFAULT_METERS_PER_UNIT: f64 = 1.0;

/// The settings of a run over files, in the units users give them (see the module's
/// documentation). [`Default`] holds the defaults of both front ends.
#[derive(Clone, Debug)]
pub struct JobSettings {
    /// Input format, overriding the extension. Default: by extension.
    pub input_format: Option<ParticleFormat>,
    /// Write vertex normals. Default true.
    pub normals: bool,
    /// Skip frames whose output exists, or that the `.mseq` output holds. Default false.
    pub skip_existing: bool,
    /// Error bound of a `.mseq` output, world units. Default `None`:
    /// [`crate::archive::default_error_bound`] of the particle radius.
    pub error_bound: Option<f64>,
    /// Error bound of a `.mseq` output's attributes, each in its own units. Default
    /// [`crate::archive::DEFAULT_ATTRIBUTE_ERROR_BOUND`].
    pub attribute_error_bound: f64,
    /// Playback rate of a sequence in one glTF or USD stage, frames per second (> 0).
    /// Default [`DEFAULT_FPS`].
    pub fps: f64,
    /// Up axis of a USD stage output. Default Y.
    pub up_axis: UpAxis,
    /// Meters in one world unit of a USD stage output. Default
    /// [`DEFAULT_METERS_PER_UNIT`].
    pub meters_per_unit: f64,
    /// How a USD stage output holds the isolated particles. Default points.
    pub usd_droplets: UsdDroplets,
    /// The point attributes carried to the surface. Default: the velocity, when present.
    pub attributes: AttributeSelection,
    /// The point attribute holding each particle's radius. Default Houdini's `pscale`
    /// when present.
    pub radius_attribute: RadiusAttribute,
    /// Worker threads (at least 1). Default `None`: all cores.
    pub threads: Option<usize>,
    /// Report a failed frame and go on with the next. Default false.
    pub keep_going: bool,
}

impl Default for JobSettings {
    fn default() -> Self {
        JobSettings {
            input_format: None,
            normals: true,
            skip_existing: false,
            error_bound: None,
            attribute_error_bound: crate::archive::DEFAULT_ATTRIBUTE_ERROR_BOUND,
            fps: DEFAULT_FPS,
            up_axis: UpAxis::default(),
            meters_per_unit: DEFAULT_METERS_PER_UNIT,
            usd_droplets: UsdDroplets::default(),
            attributes: AttributeSelection::default(),
            radius_attribute: RadiusAttribute::default(),
            threads: None,
            keep_going: false,
        }
    }
}

impl JobSettings {
    /// Checks the settings the library's stages do not: `threads` ([`check_threads`])
    /// then `fps` (finite and > 0), as [`Error::InvalidOption`] naming the setting.
    pub fn validate(&self) -> Result<()> {
        check_threads(self.threads)?;
        check_fps(self.fps)
    }

    /// The run's [`JobOptions`] for particles of radius `particle_radius` (world units;
    /// it sets the default archive error bound), stopped by `cancel`.
    pub fn options(&self, particle_radius: f32, cancel: &CancelToken) -> JobOptions {
        JobOptions {
            input_format: self.input_format,
            write: MeshWriteOptions {
                normals: self.normals,
                ..MeshWriteOptions::default()
            },
            skip_existing: self.skip_existing,
            archive_error_bound: self
                .error_bound
                .unwrap_or(crate::archive::default_error_bound(particle_radius)),
            archive_attribute_error_bound: self.attribute_error_bound,
            fps: self.fps,
            up_axis: self.up_axis,
            meters_per_unit: self.meters_per_unit,
            usd_droplets: self.usd_droplets,
            attributes: self.attributes.clone(),
            radius_attribute: self.radius_attribute.clone(),
            cancel: cancel.clone(),
            keep_going: self.keep_going,
        }
    }
}

/// Checks a worker thread count: at least 1 ([`Error::InvalidOption`] `threads`).
pub fn check_threads(threads: Option<usize>) -> Result<()> {
    if threads == Some(0) {
        return Err(Error::InvalidOption {
            option: "threads",
            message: "must be at least 1, got 0".into(),
        });
    }
    Ok(())
}

/// Checks a playback rate: finite and > 0 ([`Error::InvalidOption`] `fps`).
pub fn check_fps(fps: f64) -> Result<()> {
    if !(fps.is_finite() && fps > 0.0) {
        return Err(Error::InvalidOption {
            option: "fps",
            message: format!("must be > 0 (frames per second), got {fps}"),
        });
    }
    Ok(())
}

/// How a USD stage holds the isolated particles, as users write it: `points` or
/// `instancer` ([`Error::InvalidOption`] `usd_droplets`).
pub fn parse_usd_droplets(text: &str) -> Result<UsdDroplets> {
    text.parse().map_err(|message| Error::InvalidOption {
        option: "usd_droplets",
        message,
    })
}

/// An up axis as users write it: `Y` or `Z`, either case ([`Error::InvalidOption`]
/// `up_axis`).
pub fn parse_up_axis(text: &str) -> Result<UpAxis> {
    text.parse().map_err(|message| Error::InvalidOption {
        option: "up_axis",
        message,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn option_of(e: Error) -> &'static str {
        match e {
            Error::InvalidOption { option, .. } => option,
            e => panic!("{e}"),
        }
    }

    #[test]
    fn bad_settings_are_named_as_both_front_ends_show_them() {
        let mut s = JobSettings {
            threads: Some(0),
            fps: 0.0,
            ..JobSettings::default()
        };
        let e = s.validate().unwrap_err();
        assert_eq!(e.to_string(), "invalid threads: must be at least 1, got 0");
        s.threads = Some(2);
        let e = s.validate().unwrap_err();
        assert_eq!(
            e.to_string(),
            "invalid fps: must be > 0 (frames per second), got 0"
        );
        for fps in [f64::NAN, f64::INFINITY, -1.0] {
            s.fps = fps;
            assert_eq!(option_of(s.validate().unwrap_err()), "fps");
        }
        s.fps = 30.0;
        assert!(s.validate().is_ok());
        assert_eq!(option_of(parse_up_axis("X").unwrap_err()), "up_axis");
        assert_eq!(parse_up_axis("z").unwrap(), UpAxis::Z);
        assert_eq!(
            option_of(parse_usd_droplets("mesh").unwrap_err()),
            "usd_droplets"
        );
        assert_eq!(
            parse_usd_droplets("instancer").unwrap(),
            UsdDroplets::Instancer
        );
    }

    #[test]
    fn the_archive_bound_defaults_to_the_radius() {
        let cancel = CancelToken::new();
        let s = JobSettings::default();
        let job = s.options(0.5, &cancel);
        assert_eq!(
            job.archive_error_bound,
            crate::archive::default_error_bound(0.5)
        );
        assert!(job.write.normals);
        let given = JobSettings {
            error_bound: Some(0.25),
            normals: false,
            ..s
        };
        let job = given.options(0.5, &cancel);
        assert_eq!(job.archive_error_bound, 0.25);
        assert!(!job.write.normals);
    }
}
