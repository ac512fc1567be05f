//! The particle radius a run takes: the one policy the CLI's `reconstruct` and the Python
//! package's `reconstruct`/`reconstruct_file` follow ([`choose_radius`]). The front ends
//! only word what it decided in their own terms (`-r` or `particle_radius`,
//! `--no-radius-check` or `radius_check=False`) and refuse a given radius whose verdict
//! is [`RadiusCheck::Implausible`].

use super::{check_radius, ParticleRadii, RadiusCheck, RadiusEstimate};
use crate::error::{Error, Result};

/// What the radius of a run was taken from, or checked against.
#[derive(Debug)]
pub enum RadiusBasis {
    /// The given radius, as given: no check was asked for.
    Given,
    /// The given radius, unchecked: the first frame could not be read or measured (the
    /// error says why; a run reports it when it reads that frame).
    Unmeasured(Error),
    /// The first frame's spacing ([`super::estimate_radius`]): the radius without a given
    /// one, else what the given one was checked against.
    Estimate(RadiusEstimate),
    /// The median of the first frame's radius attribute ([`ParticleRadii::median`]): the
    /// radius without a given one, else what the given one was checked against.
    Median(f32),
}

/// The particle radius of a run and how it was chosen ([`choose_radius`]).
#[derive(Debug)]
pub struct RadiusChoice {
    /// The reference radius `r` of the run, world units.
    pub radius: f32,
    /// The first frame's radius attribute, when it has one (each particle is then meshed
    /// with its own radius).
    pub radii: Option<ParticleRadii>,
    /// What `radius` was taken from or checked against.
    pub basis: RadiusBasis,
    /// How a given, checked radius compares with the basis; `None` without one. The
    /// caller refuses [`RadiusCheck::Implausible`] (a run would hang or write an absurd
    /// mesh), warns about [`RadiusCheck::Doubtful`].
    pub verdict: Option<RadiusCheck>,
}

/// The particle radius of a run, from the radius `given` (world units, or `None`), the
/// first frame's radius attribute `radii` (as [`super::read_radii`] or
/// [`super::radii_of`] gave it) and its spacing (`estimate`, only called when needed):
///
/// * with a radius attribute, its median, or `given` checked against that median (unless
///   not `check`);
/// * otherwise the estimate, or `given` checked against the estimate (unless not
///   `check`): within 0.25×–4× plausible, within 0.05×–20× doubtful, else implausible
///   ([`check_radius`]).
///
/// A `given` radius is taken unchecked ([`RadiusBasis::Unmeasured`]) when the radii or
/// the estimate fail; without one their error is returned.
pub fn choose_radius(
    given: Option<f32>,
    check: bool,
    radii: Result<Option<ParticleRadii>>,
    estimate: impl FnOnce() -> Result<RadiusEstimate>,
) -> Result<RadiusChoice> {
    let choice = |radius, radii, basis, verdict| RadiusChoice {
        radius,
        radii,
        basis,
        verdict,
    };
    match radii {
        Ok(Some(radii)) => {
            let median = radii.median();
            return Ok(match given {
                None => choice(median, Some(radii), RadiusBasis::Median(median), None),
                Some(r) if !check => choice(r, Some(radii), RadiusBasis::Given, None),
                Some(r) => {
                    let verdict = Some(check_radius(r, median));
                    choice(r, Some(radii), RadiusBasis::Median(median), verdict)
                }
            });
        }
        Ok(None) => {}
        Err(e) => {
            return match given {
                Some(r) => Ok(choice(r, None, RadiusBasis::Unmeasured(e), None)),
                None => Err(e),
            }
        }
    }
    if let (Some(r), false) = (given, check) {
        return Ok(choice(r, None, RadiusBasis::Given, None));
    }
    let estimate = match (estimate(), given) {
        (Ok(estimate), _) => estimate,
        (Err(e), Some(r)) => return Ok(choice(r, None, RadiusBasis::Unmeasured(e), None)),
        (Err(e), None) => return Err(e),
    };
    Ok(match given {
        None => choice(estimate.radius, None, RadiusBasis::Estimate(estimate), None),
        Some(r) => {
            let verdict = Some(check_radius(r, estimate.radius));
            choice(r, None, RadiusBasis::Estimate(estimate), verdict)
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::attributes::Attribute;
    use std::path::Path;

    fn estimate(radius: f32) -> Result<RadiusEstimate> {
        Ok(RadiusEstimate {
            radius,
            half_nearest: radius,
            sample: 10,
        })
    }

    fn radii(values: Vec<f32>) -> Result<Option<ParticleRadii>> {
        let count = values.len();
        let attribute = Attribute {
            name: "pscale".into(),
            components: 1,
            values,
        };
        ParticleRadii::new(Path::new("p"), attribute, count).map(Some)
    }

    fn unreadable() -> Error {
        Error::EmptyInput { path: "p".into() }
    }

    #[test]
    fn the_estimate_is_taken_or_checks_a_given_radius() {
        let c = choose_radius(None, true, Ok(None), || estimate(0.5)).unwrap();
        assert_eq!((c.radius, c.verdict), (0.5, None));
        assert!(matches!(c.basis, RadiusBasis::Estimate(_)));
        for (r, verdict) in [
            (0.6, RadiusCheck::Plausible),
            (3.0, RadiusCheck::Doubtful),
            (30.0, RadiusCheck::Implausible),
        ] {
            let c = choose_radius(Some(r), true, Ok(None), || estimate(0.5)).unwrap();
            assert_eq!((c.radius, c.verdict), (r, Some(verdict)));
        }
        let c = choose_radius(Some(30.0), false, Ok(None), || panic!("not measured")).unwrap();
        assert_eq!((c.radius, c.verdict), (30.0, None));
        assert!(matches!(c.basis, RadiusBasis::Given));
    }

    #[test]
    fn a_radius_attribute_gives_the_median_or_checks_a_given_radius() {
        let no_estimate = || -> Result<RadiusEstimate> { panic!("not measured") };
        let c = choose_radius(None, true, radii(vec![1.0, 2.0, 9.0]), no_estimate).unwrap();
        assert_eq!((c.radius, c.verdict), (2.0, None));
        assert!(matches!(c.basis, RadiusBasis::Median(m) if m == 2.0));
        assert!(c.radii.is_some());
        let c = choose_radius(Some(100.0), true, radii(vec![2.0]), no_estimate).unwrap();
        assert_eq!(c.verdict, Some(RadiusCheck::Implausible));
        let c = choose_radius(Some(100.0), false, radii(vec![2.0]), no_estimate).unwrap();
        assert_eq!((c.radius, c.verdict), (100.0, None));
        assert!(c.radii.is_some());
    }

    #[test]
    fn a_given_radius_survives_an_unreadable_frame() {
        let c = choose_radius(Some(0.5), true, Err(unreadable()), || estimate(1.0)).unwrap();
        assert!(matches!(
            c.basis,
            RadiusBasis::Unmeasured(Error::EmptyInput { .. })
        ));
        let c = choose_radius(Some(0.5), true, Ok(None), || Err(unreadable())).unwrap();
        assert!(matches!(c.basis, RadiusBasis::Unmeasured(_)));
        assert_eq!(c.radius, 0.5);
        assert!(choose_radius(None, true, Err(unreadable()), || estimate(1.0)).is_err());
        assert!(choose_radius(None, true, Ok(None), || Err(unreadable())).is_err());
    }
}
