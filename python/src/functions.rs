//! The module's functions: `reconstruct` (arrays in memory), `reconstruct_file` (files
//! and sequences, as the CLI's `reconstruct`), `estimate_radius` and `read_particles`.
//! They translate keywords into the library's settings and call it; the checks, the
//! radius policy and the job's options are the library's.

use crate::arrays::{attribute_array, attribute_of, positions_of, vec3s};
use crate::errors::to_py;
use crate::interrupt::{run_interruptible, with_threads};
use crate::malloc;
use crate::mesh::Mesh;
use crate::options::{self, Keywords};
use crate::radius::{radius_attribute, resolve_radius};
use meniscus::attributes::AttributeSelection;
use meniscus::io::particles::{ParticleFormat, ParticleSlices};
use meniscus::job::settings::{
    check_threads, parse_up_axis, parse_usd_droplets, DEFAULT_FPS, DEFAULT_METERS_PER_UNIT,
};
use meniscus::job::{plan_frames, run_frames, FrameReport, JobSettings};
use meniscus::pipeline::{reconstruct_sized, ReconstructOptions};
use meniscus::radius::{radii_of, read_radii};
use meniscus::settings::Preset;
use numpy::PyArray2;
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;
use std::sync::Mutex;

/// The library's options of a function's `**options` (see [`options::settings`]).
fn reconstruct_options(
    py: Python<'_>,
    function: &'static str,
    preset: Preset,
    particle_radius: f32,
    given: Option<&Bound<'_, PyDict>>,
) -> PyResult<ReconstructOptions> {
    let keywords = Keywords::new(py, function, given)?;
    let settings = options::settings(preset.settings(particle_radius), &keywords)?;
    keywords.finish()?;
    settings.options().map_err(to_py)
}

/// Reconstructs the surface of particles at `positions` ((N, 3) float32 or float64;
/// a C-contiguous float32 array is not copied) of radius `particle_radius` (world
/// units; default: estimated from their spacing, see [`resolve_radius`], which also
/// checks a given one unless `radius_check` is false). `**options` are the
/// reconstruction settings ([`options::SETTINGS`]).
#[pyfunction]
#[pyo3(signature = (positions, particle_radius = None, *, attributes = None, threads = None,
    radius_check = true, radius_attribute = None, preset = None, **options))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn reconstruct(
    py: Python<'_>,
    positions: &Bound<'_, PyAny>,
    particle_radius: Option<f32>,
    attributes: Option<&Bound<'_, PyDict>>,
    threads: Option<usize>,
    radius_check: bool,
    radius_attribute: Option<String>,
    preset: Option<&str>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<Mesh> {
    check_threads(threads).map_err(to_py)?;
    let preset = options::preset(preset)?.unwrap_or(Preset::Still);
    let influence_radius = reconstruct_options(
        py,
        "reconstruct",
        preset,
        particle_radius.unwrap_or(1.0),
        options,
    )?
    .field
    .influence_radius;
    let which = self::radius_attribute(radius_attribute)?;
    let positions = positions_of(positions)?;
    let slice = positions.as_slice();
    let mut columns = Vec::new();
    if let Some(d) = attributes {
        for (k, v) in d.iter() {
            let name: String = k
                .extract()
                .map_err(|_| PyValueError::new_err("invalid attributes: names must be strings"))?;
            columns.push(attribute_of(name, &v, slice.len())?);
        }
    }
    let input = std::path::Path::new("particles in memory");
    let radii = radii_of(input, &columns, slice.len(), &which).map_err(to_py)?;
    let (particle_radius, radii) = resolve_radius(
        py,
        particle_radius,
        radius_check,
        influence_radius,
        input,
        radii,
        || meniscus::radius::estimate_radius(slice),
    )?;
    let options = reconstruct_options(py, "reconstruct", preset, particle_radius, options)?;
    let source = ParticleSlices {
        positions: slice,
        attributes: &columns,
    };
    let result = run_interruptible(py, |cancel| {
        with_threads(threads, || {
            reconstruct_sized(source, radii, &options, &|_| {}, cancel)
        })
    });
    py.allow_threads(malloc::release_free_memory);
    let (surface, stats) = result?;
    Ok(Mesh::new(
        surface,
        Some(stats),
        Some(particle_radius),
        Some(options.subdivide.levels),
    ))
}

/// The particle radius the spacing of the particles at `positions` ((N, 3) float32 or
/// float64) implies, world units: what `reconstruct` takes without `particle_radius`
/// (meniscus::radius::estimate_radius).
#[pyfunction]
pub(crate) fn estimate_radius(py: Python<'_>, positions: &Bound<'_, PyAny>) -> PyResult<f32> {
    let positions = positions_of(positions)?;
    let slice = positions.as_slice();
    py.allow_threads(|| meniscus::radius::estimate_radius(slice))
        .map(|e| e.radius)
        .map_err(to_py)
}

/// Reads a particle file (.xyz, .vtk, .vtu, .vtp, .ply, .bgeo, by extension): positions (N, 3)
/// float32 and every point attribute, name → (N,) or (N, k) float32.
#[pyfunction]
pub(crate) fn read_particles<'py>(
    py: Python<'py>,
    path: PathBuf,
) -> PyResult<(Bound<'py, PyArray2<f32>>, Bound<'py, PyDict>)> {
    let particles =
        run_interruptible(py, |_| meniscus::io::particles::read_particles(&path, None))?;
    let attributes = PyDict::new_bound(py);
    for a in &particles.attributes {
        attributes.set_item(&a.name, attribute_array(py, a))?;
    }
    Ok((vec3s(py, &particles.positions), attributes))
}

