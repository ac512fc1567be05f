//! `meniscus` for Python: the reconstruction pipeline in-process (pyo3), numpy arrays in,
//! a [`Mesh`] out. Options are named as the command line's, with the same defaults and
//! units (multiples of the particle radius `r`). The GIL is released while the library
//! works; Ctrl-C cancels the run (KeyboardInterrupt).

// pyo3 0.22's #[pymethods]/#[pyfunction] expansion converts a returned PyErr into itself.
#![allow(clippy::useless_conversion)]

use glam::Vec3;
use meniscus::attributes::Attribute;
use meniscus::attributes::AttributeSelection;
use meniscus::io::mesh::{write_surface, MeshWriteOptions};
use meniscus::io::particles::ParticleFormat;
use meniscus::io::particles::ParticleSlices;
use meniscus::io::usd::{write_stage, UpAxis, UsdFormat, UsdOptions};
use meniscus::job::{plan_frames, run_frames, FrameReport, JobOptions};
use meniscus::mesh::Surface;
use meniscus::pipeline::{reconstruct_sized, ReconstructOptions, ReconstructionStats};
use meniscus::radius::{radii_of, read_radii};
use options::Keywords;

mod archive;
mod malloc;
mod options;
mod radius;
use meniscus::{CancelToken, Error};
use numpy::ndarray::Array2;
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods,
};
use pyo3::create_exception;
use pyo3::exceptions::{
    PyFileExistsError, PyKeyboardInterrupt, PyOSError, PyRuntimeError, PyValueError,
};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use radius::{radius_attribute, resolve_radius};
use std::path::PathBuf;
use std::sync::{mpsc, Mutex};
use std::time::Duration;

create_exception!(
    meniscus,
    FormatError,
    PyValueError,
    "A particle, mesh or archive file whose content is malformed or whose format is not supported."
);

/// How often the caller's thread looks for a pending signal (Ctrl-C) while the library
/// works.
const SIGNAL_POLL: Duration = Duration::from_millis(100);

/// The Python exception for a library error.
pub(crate) fn to_py(e: Error) -> PyErr {
    let message = e.to_string();
    match e {
        Error::InvalidOption { .. }
        | Error::ImplausibleRadius { .. }
        | Error::ParticleOutOfRange { .. }
        | Error::MemoryBudget { .. } => PyValueError::new_err(message),
        Error::Io { path, source } | Error::Spill { path, source } => match source.raw_os_error() {
            // OSError(errno, strerror, filename) becomes FileNotFoundError, PermissionError, ...
            Some(errno) => PyOSError::new_err((errno, source.to_string(), path)),
            None => PyOSError::new_err(message),
        },
        Error::NoSpace { .. } => PyOSError::new_err(message),
        Error::Parse { .. }
        | Error::UnsupportedFormat { .. }
        | Error::Attribute { .. }
        | Error::InvalidRadius { .. }
        | Error::EmptyInput { .. } => FormatError::new_err(message),
        Error::FramesExist { .. } => PyFileExistsError::new_err(message),
        Error::Interrupted => PyKeyboardInterrupt::new_err(message),
        _ => PyRuntimeError::new_err(message),
    }
}

/// Runs `work` without the GIL on a scoped worker thread while the calling thread waits,
/// taking the GIL every [`SIGNAL_POLL`] to run Python's signal handlers. A handler that
/// raises (Ctrl-C: KeyboardInterrupt) cancels the token; the worker stops at its next
/// check, and the handler's exception is raised once it has (its temporary files
/// removed).
pub(crate) fn run_interruptible<T: Send>(
    py: Python<'_>,
    work: impl FnOnce(&CancelToken) -> meniscus::Result<T> + Send,
) -> PyResult<T> {
    let cancel = CancelToken::new();
    std::thread::scope(|scope| {
        let (done_tx, done_rx) = mpsc::channel::<()>();
        // Shared with each waiting closure, which must be Sync-captured.
        let done_rx = std::sync::Mutex::new(done_rx);
        let token = &cancel;
        let worker = scope.spawn(move || {
            let result = work(token);
            let _ = done_tx.send(());
            result
        });
        let mut raised: Option<PyErr> = None;
        loop {
            let finished = py.allow_threads(|| {
                match done_rx
                    .lock()
                    .expect("not poisoned")
                    .recv_timeout(SIGNAL_POLL)
                {
                    Ok(()) | Err(mpsc::RecvTimeoutError::Disconnected) => true,
                    Err(mpsc::RecvTimeoutError::Timeout) => false,
                }
            });
            if finished {
                break;
            }
            if raised.is_none() {
                if let Err(e) = py.check_signals() {
                    cancel.cancel();
                    raised = Some(e);
                }
            }
        }
        let result = py.allow_threads(|| worker.join());
        let result = match result {
            Ok(r) => r,
            Err(panic) => std::panic::resume_unwind(panic),
        };
        match (raised, result) {
            // The signal handler's exception (KeyboardInterrupt) wins over the
            // cancelled run's Error::Interrupted.
            (Some(e), Err(_)) => Err(e),
            (Some(e), Ok(_)) => Err(e),
            (None, r) => r.map_err(to_py),
        }
    })
}

