//! The particle radius a run takes: the one policy the CLI's `reconstruct`, the Python
//! package's `reconstruct`/`reconstruct_file` and the Blender extension follow
//! ([`choose_radius`]). It refuses an implausible given radius itself, with the same
//! [`Error::ImplausibleRadius`] everywhere; the front ends only say how to force it and
//! how to silence a warning in their own terms (`--no-radius-check`,
//! `radius_check=False`, a check box).

use super::{check_radius, ParticleRadii, RadiusCheck, RadiusEstimate, RadiusSource};
use crate::error::{Error, Result};
use std::path::Path;

/// What a given radius was taken from, or checked against.
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
    /// How a given, checked radius compares with the basis; `None` without one. Never
    /// [`RadiusCheck::Implausible`] ([`choose_radius`] refuses that).
    pub verdict: Option<RadiusCheck>,
    /// With a [`RadiusCheck::Doubtful`] verdict, the warning it deserves (the input, both
    /// radii, and how many particles would be isolated); the front end adds how to
    /// silence it.
    pub warning: Option<String>,
}

/// How [`choose_radius`] checks a given radius.
#[derive(Clone, Copy, Debug)]
pub struct RadiusCheckOptions<'a> {
    /// The run's influence radius R, multiples of r: the kernel's reach, within which a
    /// particle needs a neighbour not to be meshed as a sphere of its own.
    pub influence_radius: f32,
    /// How the caller runs with a refused radius anyway, in its own terms (the refusal
    /// ends "..., or {force} to run with it anyway"): `--no-radius-check`,
    /// `radius_check=False`.
    pub force: &'a str,
}

