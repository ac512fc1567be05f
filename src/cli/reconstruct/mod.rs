//! `meniscus reconstruct`: its flags ([`args`]) become the library's settings
//! ([`ReconstructSettings`], [`JobSettings`]), the radius comes from the library's policy
//! ([`radius`]), and the frames run behind a progress bar ([`progress`]).

mod args;
mod progress;
mod radius;
mod warnings;

pub(crate) use args::ReconstructArgs;

use crate::cli::Failure;
use args::KernelArg;
use clap::ArgMatches;
use meniscus::job::{check_outputs, plan_frames, JobSettings};
use meniscus::pipeline::ReconstructOptions;
use meniscus::settings::{Preset, ReconstructSettings};
use progress::{check_failed, run_with_progress, summarize, write_stats};
use radius::resolve_radius;
use std::time::Instant;
use warnings::ineffective_options;

/// Runs `meniscus reconstruct` with `args`; `given` tells which flags the command line
/// set (for the warnings about pointless ones).
pub(crate) fn run(
    args: &mut ReconstructArgs,
    given: &ArgMatches,
    cancel: &meniscus::CancelToken,
) -> Result<(), Failure> {
    // Options first, then the frames: usage errors (exit 2) before any file is read
    // (without -r, checked for r = 1 until the estimate replaces it).
    let mut job = job_settings(args);
    job.validate()?;
    args.radius = args.particle_radius.unwrap_or(1.0);
    options_from(args)?;
    if let Some(list) = &args.attributes {
        job.attributes = list
            .parse()
            .map_err(|e| Failure::option("--attributes", e))?;
    }
    let plan = plan_frames(&args.input, &args.output, &args.farm.choice())?;
    check_outputs(&plan).map_err(|e| Failure::Usage(e.to_string()))?;
    // The pool before the radius estimate, its first parallel work.
    if let Some(threads) = args.threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build_global()
            .map_err(|e| Failure::Run(e.to_string()))?;
    }
    args.radius = resolve_radius(args, &plan[0].0.input)?;
    let options = options_from(args)?;
    for warning in ineffective_options(args, given, &plan, &job.attributes) {
        eprintln!("warning: {warning}");
    }
    let job = job.options(args.radius, cancel);
    let clock = Instant::now();
    let reports = run_with_progress(args, &plan, &options, &job).map_err(|e| match e {
        meniscus::Error::FramesExist { .. } => Failure::Run(format!(
            "{e}\nhint: --skip-existing skips the frames the archive holds and appends the others"
        )),
        e => e.into(),
    })?;
    let total = clock.elapsed().as_secs_f64();
    if !args.quiet {
        summarize(&reports, total, &args.output);
    }
    if let Some(path) = &args.stats {
        write_stats(path, &options, &reports, total)?;
    }
    check_failed(&reports)
}

/// The job settings of the flags; the attributes are parsed apart (after the options, as
/// their errors are reported in that order).
fn job_settings(args: &ReconstructArgs) -> JobSettings {
    JobSettings {
        input_format: args.input_format,
        normals: !args.no_normals,
        skip_existing: args.skip_existing,
        error_bound: args.error_bound,
        attribute_error_bound: args.attribute_error_bound,
        fps: args.stage.fps,
        up_axis: args.stage.up_axis,
        meters_per_unit: args.stage.meters_per_unit,
        usd_droplets: args.stage.usd_droplets,
        attributes: Default::default(),
        radius_attribute: args.radius_attribute.clone().unwrap_or_default(),
        threads: args.threads,
        keep_going: args.keep_going,
    }
}

/// A flag's value that is `off` (or `none`) or a `T`, which the message names as `what`.
fn parse_or_off<T: std::str::FromStr>(
    value: &str,
    option: &str,
    what: &str,
) -> Result<Option<T>, Failure> {
    match value {
        "off" | "none" => Ok(None),
        v => v
            .parse()
            .map(Some)
            .map_err(|_| Failure::option(option, format!("takes {what} or `off`, got {v:?}"))),
    }
}

/// The preset the flags start from: `--preset`, `--paper`, or the input's
/// ([`Preset::for_input`]: steady for a sequence).
pub(crate) fn preset(args: &ReconstructArgs) -> Preset {
    match (args.preset, args.paper) {
        (Some(preset), _) => preset,
        (None, true) => Preset::Paper,
        (None, false) => Preset::for_input(std::path::Path::new(&args.input)),
    }
}

fn options_from(args: &ReconstructArgs) -> Result<ReconstructOptions, Failure> {
    let r = args.radius;
    let base = preset(args).settings(r);
    let settings = ReconstructSettings {
        particle_radius: r,
        influence_radius: args.influence_radius,
        cell_size: args.cell_size.unwrap_or(base.cell_size),
        t_low: args.t_low,
        t_high: args.t_high,
        particle_coverage: args.particle_coverage.unwrap_or(base.particle_coverage),
        iso_offset: args.iso_offset.unwrap_or(base.iso_offset),
        kernel: match args.kernel {
            None => base.kernel,
            Some(KernelArg::Isotropic) => meniscus::field::Kernel::Isotropic,
            Some(KernelArg::Anisotropic) => meniscus::field::Kernel::Anisotropic,
        },
        kernel_radius: args.kernel_radius,
        max_stretch: args.max_stretch,
        min_neighbours: args.min_neighbours,
        centre_smoothing: args.centre_smoothing,
        isolated_spheres: parse_or_off(
            &args.isolated_spheres,
            "--isolated-spheres",
            "a level (0, 1, 2, ...)",
        )?,
        decimate: match &args.decimate {
            None => base.decimate,
            Some(text) => text.parse().map_err(|e| Failure::option("--decimate", e))?,
        },
        decimate_error: match &args.decimate_error {
            None => base.decimate_error,
            Some(v) => parse_or_off(v, "--decimate-error", "a bound (multiples of r)")?,
        },
        smooth: args.smooth.unwrap_or(base.smooth),
        smooth_method: args.smooth_method.unwrap_or(base.smooth_method),
        smooth_max_inward: match &args.smooth_max_inward {
            None => base.smooth_max_inward,
            Some(v) => parse_or_off(v, "--smooth-max-inward", "a distance (multiples of r)")?,
        },
        smooth_feature_angle: match &args.smooth_feature_angle {
            None => base.smooth_feature_angle,
            Some(v) => parse_or_off(v, "--smooth-feature-angle", "an angle (degrees)")?,
        },
        subdivide: args.subdivide.unwrap_or(base.subdivide),
        // A `.mseq` output defers it by itself (see `job`).
        defer_subdivision: false,
        keep_inside: match &args.keep_inside {
            None => base.keep_inside,
            Some(v) => parse_or_off(v, "--keep-inside", "a depth (multiples of r)")?,
        },
        normal_smoothing: args.normal_smoothing.unwrap_or(base.normal_smoothing),
        tile_size: args.tile_size,
        memory_budget: args
            .memory_budget
            .as_deref()
            .map(meniscus::settings::parse_memory_budget)
            .transpose()?,
        temp_dir: args.temp_dir.clone(),
    };
    Ok(settings.options()?)
}