/// Runs `f` on a pool of `threads` workers, or on the global pool.
fn with_threads<T: Send>(
    threads: Option<usize>,
    f: impl FnOnce() -> meniscus::Result<T> + Send,
) -> meniscus::Result<T> {
    match threads {
        None => f(),
        Some(n) => {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .map_err(|e| Error::InvalidOption {
                    option: "threads",
                    message: e.to_string(),
                })?;
            pool.install(f)
        }
    }
}

/// An (N, 3) array's rows as `Vec3`: borrowed when it is C-contiguous float32, else
/// converted (float64, strided).
enum Positions<'py> {
    Borrowed(numpy::PyReadonlyArray2<'py, f32>),
    Owned(Vec<Vec3>),
}

fn positions_of<'py>(array: &Bound<'py, PyAny>) -> PyResult<Positions<'py>> {
    let bad = |what: String| {
        PyValueError::new_err(format!(
            "invalid positions: expected an (N, 3) float32 or float64 array, got {what}"
        ))
    };
    if let Ok(a) = array.downcast::<PyArray2<f32>>() {
        let shape = a.shape();
        if shape[1] != 3 {
            return Err(bad(format!("shape {shape:?}")));
        }
        let a = a.readonly();
        if a.is_c_contiguous() {
            return Ok(Positions::Borrowed(a));
        }
        let v = a.as_array();
        return Ok(Positions::Owned(
            v.rows()
                .into_iter()
                .map(|r| Vec3::new(r[0], r[1], r[2]))
                .collect(),
        ));
    }
    if let Ok(a) = array.downcast::<PyArray2<f64>>() {
        let shape = a.shape();
        if shape[1] != 3 {
            return Err(bad(format!("shape {shape:?}")));
        }
        let a = a.readonly();
        let v = a.as_array();
        return Ok(Positions::Owned(
            v.rows()
                .into_iter()
                .map(|r| Vec3::new(r[0] as f32, r[1] as f32, r[2] as f32))
                .collect(),
        ));
    }
    match array.downcast::<numpy::PyUntypedArray>() {
        Ok(a) => Err(bad(format!(
            "shape {:?} of dtype {}",
            a.shape(),
            a.dtype().str()?
        ))),
        Err(_) => Err(bad(format!("{}", array.get_type().name()?))),
    }
}

impl Positions<'_> {
    fn as_slice(&self) -> &[Vec3] {
        match self {
            Positions::Borrowed(a) => {
                let flat = a.as_slice().expect("C-contiguous");
                // SAFETY: Vec3 is three f32 (repr(C), align 4); the array holds 3 × N
                // floats, row-major.
                unsafe { std::slice::from_raw_parts(flat.as_ptr().cast::<Vec3>(), flat.len() / 3) }
            }
            Positions::Owned(v) => v,
        }
    }
}

/// One attribute from an (N,) or (N, k) array of any float dtype.
fn attribute_of(name: String, array: &Bound<'_, PyAny>, count: usize) -> PyResult<Attribute> {
    let np = array.py().import_bound("numpy")?;
    let converted = np
        .getattr("ascontiguousarray")?
        .call(
            (array,),
            Some(&[("dtype", "float32")].into_py_dict_bound(array.py())),
        )
        .map_err(|e| {
            PyValueError::new_err(format!(
                "invalid attributes: {name:?} is not a float array: {e}"
            ))
        })?;
    let a: PyReadonlyArrayDyn<f32> = converted.extract()?;
    let shape = a.shape().to_vec();
    let components = match shape.as_slice() {
        [n] if *n == count => 1,
        [n, k] if *n == count && *k > 0 => *k,
        _ => {
            return Err(PyValueError::new_err(format!(
            "invalid attributes: {name:?} has shape {shape:?}; expected ({count},) or ({count}, k)"
        )))
        }
    };
    let values = a.as_slice()?.to_vec();
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "invalid attributes: {name:?} of particle {} has a non-finite value {}",
            i / components,
            values[i]
        )));
    }
    Ok(Attribute {
        name,
        components,
        values,
    })
}