/// The particle radius of a run on `input`, from the radius `given` (world units, or
/// `None`), the first frame's radius attribute `radii` (as [`super::read_radii`] or
/// [`super::radii_of`] gave it) and its spacing (`estimate`, only called when needed):
///
/// * with a radius attribute, its median, or `given` checked against that median;
/// * otherwise the estimate, or `given` checked against the estimate;
///
/// a given radius checked (unless `check` is `None`) by [`check_radius`], with the
/// estimate's sample measuring isolation (not against a radius attribute, whose
/// particles each keep their own reach): an implausible one is refused with [`Error::ImplausibleRadius`]
/// (naming both radii, what a run would do, and `check.force`), a doubtful one comes
/// with a [`RadiusChoice::warning`].
///
/// A `given` radius is taken unchecked ([`RadiusBasis::Unmeasured`]) when the radii or
/// the estimate fail; without one their error is returned.
pub fn choose_radius(
    input: &Path,
    given: Option<f32>,
    check: Option<RadiusCheckOptions<'_>>,
    radii: Result<Option<ParticleRadii>>,
    estimate: impl FnOnce() -> Result<RadiusEstimate>,
) -> Result<RadiusChoice> {
    let unchecked = |radius, radii, basis| RadiusChoice {
        radius,
        radii,
        basis,
        verdict: None,
        warning: None,
    };
    let radii = match radii {
        Ok(radii) => radii,
        Err(e) => {
            return match given {
                Some(r) => Ok(unchecked(r, None, RadiusBasis::Unmeasured(e))),
                None => Err(e),
            }
        }
    };
    let (given, check) = match (given, check) {
        (None, _) => {
            return Ok(match radii {
                Some(radii) => {
                    let median = radii.median();
                    unchecked(median, Some(radii), RadiusBasis::Median(median))
                }
                None => {
                    let e = estimate()?;
                    unchecked(e.radius, None, RadiusBasis::Estimate(e))
                }
            })
        }
        (Some(r), None) => return Ok(unchecked(r, radii, RadiusBasis::Given)),
        (Some(r), Some(check)) => (r, check),
    };
    // With a radius attribute each particle is meshed with its own radius, whatever the
    // given one: isolation is not the given radius's doing, and is not measured.
    let (reference, source, basis) = match &radii {
        Some(radii) => {
            let median = radii.median();
            let source = RadiusSource::Attribute {
                name: radii.attribute.clone(),
            };
            (median, source, RadiusBasis::Median(median))
        }
        None => match estimate() {
            Ok(e) => {
                let source = RadiusSource::Spacing { sample: e.sample };
                (e.radius, source, RadiusBasis::Estimate(e))
            }
            Err(e) => return Ok(unchecked(given, None, RadiusBasis::Unmeasured(e))),
        },
    };
    let sampled = match &basis {
        RadiusBasis::Estimate(e) => Some(e),
        _ => None,
    };
    let verdict = check_radius(given, reference, sampled, check.influence_radius);
    let warning = match verdict {
        RadiusCheck::Implausible(problem) => {
            return Err(Error::ImplausibleRadius {
                path: input.to_path_buf(),
                given,
                estimate: reference,
                origin: source,
                problem,
                force: check.force.to_string(),
            })
        }
        RadiusCheck::Plausible => None,
        RadiusCheck::Doubtful { isolated } => {
            let mut w = format!(
                "{}: a particle radius of {given:?} is {:.2} × the {reference:?} {source}",
                input.display(),
                given / reference
            );
            if isolated >= 0.005 {
                w += &format!(
                    "; {:.0}% of the fluid's particles would be meshed each as a sphere of its own",
                    100.0 * isolated
                );
            }
            Some(w)
        }
    };
    Ok(RadiusChoice {
        radius: given,
        radii,
        basis,
        verdict: Some(verdict),
        warning,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::attributes::Attribute;
    use crate::radius::RadiusProblem;

    /// An estimate of `radius` whose ten sampled particles sit 1.8 radii from their
    /// nearest neighbours (as in compressed SPH).
    fn estimate(radius: f32) -> Result<RadiusEstimate> {
        Ok(RadiusEstimate {
            radius,
            half_nearest: 0.9 * radius,
            sample: 10,
            nearest: vec![1.8 * radius; 10],
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

    const CHECK: Option<RadiusCheckOptions> = Some(RadiusCheckOptions {
        influence_radius: 4.0,
        force: "force=True",
    });

    fn choose(
        given: Option<f32>,
        check: Option<RadiusCheckOptions>,
        radii: Result<Option<ParticleRadii>>,
        estimate: impl FnOnce() -> Result<RadiusEstimate>,
    ) -> Result<RadiusChoice> {
        choose_radius(Path::new("p.xyz"), given, check, radii, estimate)
    }

    #[test]
    fn the_estimate_is_taken_or_checks_a_given_radius() {
        let c = choose(None, CHECK, Ok(None), || estimate(0.5)).unwrap();
        assert_eq!((c.radius, c.verdict), (0.5, None));
        assert!(matches!(c.basis, RadiusBasis::Estimate(_)));
        assert!(c.warning.is_none());
        let c = choose(Some(0.6), CHECK, Ok(None), || estimate(0.5)).unwrap();
        assert_eq!((c.verdict, c.warning), (Some(RadiusCheck::Plausible), None));
        // 0.46 x: the reach 4 x 0.23 = 0.92 still finds the neighbours at 0.9.
        let c = choose(Some(0.23), CHECK, Ok(None), || estimate(0.5)).unwrap();
        assert_eq!(c.verdict, Some(RadiusCheck::Doubtful { isolated: 0.0 }));
        let w = c.warning.unwrap();
        assert!(
            w.starts_with("p.xyz: a particle radius of 0.23 is 0.46 × the 0.5"),
            "{w}"
        );
        let c = choose(Some(1.5), CHECK, Ok(None), || estimate(0.5)).unwrap();
        assert_eq!(c.verdict, Some(RadiusCheck::Doubtful { isolated: 0.0 }));
        // 0.44 x: no neighbour within 0.88, every particle isolated: refused.
        let e = choose(Some(0.22), CHECK, Ok(None), || estimate(0.5)).unwrap_err();
        let Error::ImplausibleRadius {
            given,
            estimate: reference,
            problem,
            ..
        } = &e
        else {
            panic!("{e}")
        };
        assert_eq!((*given, *reference), (0.22, 0.5));
        assert!(matches!(problem, RadiusProblem::Isolated { fraction, .. } if *fraction == 1.0));
        let m = e.to_string();
        assert!(
            m.contains("100% of the fluid's particles")
                && m.ends_with("or force=True to run with 0.22 anyway"),
            "{m}"
        );
        let e = choose(Some(2.5), CHECK, Ok(None), || estimate(0.5)).unwrap_err();
        assert!(
            matches!(
                e,
                Error::ImplausibleRadius {
                    problem: RadiusProblem::Blob,
                    ..
                }
            ),
            "{e}"
        );
        let c = choose(Some(30.0), None, Ok(None), || panic!("not measured")).unwrap();
        assert_eq!((c.radius, c.verdict), (30.0, None));
        assert!(matches!(c.basis, RadiusBasis::Given));
    }

    #[test]
    fn a_radius_attribute_gives_the_median_or_checks_a_given_radius() {
        let no_estimate = || -> Result<RadiusEstimate> { panic!("not measured") };
        let c = choose(None, CHECK, radii(vec![1.0, 2.0, 9.0]), no_estimate).unwrap();
        assert_eq!((c.radius, c.verdict), (2.0, None));
        assert!(matches!(c.basis, RadiusBasis::Median(m) if m == 2.0));
        assert!(c.radii.is_some());
        let e = choose(Some(100.0), CHECK, radii(vec![2.0]), no_estimate).unwrap_err();
        assert!(
            e.to_string()
                .contains("median of the particles' radius attribute \"pscale\""),
            "{e}"
        );
        // Each particle keeps its own reach: a small given radius only makes the lattice
        // finer, refused below 0.05x.
        let c = choose(Some(0.4), CHECK, radii(vec![2.0]), no_estimate).unwrap();
        assert_eq!(c.verdict, Some(RadiusCheck::Doubtful { isolated: 0.0 }));
        // Radii of 1:4, -r the smallest (the finest surface): a warning, not a refusal.
        let c = choose(Some(0.5), CHECK, radii(vec![0.5, 2.0, 2.0]), no_estimate).unwrap();
        assert_eq!(c.verdict, Some(RadiusCheck::Doubtful { isolated: 0.0 }));
        let e = choose(Some(0.09), CHECK, radii(vec![2.0]), no_estimate).unwrap_err();
        assert!(
            matches!(
                e,
                Error::ImplausibleRadius {
                    problem: RadiusProblem::FineLattice,
                    ..
                }
            ),
            "{e}"
        );
        let c = choose(Some(100.0), None, radii(vec![2.0]), no_estimate).unwrap();
        assert_eq!((c.radius, c.verdict), (100.0, None));
        assert!(c.radii.is_some());
    }

    #[test]
    fn a_given_radius_survives_an_unreadable_frame() {
        let c = choose(Some(0.5), CHECK, Err(unreadable()), || estimate(1.0)).unwrap();
        assert!(matches!(
            c.basis,
            RadiusBasis::Unmeasured(Error::EmptyInput { .. })
        ));
        let c = choose(Some(0.5), CHECK, Ok(None), || Err(unreadable())).unwrap();
        assert!(matches!(c.basis, RadiusBasis::Unmeasured(_)));
        assert_eq!(c.radius, 0.5);
        assert!(choose(None, CHECK, Err(unreadable()), || estimate(1.0)).is_err());
        assert!(choose(None, CHECK, Ok(None), || Err(unreadable())).is_err());
    }
}
