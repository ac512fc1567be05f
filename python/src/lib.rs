//! `meniscus` for Python: the reconstruction pipeline in-process (pyo3), numpy arrays in,
//! a [`Mesh`] out. Options are named as the command line's, with the same defaults and
//! units (multiples of the particle radius `r`). The GIL is released while the library
//! works; Ctrl-C cancels the run (KeyboardInterrupt).

// pyo3 0.22's #[pymethods]/#[pyfunction] expansion converts a returned PyErr into itself.
#![allow(clippy::useless_conversion)]

mod archive;
mod arrays;
mod edges;
mod errors;
mod functions;
mod interrupt;
mod malloc;
mod mesh;
mod options;
mod radius;

use errors::FormatError;
use meniscus::settings::Preset;
use pyo3::prelude::*;

/// Surface reconstruction for particle-based fluids (Akinci et al. 2013 pipeline), in
/// process.
#[pymodule]
#[pyo3(name = "meniscus")]
fn meniscus_module(m: &Bound<'_, PyModule>) -> PyResult<()> {
    malloc::tune();
    m.add("FormatError", m.py().get_type_bound::<FormatError>())?;
    m.add_class::<mesh::Mesh>()?;
    m.add_function(wrap_pyfunction!(functions::reconstruct, m)?)?;
    m.add_function(wrap_pyfunction!(functions::estimate_radius, m)?)?;
    m.add_function(wrap_pyfunction!(functions::read_particles, m)?)?;
    m.add_function(wrap_pyfunction!(functions::reconstruct_file, m)?)?;
    m.add_class::<archive::Archive>()?;
    m.add_function(wrap_pyfunction!(archive::merge_archives, m)?)?;
    m.add("PAPER", options::preset_keywords(m.py(), Preset::Paper)?)?;
    m.add("STEADY", options::preset_keywords(m.py(), Preset::Steady)?)?;
    m.add(
        "VELOCITY_NAMES",
        pyo3::types::PyTuple::new_bound(m.py(), meniscus::attributes::VELOCITY_NAMES),
    )?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