use pyo3::types::IntoPyDict;

/// The library's options of a function's `**options` (see [`options::settings`]).
fn reconstruct_options(
    py: Python<'_>,
    function: &'static str,
    particle_radius: f32,
    given: Option<&Bound<'_, PyDict>>,
) -> PyResult<ReconstructOptions> {
    let keywords = Keywords::new(py, function, given)?;
    let settings = options::settings(particle_radius, &keywords)?;
    keywords.finish()?;
    settings.options().map_err(to_py)
}

/// A reconstructed surface: the fluid and the isolated-particle spheres, merged into
/// `vertices` / `triangles` as the CLI's PLY/OBJ/VTK output holds them.
///
/// It holds the surface only (spheres as instances); the getters merge it each time they
/// are called. Keeping the merged copy as well took a mesh from 2.0 to 5.3 MiB on frame
/// 25, and a caller's previous mesh is alive while the next call works.
#[pyclass(module = "meniscus", frozen)]
pub struct Mesh {
    surface: Surface,
    stats: Option<ReconstructionStats>,
    /// The particle radius it was reconstructed with (unknown for an archive's frame).
    particle_radius: Option<f32>,
    /// The Loop steps it was reconstructed with (unknown for an archive's frame).
    subdivided: Option<u32>,
}

impl Mesh {
    /// A mesh read from an archive: no figures, radius or subdivision known.
    fn decoded(surface: Surface) -> Self {
        Mesh::new(surface, None, None, None)
    }

    fn new(
        surface: Surface,
        stats: Option<ReconstructionStats>,
        particle_radius: Option<f32>,
        subdivided: Option<u32>,
    ) -> Self {
        Mesh {
            surface,
            stats,
            particle_radius,
            subdivided,
        }
    }
}

fn vec3s<'py>(py: Python<'py>, v: &[Vec3]) -> Bound<'py, PyArray2<f32>> {
    let flat: Vec<f32> = v.iter().flat_map(|p| p.to_array()).collect();
    Array2::from_shape_vec((v.len(), 3), flat)
        .expect("3 per row")
        .into_pyarray_bound(py)
}

fn attribute_array<'py>(py: Python<'py>, a: &Attribute) -> Bound<'py, PyAny> {
    if a.components == 1 {
        PyArray1::from_slice_bound(py, &a.values).into_any()
    } else {
        Array2::from_shape_vec((a.len(), a.components), a.values.clone())
            .expect("components per row")
            .into_pyarray_bound(py)
            .into_any()
    }
}

/// The edges of `triangles` over `vertices` vertices, each unordered vertex pair once
/// (numbered in order of their smaller, then larger vertex), and the edge of every
/// triangle side (side k of triangle t joins corners k and k + 1 mod 3) at 3t + k.
fn number_edges(triangles: &[[u32; 3]], vertices: usize) -> (Vec<[i32; 2]>, Vec<i32>) {
    // Sides bucketed by their smaller vertex, then numbered bucket by bucket.
    let mut start = vec![0u32; vertices + 1];
    for t in triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            start[a.min(b) as usize + 1] += 1;
        }
    }
    for v in 0..vertices {
        start[v + 1] += start[v];
    }
    let mut fill = start.clone();
    // Each side as (larger vertex << 32 | side index): a bucket sorts without looking
    // its sides up.
    let mut sides = vec![0u64; 3 * triangles.len()];
    for (i, t) in triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let low = a.min(b) as usize;
            sides[fill[low] as usize] = (u64::from(a.max(b)) << 32) | (3 * i + k) as u64;
            fill[low] += 1;
        }
    }
    let mut edges: Vec<[i32; 2]> = Vec::with_capacity(3 * triangles.len() / 2 + 1);
    let mut corners = vec![0i32; 3 * triangles.len()];
    for a in 0..vertices {
        let bucket = &mut sides[start[a] as usize..start[a + 1] as usize];
        bucket.sort_unstable();
        let mut previous = None;
        for &s in bucket.iter() {
            let b = (s >> 32) as u32;
            if previous != Some(b) {
                edges.push([a as i32, b as i32]);
                previous = Some(b);
            }
            corners[(s & 0xffff_ffff) as usize] = (edges.len() - 1) as i32;
        }
    }
    (edges, corners)
}