/// The attribute selection of the CLI's --attributes: None (velocity when the input has
/// one), "none", "all", "a,b" or a list of names.
fn selection(attributes: Option<&Bound<'_, PyAny>>) -> PyResult<AttributeSelection> {
    let bad = |e: String| PyValueError::new_err(format!("invalid attributes: {e}"));
    match attributes {
        None => Ok(AttributeSelection::default()),
        Some(a) if a.is_none() => Ok(AttributeSelection::default()),
        Some(a) => {
            if let Ok(text) = a.extract::<String>() {
                text.parse().map_err(bad)
            } else if let Ok(names) = a.extract::<Vec<String>>() {
                if names.is_empty() {
                    Ok(AttributeSelection::None)
                } else {
                    Ok(AttributeSelection::Names(names))
                }
            } else {
                Err(bad(
                    "\"none\", \"all\", \"a,b\" or a list of names".to_string()
                ))
            }
        }
    }
}

/// Reconstructs a particle file (or a frame sequence: a `{}` pattern, a `.pvd`
/// collection) into `output` as the CLI's
/// `meniscus reconstruct INPUT -o OUTPUT` does (a mesh file, a `{}` pattern of them, a
/// `.mseq` archive, one `.glb` or one USD stage for a sequence; `up_axis` and
/// `meters_per_unit` are a stage's metadata), through the same library function
/// ([`run_frames`]). `frames`, `shard`, `start`/`end`, `keep_going` are the CLI's
/// `--frames`, `--shard`, `--start`/`--end`, `--keep-going`; `progress` is called with
/// each finished frame's `--json-progress` object (a dict). Returns one report per frame
/// (dicts as the CLI's `--stats` JSON); with `keep_going`, a failed frame is one with
/// status "failed" and an error, and the call returns normally.
#[pyfunction]
#[pyo3(signature = (input, output, particle_radius = None, *, attributes = None, threads = None, radius_check = true,
    radius_attribute = None,
    frames = None, shard = None, start = None, end = None, keep_going = false,
    progress = None, skip_existing = false, normals = true, error_bound = None,
    attribute_error_bound = meniscus::archive::DEFAULT_ATTRIBUTE_ERROR_BOUND, fps = DEFAULT_FPS,
    up_axis = "Y", meters_per_unit = DEFAULT_METERS_PER_UNIT, usd_droplets = "points", input_format = None, preset = None, **options))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn reconstruct_file<'py>(
    py: Python<'py>,
    input: String,
    output: String,
    particle_radius: Option<f32>,
    attributes: Option<&Bound<'_, PyAny>>,
    threads: Option<usize>,
    radius_check: bool,
    radius_attribute: Option<String>,
    frames: Option<&Bound<'_, PyAny>>,
    shard: Option<&Bound<'_, PyAny>>,
    start: Option<i64>,
    end: Option<i64>,
    keep_going: bool,
    progress: Option<Bound<'_, PyAny>>,
    skip_existing: bool,
    normals: bool,
    error_bound: Option<f64>,
    attribute_error_bound: f64,
    fps: f64,
    up_axis: &str,
    meters_per_unit: f64,
    usd_droplets: &str,
    input_format: Option<String>,
    preset: Option<&str>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    let preset =
        options::preset(preset)?.unwrap_or_else(|| Preset::for_input(std::path::Path::new(&input)));
    let mut job = JobSettings {
        normals,
        skip_existing,
        error_bound,
        attribute_error_bound,
        fps,
        meters_per_unit,
        threads,
        keep_going,
        ..JobSettings::default()
    };
    job.validate().map_err(to_py)?;
    job.up_axis = parse_up_axis(up_axis).map_err(to_py)?;
    job.usd_droplets = parse_usd_droplets(usd_droplets).map_err(to_py)?;
    let influence_radius = reconstruct_options(
        py,
        "reconstruct_file",
        preset,
        particle_radius.unwrap_or(1.0),
        options,
    )?
    .field
    .influence_radius;
    job.attributes = selection(attributes)?;
    let choice = options::frame_choice(start, end, frames, shard)?;
    let input_format = input_format
        .map(|f| f.parse::<ParticleFormat>())
        .transpose()
        .map_err(|e| PyValueError::new_err(format!("invalid input_format: {e}")))?;
    job.input_format = input_format;
    let first = plan_frames(&input, &output, &choice).map_err(to_py)?[0]
        .0
        .input
        .clone();
    job.radius_attribute = self::radius_attribute(radius_attribute)?;
    let which = &job.radius_attribute;
    let radii = match py.allow_threads(|| read_radii(&first, input_format, which)) {
        Ok(radii) => radii,
        // With a given radius the run reports the frame as it reads it (with
        // keep_going, as that frame's failure).
        Err(_) if particle_radius.is_some() => None,
        Err(e) => return Err(to_py(e)),
    };
    let (particle_radius, _) = resolve_radius(
        py,
        particle_radius,
        radius_check,
        influence_radius,
        &first,
        radii,
        || meniscus::radius::estimate_radius_of_file(&first, input_format),
    )?;
    let options = reconstruct_options(py, "reconstruct_file", preset, particle_radius, options)?;
    let progress = progress.filter(|p| !p.is_none()).map(Bound::unbind);
    // An exception of the progress callback: it stops the run and is raised.
    let raised: Mutex<Option<PyErr>> = Mutex::new(None);
    let run = run_interruptible(py, |cancel| {
        let plan = plan_frames(&input, &output, &choice)?;
        let job = job.options(particle_radius, cancel);
        let mut on_done = |report: &FrameReport| {
            let Some(callback) = &progress else { return };
            Python::with_gil(|py| {
                let line = report.progress_line().to_string();
                let called = py
                    .import_bound("json")
                    .and_then(|json| json.call_method1("loads", (line,)))
                    .and_then(|dict| callback.call1(py, (dict,)));
                if let Err(e) = called {
                    raised.lock().expect("not poisoned").get_or_insert(e);
                    cancel.cancel();
                }
            });
        };
        with_threads(threads, || {
            run_frames(
                &plan,
                &options,
                &job,
                &mut |_, _| {},
                &mut |_| {},
                &mut on_done,
            )
        })
    });
    if let Some(e) = raised.into_inner().expect("not poisoned") {
        return Err(e);
    }
    let text = serde_json::to_string(&run?).map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    py.import_bound("json")?.call_method1("loads", (text,))
}
