//! The particle radius of a Python call: the library's policy
//! ([`meniscus::radius::choose_radius`], as the CLI's) worded as keywords:
//! `particle_radius`, `radius_attribute`, `radius_check`.

use crate::errors::to_py;
use meniscus::radius::{ParticleRadii, RadiusAttribute, RadiusBasis, RadiusCheck};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// The particle radius of a run, and the particles' radii when `radii` (a radius
/// attribute) holds them ([`meniscus::radius::choose_radius`]): with `radii` their
/// median, or `given` checked against it; otherwise the estimate, or `given` checked
/// against it; unless not `radius_check`. A doubtful `given` is a `UserWarning`, an
/// implausible one a `ValueError`; an estimate that fails is raised, also with `given`.
/// `input` names the particles in errors.
pub(crate) fn resolve_radius(
    py: Python<'_>,
    given: Option<f32>,
    radius_check: bool,
    input: &std::path::Path,
    radii: Option<ParticleRadii>,
    estimate: impl FnOnce() -> meniscus::Result<meniscus::radius::RadiusEstimate> + Send,
) -> PyResult<(f32, Option<ParticleRadii>)> {
    let choice = py
        .allow_threads(|| meniscus::radius::choose_radius(given, radius_check, Ok(radii), estimate))
        .map_err(to_py)?;
    let r = choice.radius;
    match (choice.basis, choice.verdict) {
        (RadiusBasis::Unmeasured(e), _) => return Err(to_py(e)),
        (RadiusBasis::Estimate(estimate), Some(RadiusCheck::Doubtful)) => {
            let message = format!(
                "particle_radius {r:?} is {:.2} × the radius the spacing of {}'s particles implies ({:?}); radius_check=False silences this",
                r / estimate.radius,
                input.display(),
                estimate.radius
            );
            user_warning(py, &message)?;
        }
        (RadiusBasis::Estimate(estimate), Some(RadiusCheck::Implausible)) => {
            return Err(to_py(meniscus::Error::ImplausibleRadius {
                path: input.to_path_buf(),
                given: r,
                estimate: estimate.radius,
                sample: estimate.sample,
            }))
        }
        (RadiusBasis::Median(median), Some(verdict)) => {
            let radii = choice.radii.as_ref().expect("a median of radii");
            let source = format!("attribute {:?} of {}", radii.attribute, input.display());
            let ratio = r / median;
            match verdict {
                RadiusCheck::Plausible => {}
                RadiusCheck::Doubtful => user_warning(
                    py,
                    &format!("particle_radius {r:?} is {ratio:.3} × the median radius {median:?} of {source}; radius_check=False silences this"),
                )?,
                RadiusCheck::Implausible => {
                    return Err(PyValueError::new_err(format!(
                        "particle_radius {r:?} is {ratio:.3e} × the median radius {median:?} of {source}; leave it out (the median is taken), or radius_check=False"
                    )))
                }
            }
        }
        _ => {}
    }
    Ok((r, choice.radii))
}

/// Issues a Python `UserWarning`.
fn user_warning(py: Python<'_>, message: &str) -> PyResult<()> {
    PyErr::warn_bound(
        py,
        &py.get_type_bound::<pyo3::exceptions::PyUserWarning>(),
        message,
        1,
    )
}

/// The radius attribute of a function's `radius_attribute`: None (Houdini's `pscale`
/// when present), "none", or a name.
pub(crate) fn radius_attribute(name: Option<String>) -> PyResult<RadiusAttribute> {
    name.map(|n| n.parse())
        .transpose()
        .map(Option::unwrap_or_default)
        .map_err(|e| PyValueError::new_err(format!("invalid radius_attribute: {e}")))
}
