//! `meniscus` for Python: the reconstruction pipeline in-process (pyo3), numpy arrays in,
//! a [`Mesh`] out. Options are named as the command line's, with the same defaults and
//! units (multiples of the particle radius `r`). The GIL is released while the library
//! works; Ctrl-C cancels the run (KeyboardInterrupt).

// pyo3 0.22's #[pymethods]/#[pyfunction] expansion converts a returned PyErr into itself.
#![allow(clippy::useless_conversion)]

use glam::Vec3;
use meniscus::attributes::{Attribute, AttributeLayout};
use meniscus::decimation::DecimateOptions;
use meniscus::io::mesh::{write_surface, MeshWriteOptions};
use meniscus::io::particles::{ParticleChunk, ParticleSource};
use meniscus::mesh::{Surface, TriMesh};
use meniscus::pipeline::{reconstruct_source, ReconstructOptions, ReconstructionStats};
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
use pyo3::types::{PyDict, PyList};
use std::path::PathBuf;
use std::sync::mpsc;
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
fn to_py(e: Error) -> PyErr {
    let message = e.to_string();
    match e {
        Error::InvalidOption { .. }
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
fn run_interruptible<T: Send>(
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

/// Positions borrowed from a numpy array (or owned when converted), with attributes as
/// payload.
struct ArraySource<'a> {
    positions: &'a [Vec3],
    attributes: Vec<Attribute>,
}

const CHUNK: usize = 1 << 16;

impl ParticleSource for ArraySource<'_> {
    fn particle_count(&self) -> usize {
        self.positions.len()
    }
    fn attribute_layout(&self) -> Vec<AttributeLayout> {
        self.attributes.iter().map(AttributeLayout::of).collect()
    }
    fn visit_chunks(
        &self,
        visit: &mut dyn FnMut(ParticleChunk<'_>) -> meniscus::Result<()>,
    ) -> meniscus::Result<()> {
        let mut rows = Vec::new();
        for (n, chunk) in self.positions.chunks(CHUNK).enumerate() {
            let first = n * CHUNK;
            rows.clear();
            if !self.attributes.is_empty() {
                for i in first..first + chunk.len() {
                    for a in &self.attributes {
                        rows.extend_from_slice(a.item(i));
                    }
                }
            }
            visit(ParticleChunk {
                first,
                positions: chunk,
                payload: &rows,
            })?;
        }
        Ok(())
    }
    fn as_slices(&self) -> Option<(&[Vec3], &[f32])> {
        self.attributes
            .is_empty()
            .then_some((self.positions, &[][..]))
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
        _ => return Err(PyValueError::new_err(format!(
            "invalid attributes: {name:?} has shape {shape:?}; expected ({count},) or ({count}, k)"
        ))),
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

/// The options of the command line, in its units.
#[allow(clippy::too_many_arguments)]
fn options(
    particle_radius: f32,
    influence_radius: f32,
    cell_size: f32,
    decimate: Option<f32>,
    subdivide: u32,
    isolated_spheres: Option<u32>,
    iso_offset: f32,
    memory_budget: Option<&Bound<'_, PyAny>>,
) -> PyResult<ReconstructOptions> {
    let mut o = ReconstructOptions::new(particle_radius);
    o.field.influence_radius = influence_radius;
    o.field.cell_size = cell_size;
    o.field.iso_offset = iso_offset;
    o.isolated_sphere_level = isolated_spheres;
    o.subdivide.levels = subdivide;
    o.decimate = match decimate {
        None => None,
        Some(f) if (0.0..1.0).contains(&f) => Some(DecimateOptions {
            target_reduction: Some(f),
            ..Default::default()
        }),
        Some(f) => {
            return Err(PyValueError::new_err(format!(
                "invalid decimate: takes a fraction in [0, 1) or None, got {f}"
            )))
        }
    };
    o.tiles.memory_budget_bytes = match memory_budget {
        None => meniscus::tiles::default_memory_budget(),
        Some(b) if b.is_none() => meniscus::tiles::default_memory_budget(),
        Some(b) => Some(if let Ok(bytes) = b.extract::<u64>() {
            bytes
        } else {
            let text: String = b.extract().map_err(|_| {
                PyValueError::new_err(
                    "invalid memory_budget: bytes (int) or a size such as \"2GiB\"",
                )
            })?;
            meniscus::tiles::parse_memory_size(&text)
                .map_err(|e| PyValueError::new_err(format!("invalid memory_budget: {e}")))?
        }),
    };
    o.field.validate().map_err(to_py)?;
    Ok(o)
}

/// A reconstructed surface: the fluid and the isolated-particle spheres, merged into
/// `vertices` / `triangles` as the CLI's PLY/OBJ/VTK output holds them.
#[pyclass(module = "meniscus", frozen)]
struct Mesh {
    surface: Surface,
    merged: TriMesh,
    stats: Option<ReconstructionStats>,
}

impl Mesh {
    fn new(surface: Surface, stats: Option<ReconstructionStats>) -> Self {
        let merged = surface.merged();
        Mesh {
            surface,
            merged,
            stats,
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

#[pymethods]
impl Mesh {
    /// Vertex positions, (V, 3) float32: the fluid surface, then every sphere.
    #[getter]
    fn vertices<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f32>> {
        vec3s(py, &self.merged.positions)
    }

    /// Triangles, (T, 3) uint32 vertex indices, counter-clockwise seen from outside.
    #[getter]
    fn triangles<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<u32>> {
        let flat: Vec<u32> = self.merged.triangles.iter().flatten().copied().collect();
        Array2::from_shape_vec((self.merged.triangles.len(), 3), flat)
            .expect("3 per row")
            .into_pyarray_bound(py)
    }

    /// Unit vertex normals, (V, 3) float32 ((0, 3) when the mesh has none).
    #[getter]
    fn normals<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f32>> {
        vec3s(py, &self.merged.normals)
    }

    /// Per-vertex attributes carried from the particles: name → (V,) or (V, k) float32.
    #[getter]
    fn attributes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new_bound(py);
        for a in &self.merged.attributes {
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

    /// Number of vertices.
    #[getter]
    fn vertex_count(&self) -> usize {
        self.merged.positions.len()
    }

    /// Number of triangles.
    #[getter]
    fn triangle_count(&self) -> usize {
        self.merged.triangles.len()
    }

    /// Writes the surface to `path` (.ply, .obj, .glb, .gltf or .vtk by extension), as
    /// the CLI writes it (glTF keeps the spheres instanced). Returns the bytes written.
    #[pyo3(signature = (path, *, normals = true))]
    fn write(&self, py: Python<'_>, path: PathBuf, normals: bool) -> PyResult<u64> {
        let options = MeshWriteOptions {
            normals,
            ..MeshWriteOptions::default()
        };
        let surface = &self.surface;
        run_interruptible(py, |_| {
            write_surface(&path, surface, &options).map(|s| s.bytes)
        })
    }

    fn __repr__(&self) -> String {
        format!(
            "<meniscus.Mesh: {} vertices, {} triangles, {} spheres, attributes {:?}>",
            self.merged.positions.len(),
            self.merged.triangles.len(),
            self.surface.spheres.centers.len(),
            self.merged
                .attributes
                .iter()
                .map(|a| a.name.as_str())
                .collect::<Vec<_>>()
        )
    }
}

/// Reconstructs the surface of particles at `positions` ((N, 3) float32 or float64;
/// a C-contiguous float32 array is not copied) of radius `particle_radius` (world
/// units). See the module documentation for the options.
#[pyfunction]
#[pyo3(signature = (positions, particle_radius, *, attributes = None, influence_radius = 4.0,
    cell_size = 1.0, decimate = Some(0.8), subdivide = 1, isolated_spheres = Some(2),
    iso_offset = 0.0, threads = None, memory_budget = None))]
#[allow(clippy::too_many_arguments)]
fn reconstruct(
    py: Python<'_>,
    positions: &Bound<'_, PyAny>,
    particle_radius: f32,
    attributes: Option<&Bound<'_, PyDict>>,
    influence_radius: f32,
    cell_size: f32,
    decimate: Option<f32>,
    subdivide: u32,
    isolated_spheres: Option<u32>,
    iso_offset: f32,
    threads: Option<usize>,
    memory_budget: Option<&Bound<'_, PyAny>>,
) -> PyResult<Mesh> {
    check_threads(threads)?;
    let options = options(
        particle_radius,
        influence_radius,
        cell_size,
        decimate,
        subdivide,
        isolated_spheres,
        iso_offset,
        memory_budget,
    )?;
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
    let source = ArraySource {
        positions: slice,
        attributes: columns,
    };
    let (surface, stats) = run_interruptible(py, |cancel| {
        with_threads(threads, || {
            reconstruct_source(source, &options, &|_| {}, cancel)
        })
    })?;
    Ok(Mesh::new(surface, Some(stats)))
}

fn check_threads(threads: Option<usize>) -> PyResult<()> {
    if threads == Some(0) {
        return Err(PyValueError::new_err(
            "invalid threads: must be at least 1, got 0",
        ));
    }
    Ok(())
}

/// Surface reconstruction for particle-based fluids (Akinci et al. 2013 pipeline), in
/// process.
#[pymodule]
#[pyo3(name = "meniscus")]
fn meniscus_module(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("FormatError", m.py().get_type_bound::<FormatError>())?;
    m.add_class::<Mesh>()?;
    m.add_function(wrap_pyfunction!(reconstruct, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    let _ = PyList::empty_bound(m.py());
    Ok(())
}
