//! The particle radius of a Python call: `particle_radius`, the radius attribute and the
//! check of a given radius against the particles (as the CLI's `cli/radius.rs`).

use crate::to_py;
use meniscus::radius::{ParticleRadii, RadiusAttribute};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// The particle radius of a run. With `radii` (a radius attribute) their median, or
/// `given` checked against it ([`radius_from_attribute`]). Otherwise `given` after
/// checking it against the estimate (a `UserWarning` outside 0.25×–4×, a `ValueError`
/// outside 0.05×–20×) unless not `radius_check`; without `given`, the estimate. `input`
/// names the particles in errors.
pub(crate) fn resolve_radius(
    py: Python<'_>,
    given: Option<f32>,
    radius_check: bool,
    input: &std::path::Path,
    radii: Option<&ParticleRadii>,
    estimate: impl FnOnce() -> meniscus::Result<meniscus::radius::RadiusEstimate> + Send,
) -> PyResult<f32> {
    use meniscus::radius::{verify_radius, RadiusCheck};
    if let Some(radii) = radii {
        return radius_from_attribute(py, given, radius_check, input, radii);
    }
    if let (Some(r), false) = (given, radius_check) {
        return Ok(r);
    }
    let estimate = py.allow_threads(estimate).map_err(to_py)?;
    let Some(r) = given else {
        return Ok(estimate.radius);
    };
    if verify_radius(input, r, &estimate).map_err(to_py)? == RadiusCheck::Doubtful {
        let message = format!(
            "particle_radius {r:?} is {:.2} × the radius the spacing of {}'s particles implies ({:?}); radius_check=False silences this",
            r / estimate.radius,
            input.display(),
            estimate.radius
        );
        user_warning(py, &message)?;
    }
    Ok(r)
}

/// The particle radius of a run whose particles carry a radius attribute: without
/// `given` the median; `given` checked against the median as against the estimate
/// (unless not `radius_check`).
fn radius_from_attribute(
    py: Python<'_>,
    given: Option<f32>,
    radius_check: bool,
    input: &std::path::Path,
    radii: &ParticleRadii,
) -> PyResult<f32> {
    use meniscus::radius::{check_radius, RadiusCheck};
    let median = radii.median();
    let source = format!("attribute {:?} of {}", radii.attribute, input.display());
    let Some(r) = given else {
        return Ok(median);
    };
    if !radius_check {
        return Ok(r);
    }
    let ratio = r / median;
    match check_radius(r, median) {
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
    Ok(r)
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
