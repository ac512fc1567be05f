//! The flags of `meniscus reconstruct`. Every reconstruction flag's default comes from
//! the library's [`ReconstructSettings`], every job flag's from
//! [`meniscus::job::JobSettings`].

use crate::cli::{FarmArgs, StageArgs};
use clap::Args;
use meniscus::io::particles::ParticleFormat;
use meniscus::settings::{Preset, ReconstructSettings, SmoothMethod};
use std::path::PathBuf;

#[derive(Args)]
pub(crate) struct ReconstructArgs {
    /// Particle file (.xyz, .vtk, .vtu, .vtp, .ply, .bgeo), or a sequence: a pattern with
    /// `{}` for the frame number, or a ParaView collection (.pvd; frames 0, 1, 2, … by
    /// timestep).
    pub(crate) input: String,
    /// Output mesh (.glb, .gltf, .ply, .obj, .vtk); a pattern with `{}` for sequences.
    #[arg(short, long)]
    pub(crate) output: String,
    /// Particle radius r, world units (half the rest spacing). Default: estimated from
    /// the first frame's spacing (printed). A given r far from that estimate is warned
    /// about (outside 0.25×–4×) or refused (outside 0.05×–20×).
    #[arg(allow_negative_numbers = true, short = 'r', long)]
    pub(crate) particle_radius: Option<f32>,
    /// Take `-r` as given, without comparing it with the particles' spacing.
    #[arg(long)]
    pub(crate) no_radius_check: bool,
    /// The point attribute holding each particle's radius (`none`: ignore it). Default:
    /// Houdini's `pscale` when the input has it. Without `-r`, r is its median; a given
    /// `-r` is checked against that median.
    #[arg(long, value_name = "NAME")]
    pub(crate) radius_attribute: Option<meniscus::radius::RadiusAttribute>,
    /// The radius the run uses: `-r`, or the estimate.
    #[arg(skip)]
    pub(crate) radius: f32,
    /// Influence radius R, multiples of r.
    #[arg(allow_negative_numbers = true, long, default_value_t = defaults().influence_radius)]
    pub(crate) influence_radius: f32,
    #[arg(allow_negative_numbers = true, short = 'c', long, help = with_defaults(CELL_SIZE_HELP, |s| s.cell_size))]
    pub(crate) cell_size: Option<f32>,
    /// Lower eigenvalue threshold t_low of the Solenthaler concavity factor (isotropic
    /// kernel).
    #[arg(long, default_value_t = defaults().t_low)]
    pub(crate) t_low: f32,
    /// Upper eigenvalue threshold t_high of the Solenthaler concavity factor (isotropic
    /// kernel).
    #[arg(long, default_value_t = defaults().t_high)]
    pub(crate) t_high: f32,
    /// Icosphere subdivision level for isolated particles (no neighbour within R), or
    /// `off` to leave them in the field.
    #[arg(long, default_value_t = off_or(defaults().isolated_spheres))]
    pub(crate) isolated_spheres: String,
    #[arg(long, help = with_defaults(DECIMATE_HELP, |s| s.decimate))]
    pub(crate) decimate: Option<String>,
    #[arg(long, allow_hyphen_values = true, help = with_defaults(DECIMATE_ERROR_HELP, |s| off_or(s.decimate_error)))]
    pub(crate) decimate_error: Option<String>,
    #[arg(long, help = with_defaults(SMOOTH_HELP, |s| s.smooth))]
    pub(crate) smooth: Option<u32>,
    #[arg(long, help = with_defaults(SMOOTH_METHOD_HELP, |s| s.smooth_method))]
    pub(crate) smooth_method: Option<SmoothMethod>,
    #[arg(long, allow_hyphen_values = true, help = with_defaults(SMOOTH_MAX_INWARD_HELP, |s| off_or(s.smooth_max_inward)))]
    pub(crate) smooth_max_inward: Option<String>,
    #[arg(long, help = with_defaults(SMOOTH_FEATURE_ANGLE_HELP, |s| off_or(s.smooth_feature_angle)))]
    pub(crate) smooth_feature_angle: Option<String>,
    #[arg(long, help = with_defaults(SUBDIVIDE_HELP, |s| s.subdivide))]
    pub(crate) subdivide: Option<u32>,
    #[arg(long, help = with_defaults(KEEP_INSIDE_HELP, |s| off_or(s.keep_inside)))]
    pub(crate) keep_inside: Option<String>,
    #[arg(long, help = with_defaults(NORMAL_SMOOTHING_HELP, |s| s.normal_smoothing))]
    pub(crate) normal_smoothing: Option<u32>,
    #[arg(allow_negative_numbers = true, long, help = with_defaults(COVERAGE_HELP, |s| s.particle_coverage))]
    pub(crate) particle_coverage: Option<f32>,
    #[arg(long, allow_negative_numbers = true, help = with_defaults(ISO_OFFSET_HELP, |s| s.iso_offset))]
    pub(crate) iso_offset: Option<f32>,
    #[arg(long, value_enum, help = with_defaults(KERNEL_HELP, |s| kernel_name(s.kernel)))]
    pub(crate) kernel: Option<KernelArg>,
    /// The defaults the other flags start from (any flag given beside it wins): `still`
    /// (the best still frame), `steady` (for animation: shading that does not flicker
    /// from frame to frame) or `paper` (Akinci et al. 2013 exactly). Default: `steady`
    /// for a sequence (a `{}` pattern or a `.pvd`), `still` for one file.
    #[arg(long, value_name = "PRESET", conflicts_with = "paper")]
    pub(crate) preset: Option<Preset>,
    /// `--preset paper`: the pipeline of Akinci et al. 2013 exactly (`--kernel isotropic
    /// --particle-coverage 0 --decimate 0.8 --decimate-error off --smooth 0 --keep-inside
    /// off`).
    #[arg(long)]
    pub(crate) paper: bool,
    /// Anisotropic kernels: radius h_a of an unstretched kernel, multiples of r.
    #[arg(long, default_value_t = defaults().kernel_radius)]
    pub(crate) kernel_radius: f32,
    /// Anisotropic kernels: largest ratio of the longest to the shortest axis (k_r).
    #[arg(long, default_value_t = defaults().max_stretch)]
    pub(crate) max_stretch: f32,
    /// Anisotropic kernels: fewest neighbours within R for a stretched kernel (N_ε).
    #[arg(long, default_value_t = defaults().min_neighbours)]
    pub(crate) min_neighbours: u32,
    /// Anisotropic kernels: centre smoothing λ in [0, 1] (0 = the particle positions).
    #[arg(long, default_value_t = defaults().centre_smoothing)]
    pub(crate) centre_smoothing: f32,
    /// Tile edge in marching-cubes cells (rounded up to 8-cell blocks); default: one tile
    /// if the scene fits the memory budget, else the largest tile that does. The
    /// marching-cubes mesh does not depend on it.
    #[arg(long)]
    pub(crate) tile_size: Option<u32>,
    /// Memory the run may use: `512MiB`, `2GiB` (powers of 2), `2GB` (powers of 10) or
    /// plain bytes; a bare `2g` or `512M` is refused as ambiguous. Default half the
    /// available memory. Picks the tile size; a run whose smallest tile cannot fit fails
    /// before any work.
    #[arg(long)]
    pub(crate) memory_budget: Option<String>,
    /// Directory for the spill file of a tiled run (default: the system's temporary
    /// directory); removed on success, error and Ctrl-C.
    #[arg(long)]
    pub(crate) temp_dir: Option<PathBuf>,
    /// Input format, overriding the extension (xyz, vtk, vtu, vtp, ply, bgeo).
    #[arg(long)]
    pub(crate) input_format: Option<ParticleFormat>,
    #[command(flatten)]
    pub(crate) farm: FarmArgs,
    /// Skip frames whose output already exists, or that the `.mseq` output holds (the
    /// others are appended).
    #[arg(long)]
    pub(crate) skip_existing: bool,
    /// Print one JSON line per finished frame on stdout (frame, input, output, status
    /// done/skipped/failed, triangles, seconds, peak_rss_bytes, error), for farm managers.
    #[arg(long)]
    pub(crate) json_progress: bool,
    /// Report a frame that fails and go on with the next (default: stop at the first).
    /// The exit status is 1 when any frame failed; a `.mseq` output keeps the others.
    #[arg(long)]
    pub(crate) keep_going: bool,
    /// Worker threads (default: all cores). Output does not depend on it.
    #[arg(long)]
    pub(crate) threads: Option<usize>,
    /// Write per-frame, per-stage statistics as JSON to this file.
    #[arg(long)]
    pub(crate) stats: Option<PathBuf>,
    /// Error bound of a `.mseq` output, world units (each coordinate within it), as
    /// `archive info` prints it and `archive pack` takes it; appending needs the
    /// archive's own. Default 0.01 × the particle radius.
    #[arg(allow_negative_numbers = true, long)]
    pub(crate) error_bound: Option<f64>,
    /// Error bound of the attributes in a `.mseq` output, in each attribute's own units
    /// (m/s for a velocity): every value within it.
    #[arg(allow_negative_numbers = true, long, default_value_t = meniscus::archive::DEFAULT_ATTRIBUTE_ERROR_BOUND)]
    pub(crate) attribute_error_bound: f64,
    #[command(flatten)]
    pub(crate) stage: StageArgs,
    /// Point attributes carried to the surface: a comma-separated list of names
    /// (`velocity,density`), `all`, or `none`. Default: the velocity (`v`, `vel` or
    /// `velocity`, any case) when the input has one.
    #[arg(long, value_name = "LIST")]
    pub(crate) attributes: Option<String>,
    /// Do not write vertex normals.
    #[arg(long)]
    pub(crate) no_normals: bool,
    /// No progress bar and no timing table.
    #[arg(short, long)]
    pub(crate) quiet: bool,
}

