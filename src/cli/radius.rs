//! `-r` and the particle radius check of `meniscus reconstruct`.

use crate::{Failure, ReconstructArgs};
use std::path::Path;

/// The particle radius of the run: `-r` after checking it against the first frame's
/// spacing (a warning outside 0.25×–4×, a usage error outside 0.05×–20×), or without `-r`
/// the estimate, printed. `--no-radius-check` takes `-r` as given, unread; so does a
/// first frame the estimate cannot read or measure.
pub(crate) fn resolve_radius(args: &ReconstructArgs, first: &Path) -> Result<f32, Failure> {
    use meniscus::radius::{estimate_radius_of_file, verify_radius, RadiusCheck};
    let given = match args.particle_radius {
        Some(r) if args.no_radius_check => return Ok(r),
        given => given,
    };
    let estimate = match (estimate_radius_of_file(first, args.input_format), given) {
        (Ok(estimate), _) => estimate,
        // A frame that cannot be read or measured: with -r, the run reports it as it
        // reads it (with --keep-going, as that frame's failure).
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