#[pymethods]
impl Mesh {
    /// Vertex positions, (V, 3) float32: the fluid surface, then every sphere.
    #[getter]
    fn vertices<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f32>> {
        vec3s(py, &self.surface.merged().positions)
    }

    /// Triangles, (T, 3) uint32 vertex indices, counter-clockwise seen from outside.
    #[getter]
    fn triangles<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<u32>> {
        let triangles = self.surface.merged().triangles;
        let flat: Vec<u32> = triangles.iter().flatten().copied().collect();
        Array2::from_shape_vec((triangles.len(), 3), flat)
            .expect("3 per row")
            .into_pyarray_bound(py)
    }

    /// Unit vertex normals, (V, 3) float32 ((0, 3) when the mesh has none).
    #[getter]
    fn normals<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f32>> {
        vec3s(py, &self.surface.merged().normals)
    }

    /// Per-vertex attributes carried from the particles: name → (V,) or (V, k) float32.
    #[getter]
    fn attributes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new_bound(py);
        for a in &self.surface.merged().attributes {
            d.set_item(&a.name, attribute_array(py, a))?;
        }
        Ok(d)
    }

    /// The run's figures: counts and the per-stage table (`stages`: stage, seconds,
    /// triangles, peak_rss_bytes), as the CLI's `--stats` JSON; empty for a mesh read
    /// from an archive.
    #[getter]
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        match &self.stats {
            None => Ok(PyDict::new_bound(py).into_any()),
            Some(s) => {
                let text =
                    serde_json::to_string(s).map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
                py.import_bound("json")?.call_method1("loads", (text,))
            }
        }
    }

    /// The fluid surface alone, without the spheres (what a player swaps in each frame,
    /// with no merging): `(vertices (V, 3) float32, triangles (T, 3) uint32, normals
    /// (V, 3) or (0, 3) float32, attributes: name → (V,) or (V, k) float32)`.
    fn fluid<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        let fluid = &self.surface.fluid;
        let flat: Vec<u32> = fluid.triangles.iter().flatten().copied().collect();
        let triangles = Array2::from_shape_vec((fluid.triangles.len(), 3), flat)
            .expect("3 per row")
            .into_pyarray_bound(py);
        let attributes = PyDict::new_bound(py);
        for a in &fluid.attributes {
            attributes.set_item(&a.name, attribute_array(py, a))?;
        }
        Ok(PyTuple::new_bound(
            py,
            [
                vec3s(py, &fluid.positions).into_any(),
                triangles.into_any(),
                vec3s(py, &fluid.normals).into_any(),
                attributes.into_any(),
            ],
        ))
    }

    /// The fluid surface's edges, as Blender's meshes store them (so a player need not
    /// compute them: Blender takes 0.8 s for a 1 M-triangle mesh): `(edges (E, 2) int32,
    /// each vertex pair once, corner_edges (3T,) int32, the edge from corner k of a
    /// triangle to its next corner)`.
    fn fluid_edges<'py>(&self, py: Python<'py>) -> Bound<'py, PyTuple> {
        let fluid = &self.surface.fluid;
        let (edges, corners) =
            py.allow_threads(|| number_edges(&fluid.triangles, fluid.positions.len()));
        let flat: Vec<i32> = edges.iter().flatten().copied().collect();
        let edges = Array2::from_shape_vec((edges.len(), 2), flat)
            .expect("2 per row")
            .into_pyarray_bound(py);
        PyTuple::new_bound(
            py,
            [
                edges.into_any(),
                PyArray1::from_vec_bound(py, corners).into_any(),
            ],
        )
    }

    /// Per-sphere attributes (the value of each isolated particle): name → (S,) or (S, k)
    /// float32.
    #[getter]
    fn sphere_attributes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new_bound(py);
        for a in &self.surface.spheres.attributes {
            d.set_item(&a.name, attribute_array(py, a))?;
        }
        Ok(d)
    }

    /// Radius of the sphere template (the particle radius r), world units: the mean
    /// distance of its vertices from its centre; 0 without spheres. Sphere k has radius
    /// `sphere_radius * sphere_scales[k]`.
    #[getter]
    fn sphere_radius(&self) -> f32 {
        let t = &self.surface.spheres.template.positions;
        if t.is_empty() {
            return 0.0;
        }
        (t.iter().map(|p| p.length() as f64).sum::<f64>() / t.len() as f64) as f32
    }

    /// Centres of the isolated-particle spheres, (S, 3) float32.
    #[getter]
    fn sphere_centers<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f32>> {
        vec3s(py, &self.surface.spheres.centers)
    }

    /// Each sphere's scale, (S,) float32: its radius over `particle_radius` (1 when the
    /// particles share one radius).
    #[getter]
    fn sphere_scales<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        let s = &self.surface.spheres;
        if s.scales.is_empty() {
            PyArray1::from_vec_bound(py, vec![1.0; s.centers.len()])
        } else {
            PyArray1::from_slice_bound(py, &s.scales)
        }
    }

    /// Number of vertices.
    #[getter]
    fn vertex_count(&self) -> usize {
        let Surface { fluid, spheres } = &self.surface;
        fluid.positions.len() + spheres.centers.len() * spheres.template.positions.len()
    }

    /// Number of triangles.
    #[getter]
    fn triangle_count(&self) -> usize {
        let Surface { fluid, spheres } = &self.surface;
        fluid.triangles.len() + spheres.centers.len() * spheres.template.triangles.len()
    }

    /// Writes the surface to `path` (.ply, .obj, .glb, .gltf, .vtk, or a USD stage
    /// .usdc, .usda, .usd, by extension), as the CLI writes it (glTF keeps the spheres
    /// instanced, USD has them as a point cloud with widths and velocities). A stage holds the surface at time
    /// code `frame` (other formats have no time). Returns the bytes written.
    #[pyo3(signature = (path, *, normals = true, frame = 0))]
    fn write(&self, py: Python<'_>, path: PathBuf, normals: bool, frame: i64) -> PyResult<u64> {
        let surface = &self.surface;
        if UsdFormat::from_path(&path).is_ok() {
            let options = UsdOptions {
                normals,
                ..UsdOptions::default()
            };
            return run_interruptible(py, |_| {
                write_stage(&path, frame, surface, &options).map(|s| s.bytes)
            });
        }
        let options = MeshWriteOptions {
            normals,
            ..MeshWriteOptions::default()
        };
        run_interruptible(py, |_| {
            write_surface(&path, surface, &options).map(|s| s.bytes)
        })
    }

    fn __repr__(&self) -> String {
        let merged = self.surface.merged();
        format!(
            "<meniscus.Mesh: {} vertices, {} triangles, {} spheres, attributes {:?}>",
            merged.positions.len(),
            merged.triangles.len(),
            self.surface.spheres.centers.len(),
            merged
                .attributes
                .iter()
                .map(|a| a.name.as_str())
                .collect::<Vec<_>>()
        )
    }
}

