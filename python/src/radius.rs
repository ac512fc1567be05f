//! The particle radius of a Python call: the library's policy
//! ([`meniscus::radius::choose_radius`], as the CLI's) worded as keywords:
//! `particle_radius`, `radius_attribute`, `radius_check`.

use crate::errors::to_py;
use meniscus::radius::{ParticleRadii, RadiusAttribute, RadiusBasis, RadiusCheckOptions};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// The particle radius of a run, and the particles' radii when `radii` (a radius
/// attribute) holds them ([`meniscus::radius::choose_radius`]): with `radii` their
/// median, or `given` checked against it; otherwise the estimate, or `given` checked
/// against it (for a run whose kernel reaches `influence_radius` × r); unless not
/// `radius_check`. A doubtful `given` is a `UserWarning`, an implausible one a
/// `ValueError` with the library's message (naming `radius_check=False`); an estimate
/// that fails is raised, also with `given`. `input` names the particles in errors.
pub(crate) fn resolve_radius(
    py: Python<'_>,
    given: Option<f32>,
    radius_check: bool,
    influence_radius: f32,
    input: &std::path::Path,
    radii: Option<ParticleRadii>,
    estimate: impl FnOnce() -> meniscus::Result<meniscus::radius::RadiusEstimate> + Send,
) -> PyResult<(f32, Option<ParticleRadii>)> {
    let check = RadiusCheckOptions {
        influence_radius,
        force: FORCE,
    };
    let choice = py
        .allow_threads(|| {
            meniscus::radius::choose_radius(
                input,
                given,
                radius_check.then_some(check),
                Ok(radii),
                estimate,
            )
        })
        .map_err(to_py)?;
    if let RadiusBasis::Unmeasured(e) = choice.basis {
        return Err(to_py(e));
    }
    if let Some(warning) = &choice.warning {
        user_warning(py, &format!("{warning}; {FORCE} silences this"))?;
    }
    Ok((choice.radius, choice.radii))
}

/// How a Python caller runs with a refused radius, or silences a warning.
pub(crate) const FORCE: &str = "radius_check=False";

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