/// The settings' defaults, for particles of radius 1: every default of `reconstruct`'s
/// flags comes from them ([`ReconstructSettings::new`], which reads the library's).
fn defaults() -> ReconstructSettings {
    ReconstructSettings::new(1.0)
}

/// `off` for `None`, else the value.
fn off_or<T: std::fmt::Display>(value: Option<T>) -> String {
    value.map_or_else(|| "off".to_string(), |v| v.to_string())
}

/// A kernel as `--kernel` names it.
fn kernel_name(kernel: meniscus::field::Kernel) -> &'static str {
    match kernel {
        meniscus::field::Kernel::Isotropic => "isotropic",
        _ => "anisotropic",
    }
}

/// A flag's help with its default (the `still` preset's) and each other preset's value
/// where it differs.
fn with_defaults<T: std::fmt::Display>(
    help: &str,
    value: impl Fn(&ReconstructSettings) -> T,
) -> String {
    let default = value(&defaults()).to_string();
    let mut text = format!("{help} [default: {default}");
    for preset in [Preset::Steady, Preset::Paper] {
        let other = value(&preset.settings(1.0)).to_string();
        if other != default {
            text.push_str(&format!("; {preset}: {other}"));
        }
    }
    text + "]"
}

const DECIMATE_HELP: &str = "Quadric decimation: fraction of triangles to remove (0.8 = the paper's), `adaptive` (stop on the error bound only: flat regions simplify, curved ones keep their triangles), or `off`; the default holds the anisotropic surface to the paper's triangle count";
const DECIMATE_ERROR_HELP: &str = "Error bound of decimation, multiples of r (RMS distance of a collapse to the original planes), or `off`; with a fraction, whichever is reached first stops it";
const CELL_SIZE_HELP: &str = "Marching-cubes cell size h, multiples of r";
const ISO_OFFSET_HELP: &str = "Iso-surface offset, multiples of r: extract where phi = offset·r, moving the surface outwards by about that much (0 = the paper's surface)";
const SMOOTH_HELP: &str =
    "Smoothing steps after decimation (0 = off): remove the field's small bumps";