/// Reconstructs the surface of particles at `positions` ((N, 3) float32 or float64;
/// a C-contiguous float32 array is not copied) of radius `particle_radius` (world
/// units; default: estimated from their spacing, see [`resolve_radius`], which also
/// checks a given one unless `radius_check` is false). `**options` are the
/// reconstruction settings ([`options::SETTINGS`]).
#[pyfunction]
#[pyo3(signature = (positions, particle_radius = None, *, attributes = None, threads = None,
    radius_check = true, radius_attribute = None, **options))]
#[allow(clippy::too_many_arguments)]
fn reconstruct(
    py: Python<'_>,
    positions: &Bound<'_, PyAny>,
    particle_radius: Option<f32>,
    attributes: Option<&Bound<'_, PyDict>>,
    threads: Option<usize>,
    radius_check: bool,
    radius_attribute: Option<String>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<Mesh> {
    check_threads(threads)?;
    reconstruct_options(py, "reconstruct", particle_radius.unwrap_or(1.0), options)?;
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
    let particle_radius = resolve_radius(
        py,
        particle_radius,
        radius_check,
        input,
        radii.as_ref(),
        || meniscus::radius::estimate_radius(slice),
    )?;
    let options = reconstruct_options(py, "reconstruct", particle_radius, options)?;
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
fn estimate_radius(py: Python<'_>, positions: &Bound<'_, PyAny>) -> PyResult<f32> {
    let positions = positions_of(positions)?;
    let slice = positions.as_slice();
    py.allow_threads(|| meniscus::radius::estimate_radius(slice))
        .map(|e| e.radius)
        .map_err(to_py)
}

fn check_threads(threads: Option<usize>) -> PyResult<()> {
    if threads == Some(0) {
        return Err(PyValueError::new_err(
            "invalid threads: must be at least 1, got 0",
        ));
    }
    Ok(())
}

/// Reads a particle file (.xyz, .vtk, .vtu, .vtp, .ply, .bgeo, by extension): positions (N, 3)
/// float32 and every point attribute, name → (N,) or (N, k) float32.
#[pyfunction]
fn read_particles<'py>(
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
    attribute_error_bound = meniscus::archive::DEFAULT_ATTRIBUTE_ERROR_BOUND, fps = 24.0,
    up_axis = "Y", meters_per_unit = 1.0, usd_droplets = "points", input_format = None, **options))]
