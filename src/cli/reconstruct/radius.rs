//! The particle radius of `meniscus reconstruct`: the library's policy
//! ([`meniscus::radius::choose_radius`]) worded as flags: `-r`, `--radius-attribute`,
//! `--no-radius-check`.

use super::ReconstructArgs;
use crate::cli::Failure;
use meniscus::radius::{
    ParticleRadii, RadiusAttribute, RadiusBasis, RadiusCheckOptions, RadiusChoice,
};
use std::path::Path;

/// The particle radius of the run ([`meniscus::radius::choose_radius`] on the first
/// frame): with a radius attribute its median, or `-r` checked against that median;
/// otherwise the estimate, or `-r` checked against it. A doubtful `-r` is warned about,
/// an implausible one refused (a usage error, the library's message naming
/// `--no-radius-check`); `--no-radius-check` takes `-r` as given, and so does a first
/// frame that cannot be read or measured. Prints where r came from (unless `--quiet`).
pub(crate) fn resolve_radius(args: &ReconstructArgs, first: &Path) -> Result<f32, Failure> {
    use meniscus::radius::{choose_radius, estimate_radius_of_file, read_radii};
    let which = args.radius_attribute.clone().unwrap_or_default();
    let check = RadiusCheckOptions {
        influence_radius: args.influence_radius,
        force: "--no-radius-check",
    };
    let choice = choose_radius(
        first,
        args.particle_radius,
        (!args.no_radius_check).then_some(check),
        read_radii(first, args.input_format, &which),
        || estimate_radius_of_file(first, args.input_format),
    )
    .map_err(|e| match e {
        e @ meniscus::Error::ImplausibleRadius { .. } => Failure::Usage(e.to_string()),
        e => e.into(),
    })?;
    if let Some(warning) = &choice.warning {
        eprintln!("warning: {warning} (--no-radius-check silences this)");
    }
    match &choice.radii {
        Some(radii) => from_attribute(args, first, &which, radii, &choice),
        None => from_estimate(args, first, &choice),
    }
}

/// Reports a radius taken from the spacing.
fn from_estimate(
    args: &ReconstructArgs,
    first: &Path,
    choice: &RadiusChoice,
) -> Result<f32, Failure> {
    if let (RadiusBasis::Estimate(estimate), None, false) =
        (&choice.basis, choice.verdict, args.quiet)
    {
        eprintln!(
            "particle radius r = {:?} (estimated from the spacing of {} of {}'s particles; -r sets it)",
            estimate.radius,
            estimate.sample,
            first.display()
        );
    }
    Ok(choice.radius)
}

/// Reports the radius of a run whose first frame has a radius attribute: without `-r`
/// the attribute's median. Says when it took Houdini's `pscale` by default, and when the
/// radii differ (each particle is meshed with its own).
fn from_attribute(
    args: &ReconstructArgs,
    first: &Path,
    which: &RadiusAttribute,
    radii: &ParticleRadii,
    choice: &RadiusChoice,
) -> Result<f32, Failure> {
    let r = choice.radius;
    let (lo, hi) = radii.range();
    let source = format!("attribute {:?} of {}", radii.attribute, first.display());
    if !args.quiet && *which == RadiusAttribute::Houdini {
        eprintln!(
            "particle radii from Houdini's {source}, taken when present (--radius-attribute none ignores it)"
        );
    }
    if !radii.is_uniform() && !args.quiet {
        eprintln!(
            "particle radii of {source} from {lo:?} to {hi:?}: each particle meshed with its own; cell size and options in multiples of r = {r:?}"
        );
    }
    if let (RadiusBasis::Median(median), None, false) = (&choice.basis, choice.verdict, args.quiet)
    {
        eprintln!("particle radius r = {median:?} (the median of {source}; -r sets it)");
    }
    Ok(r)
}
