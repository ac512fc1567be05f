//! The particle radius of `meniscus reconstruct`: the library's policy
//! ([`meniscus::radius::choose_radius`]) worded as flags: `-r`, `--radius-attribute`,
//! `--no-radius-check`.

use super::ReconstructArgs;
use crate::cli::Failure;
use meniscus::radius::{ParticleRadii, RadiusAttribute, RadiusBasis, RadiusCheck, RadiusChoice};
use std::path::Path;

/// The particle radius of the run ([`meniscus::radius::choose_radius`] on the first
/// frame): with a radius attribute its median, or `-r` checked against that median;
/// otherwise the estimate, or `-r` checked against it. A doubtful `-r` is warned about,
/// an implausible one refused (a usage error); `--no-radius-check` takes `-r` as given,
/// and so does a first frame that cannot be read or measured. Prints where r came from
/// (unless `--quiet`).
pub(crate) fn resolve_radius(args: &ReconstructArgs, first: &Path) -> Result<f32, Failure> {
    use meniscus::radius::{choose_radius, estimate_radius_of_file, read_radii};
    let which = args.radius_attribute.clone().unwrap_or_default();
    let choice = choose_radius(
        args.particle_radius,
        !args.no_radius_check,
        read_radii(first, args.input_format, &which),
        || estimate_radius_of_file(first, args.input_format),
    )?;
    match &choice.radii {
        Some(radii) => from_attribute(args, first, &which, radii, &choice),
        None => from_estimate(args, first, &choice),
    }
}

/// Reports a radius taken from, or checked against, the spacing.
fn from_estimate(
    args: &ReconstructArgs,
    first: &Path,
    choice: &RadiusChoice,
) -> Result<f32, Failure> {
    let (r, RadiusBasis::Estimate(estimate)) = (choice.radius, &choice.basis) else {
        return Ok(choice.radius);
    };
    let shown = format!("{:?}", estimate.radius);
    match choice.verdict {
        None if !args.quiet => eprintln!(
            "particle radius r = {:?} (estimated from the spacing of {} of {}'s particles; -r sets it)",
            estimate.radius,
            estimate.sample,
            first.display()
        ),
        None | Some(RadiusCheck::Plausible) => {}
        Some(RadiusCheck::Doubtful) => eprintln!(
            "warning: -r {r:?} is {:.2} × the particle radius the spacing of {}'s particles implies ({}); r is half the rest spacing (--no-radius-check silences this)",
            r / estimate.radius,
            first.display(),
            shown
        ),
        Some(RadiusCheck::Implausible) => {
            let e = meniscus::Error::ImplausibleRadius {
                path: first.to_path_buf(),
                given: r,
                estimate: estimate.radius,
                sample: estimate.sample,
            };
            return Err(Failure::Usage(format!(
                "{e}\nhint: give -r about {shown} (half the particle spacing), or --no-radius-check to run with -r {r:?} anyway"
            )));
        }
    }
    Ok(r)
}

/// Reports the radius of a run whose first frame has a radius attribute: without `-r`
/// the attribute's median; `-r` checked against the median as against the estimate
/// (unless `--no-radius-check`). Says when it took Houdini's `pscale` by default, and
/// when the radii differ (each particle is meshed with its own).
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
    let RadiusBasis::Median(median) = choice.basis else {
        return Ok(r);
    };
    let ratio = r / median;
    match choice.verdict {
        None if !args.quiet => {
            eprintln!("particle radius r = {median:?} (the median of {source}; -r sets it)");
        }
        None | Some(RadiusCheck::Plausible) => {}
        Some(RadiusCheck::Doubtful) => eprintln!(
            "warning: -r {r:?} is {ratio:.3} × the median radius {median:?} of {source} (--no-radius-check silences this)"
        ),
        Some(RadiusCheck::Implausible) => {
            return Err(Failure::Usage(format!(
                "-r {r:?} is {ratio:.3e} × the median radius {median:?} of {source}\nhint: leave out -r (r is then the median), give -r about {median:?}, or --no-radius-check to run with -r {r:?} anyway"
            )))
        }
    }
    Ok(r)
}