#[allow(clippy::too_many_arguments)]
fn reconstruct_file<'py>(
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
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    check_threads(threads)?;
    if !(fps.is_finite() && fps > 0.0) {
        return Err(PyValueError::new_err(format!(
            "invalid fps: must be > 0 (frames per second), got {fps}"
        )));
    }
    let up_axis: UpAxis = up_axis
        .parse()
        .map_err(|e| PyValueError::new_err(format!("invalid up_axis: {e}")))?;
    let usd_droplets: meniscus::io::usd::UsdDroplets = usd_droplets
        .parse()
        .map_err(|e| PyValueError::new_err(format!("invalid usd_droplets: {e}")))?;
    reconstruct_options(
        py,
        "reconstruct_file",
        particle_radius.unwrap_or(1.0),
        options,
    )?;
    let attributes = selection(attributes)?;
    let choice = options::frame_choice(start, end, frames, shard)?;
    let input_format = input_format
        .map(|f| f.parse::<ParticleFormat>())
        .transpose()
        .map_err(|e| PyValueError::new_err(format!("invalid input_format: {e}")))?;
    let first = plan_frames(&input, &output, &choice).map_err(to_py)?[0]
        .0
        .input
        .clone();
    let which = self::radius_attribute(radius_attribute)?;
    let radii = match py.allow_threads(|| read_radii(&first, input_format, &which)) {
        Ok(radii) => radii,
        // With a given radius the run reports the frame as it reads it (with
        // keep_going, as that frame's failure).
        Err(_) if particle_radius.is_some() => None,
        Err(e) => return Err(to_py(e)),
    };
    let particle_radius = resolve_radius(
        py,
        particle_radius,
        radius_check,
        &first,
        radii.as_ref(),
        || meniscus::radius::estimate_radius_of_file(&first, input_format),
    )?;
    let options = reconstruct_options(py, "reconstruct_file", particle_radius, options)?;
    let progress = progress.filter(|p| !p.is_none()).map(Bound::unbind);
    // An exception of the progress callback: it stops the run and is raised.
    let raised: Mutex<Option<PyErr>> = Mutex::new(None);
    let run = run_interruptible(py, |cancel| {
        let plan = plan_frames(&input, &output, &choice)?;
        let job = JobOptions {
            input_format,
            write: MeshWriteOptions {
                normals,
                ..MeshWriteOptions::default()
            },
            skip_existing,
            archive_error_bound: error_bound
                .unwrap_or(meniscus::archive::default_error_bound(particle_radius)),
            archive_attribute_error_bound: attribute_error_bound,
            fps,
            up_axis,
            meters_per_unit,
            usd_droplets,
            attributes,
            radius_attribute: which.clone(),
            cancel: cancel.clone(),
            keep_going,
        };
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

/// Surface reconstruction for particle-based fluids (Akinci et al. 2013 pipeline), in
/// process.
#[pymodule]
#[pyo3(name = "meniscus")]
fn meniscus_module(m: &Bound<'_, PyModule>) -> PyResult<()> {
    malloc::tune();
    m.add("FormatError", m.py().get_type_bound::<FormatError>())?;
    m.add_class::<Mesh>()?;
    m.add_function(wrap_pyfunction!(reconstruct, m)?)?;
    m.add_function(wrap_pyfunction!(estimate_radius, m)?)?;
    m.add_function(wrap_pyfunction!(read_particles, m)?)?;
    m.add_function(wrap_pyfunction!(reconstruct_file, m)?)?;
    m.add_class::<archive::Archive>()?;
    m.add_function(wrap_pyfunction!(archive::merge_archives, m)?)?;
    m.add("PAPER", options::paper(m.py())?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