const SMOOTH_METHOD_HELP: &str = "How the smoothing steps move the vertices: `taubin` (little shrinkage, the finest noise stays) or `laplacian` (each vertex to its neighbours' mean: removes the noise, shrinks unless bounded by --smooth-max-inward)";
const SMOOTH_MAX_INWARD_HELP: &str =
    "Farthest smoothing may move a vertex inwards, multiples of r, or `off`";
const SMOOTH_FEATURE_ANGLE_HELP: &str = "Feature weights of the smoothing's inward moves, degrees (Laplacian steps only): neighbours whose normals differ by more than about this angle pull less, so the edges of resting water and crests stay while flat noise goes; `off` for plain steps";
const SUBDIVIDE_HELP: &str = "Loop subdivision steps after decimation (0 = off)";
const NORMAL_SMOOTHING_HELP: &str = "Smoothing steps of the written vertex normals (0 = the area-weighted normals): steadier shading from frame to frame";
const KEEP_INSIDE_HELP: &str = "Least depth of every non-isolated particle centre under the final surface, multiples of r (0 to 1): where decimation or subdivision left one shallower or outside, the surface over it is pushed out; `off` leaves the surface as they made it";
const COVERAGE_HELP: &str = "Coverage radius c, multiples of r: particles the paper's surface would leave outside are enclosed in a ball of c·r (0 = off, the pure Solenthaler field)";
const KERNEL_HELP: &str = "Particle kernel: `anisotropic` (Yu & Turk 2013 kernels stretched along the local surface: smoother, and on the particles instead of inside them) or `isotropic` (the paper's Solenthaler field)";

/// `--kernel` values.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub(crate) enum KernelArg {
    Isotropic,
    Anisotropic,
}

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    /// The long flags of `meniscus reconstruct`.
    fn flags() -> Vec<String> {
        let cli = crate::Cli::command();
        let reconstruct = cli
            .find_subcommand("reconstruct")
            .expect("the reconstruct subcommand");
        reconstruct
            .get_arguments()
            .filter_map(|a| a.get_long().map(str::to_string))
            .collect()
    }

    #[test]
    fn every_setting_is_a_flag() {
        let flags = flags();
        for name in meniscus::settings::SETTINGS {
            // A `.mseq` output defers subdivision by itself.
            if *name == "defer_subdivision" {
                continue;
            }
            let flag = name.replace('_', "-");
            assert!(flags.contains(&flag), "--{flag} is missing");
        }
    }
}
