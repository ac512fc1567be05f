//! `-r`, the radius attribute and the particle radius check of `meniscus reconstruct`.

use crate::{Failure, ReconstructArgs};
use meniscus::radius::{ParticleRadii, RadiusAttribute, RadiusCheck};
use std::path::Path;

/// The particle radius of the run. With a radius attribute in the first frame
/// ([`from_attribute`]) its median, or `-r` checked against that median. Otherwise `-r`
/// after checking it against the first frame's spacing (a warning outside 0.25×–4×, a
/// usage error outside 0.05×–20×), or without `-r` the estimate, printed.
/// `--no-radius-check` takes `-r` as given, unread; so does a first frame the estimate
/// cannot read or measure.
pub(crate) fn resolve_radius(args: &ReconstructArgs, first: &Path) -> Result<f32, Failure> {
    use meniscus::radius::{estimate_radius_of_file, read_radii, verify_radius};
    let which = args.radius_attribute.clone().unwrap_or_default();
    match (
        read_radii(first, args.input_format, &which),
        args.particle_radius,
    ) {
        (Ok(Some(radii)), given) => return from_attribute(args, first, &which, &radii, given),
        (Ok(None), _) => {}
        // A frame that cannot be read: with -r, the run reports it as it reads it (with
        // --keep-going, as that frame's failure).
        (Err(_), Some(r)) => return Ok(r),
        (Err(e), None) => return Err(e.into()),
    }
    let given = match args.particle_radius {
        Some(r) if args.no_radius_check => return Ok(r),
        given => given,
    };
    let estimate = match (estimate_radius_of_file(first, args.input_format), given) {
        (Ok(estimate), _) => estimate,
        (Err(_), Some(r)) => return Ok(r),
        (Err(e), None) => return Err(e.into()),
    };
    let shown = format!("{:?}", estimate.radius);
    let Some(r) = given else {
        if !args.quiet {
            eprintln!(
                "particle radius r = {:?} (estimated from the spacing of {} of {}'s particles; -r sets it)",
                estimate.radius,
                estimate.sample,
                first.display()
            );
        }
        return Ok(estimate.radius);
    };
    match verify_radius(first, r, &estimate) {
        Ok(RadiusCheck::Plausible) => {}
        Ok(_) => eprintln!(
            "warning: -r {r:?} is {:.2} × the particle radius the spacing of {}'s particles implies ({}); r is half the rest spacing (--no-radius-check silences this)",
            r / estimate.radius,
            first.display(),
            shown
        ),
        Err(e) => {
            return Err(Failure::Usage(format!(
                "{e}\nhint: give -r about {shown} (half the particle spacing), or --no-radius-check to run with -r {r:?} anyway"
            )))
        }
    }
    Ok(r)
}

/// The radius of a run whose first frame has a radius attribute: without `-r` the
/// attribute's median, printed; `-r` checked against the median as against the estimate
/// (unless `--no-radius-check`). Says when it took Houdini's `pscale` by default, and
/// when the radii differ (each particle is meshed with its own).
fn from_attribute(
    args: &ReconstructArgs,
    first: &Path,
    which: &RadiusAttribute,
    radii: &ParticleRadii,
    given: Option<f32>,
) -> Result<f32, Failure> {
    let median = radii.median();
    let (lo, hi) = radii.range();
    let source = format!("attribute {:?} of {}", radii.attribute, first.display());
    if !args.quiet && *which == RadiusAttribute::Houdini {
        eprintln!(
            "particle radii from Houdini's {source}, taken when present (--radius-attribute none ignores it)"
        );
    }
    if !radii.is_uniform() && !args.quiet {
        eprintln!(
            "particle radii of {source} from {lo:?} to {hi:?}: each particle meshed with its own; cell size and options in multiples of r = {:?}",
            given.unwrap_or(median)
        );
    }
    let Some(r) = given else {
        if !args.quiet {
            eprintln!("particle radius r = {median:?} (the median of {source}; -r sets it)");
        }
        return Ok(median);
    };
    if args.no_radius_check {
        return Ok(r);
    }
    let ratio = r / median;
    match meniscus::radius::check_radius(r, median) {
        RadiusCheck::Plausible => {}
        RadiusCheck::Doubtful => eprintln!(
            "warning: -r {r:?} is {ratio:.3} × the median radius {median:?} of {source} (--no-radius-check silences this)"
        ),
        RadiusCheck::Implausible => {
            return Err(Failure::Usage(format!(
                "-r {r:?} is {ratio:.3e} × the median radius {median:?} of {source}\nhint: leave out -r (r is then the median), give -r about {median:?}, or --no-radius-check to run with -r {r:?} anyway"
            )))
        }
    }
    Ok(r)
}
