//! `.mseq` archives from Python: the `Archive` class and `merge_archives`.

use crate::interrupt::run_interruptible;
use crate::mesh::Mesh;
use meniscus::archive::{ArchiveFrame, ArchiveOptions, ArchiveReader, ArchiveWriter};
use meniscus::Error;
use pyo3::exceptions::{PyKeyError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// A `.mseq` archive of meshes, one per frame number: `len(a)`, `a.frames`, `a[frame]`,
/// `a.append(frame, mesh)`, `a.verify()`. The file is created by the first append.
#[pyclass(module = "meniscus")]
pub struct Archive {
    path: PathBuf,
    error_bound: Option<f64>,
    attribute_error_bound: f64,
}

impl Archive {
    fn reader(&self, py: Python<'_>) -> PyResult<Option<ArchiveReader>> {
        if !self.path.exists() {
            return Ok(None);
        }
        let path = &self.path;
        run_interruptible(py, |_| ArchiveReader::open(path)).map(Some)
    }
}

#[pymethods]
impl Archive {
    /// Opens (or names, for a new archive) the archive at `path`. `error_bound` (world
    /// units) bounds the positions of appended frames (default 0.01 × the particle
    /// radius of the mesh); `attribute_error_bound` their attributes.
    #[new]
    #[pyo3(signature = (path, *, error_bound = None,
        attribute_error_bound = meniscus::archive::DEFAULT_ATTRIBUTE_ERROR_BOUND))]
    fn new(path: PathBuf, error_bound: Option<f64>, attribute_error_bound: f64) -> Self {
        Archive {
            path,
            error_bound,
            attribute_error_bound,
        }
    }

    fn __len__(&self, py: Python<'_>) -> PyResult<usize> {
        Ok(self.reader(py)?.map_or(0, |r| r.frames().len()))
    }

    /// The frame numbers held, in file order.
    #[getter]
    fn frames(&self, py: Python<'_>) -> PyResult<Vec<i64>> {
        Ok(self
            .reader(py)?
            .map_or_else(Vec::new, |r| r.frames().iter().map(|f| f.number).collect()))
    }

    fn __contains__(&self, py: Python<'_>, frame: i64) -> PyResult<bool> {
        Ok(self.frames(py)?.contains(&frame))
    }

    /// The mesh of frame `frame` (decoded, with normals); KeyError when not held.
    fn __getitem__(&self, py: Python<'_>, frame: i64) -> PyResult<Mesh> {
        let reader = self.reader(py)?;
        let reader = match reader {
            Some(r) if r.frames().iter().any(|f| f.number == frame) => r,
            Some(r) => {
                return Err(PyKeyError::new_err(format!(
                    "frame {frame}: {} ({})",
                    r.absent_frame_message(),
                    self.path.display()
                )))
            }
            None => {
                return Err(PyKeyError::new_err(format!(
                    "frame {frame}: {} does not exist yet (the first append creates it)",
                    self.path.display()
                )))
            }
        };
        let surface = run_interruptible(py, |_| reader.read_surface(frame))?;
        Ok(Mesh::decoded(surface))
    }

    /// Appends `mesh` as frame `frame` (creating the archive); returns the bytes
    /// written. A frame number already held is refused (FileExistsError). `subdivide`:
    /// Loop steps the archive's reader applies to `mesh`, which is then the control mesh
    /// (the CLI stores a `.mseq` frame so: reconstructed with `defer_subdivision=True`,
    /// appended with `subdivide=1`, it is the CLI's frame, byte for byte).
    #[pyo3(signature = (frame, mesh, *, error_bound = None, subdivide = 0))]
    fn append(
        &self,
        py: Python<'_>,
        frame: i64,
        mesh: &Mesh,
        error_bound: Option<f64>,
        subdivide: u32,
    ) -> PyResult<u64> {
        if subdivide > 0 {
            if let Some(levels) = mesh.subdivided.filter(|&l| l > 0) {
                return Err(PyValueError::new_err(format!(
                    "invalid subdivide: the mesh is subdivided already (reconstructed with subdivide={levels}); reconstruct it with defer_subdivision=True to append its control mesh"
                )));
            }
        }
        let given = error_bound.or(self.error_bound);
        let path = &self.path;
        let surface = &mesh.surface;
        let radius = mesh.particle_radius;
        let attribute_error_bound = self.attribute_error_bound;
        run_interruptible(py, |_| {
            let held = if path.exists() {
                let reader = ArchiveReader::open(path)?;
                reader.check_new_frames(&[frame])?;
                // One archive, one bound: by default, the one its frames have.
                reader.frames().first().map(|f| f.step / 2.0)
            } else {
                None
            };
            let error_bound = given
                .or(held)
                .or(radius.map(meniscus::archive::default_error_bound))
                .ok_or(Error::InvalidOption {
                    option: "error_bound",
                    message: "a mesh read from an archive has no particle radius; give the bound (world units)".into(),
                })?;
            let options = ArchiveOptions {
                attribute_error_bound,
                ..ArchiveOptions::new(error_bound)
            };
            let mut writer = if path.exists() {
                ArchiveWriter::open_append(path, &options)?
            } else {
                ArchiveWriter::create(path, &options)?
            };
            let bytes = writer.append_frame(
                frame,
                &ArchiveFrame {
                    fluid: &surface.fluid,
                    subdivision_levels: subdivide,
                    spheres: &surface.spheres,
                },
            )?;
            writer.finish()?;
            Ok(bytes)
        })
    }

    /// Decodes every frame and checks it: a dict with `clean` (bool), `good` (frame
    /// numbers), `damaged` ([frame, why]), `damage` (other damage), `trailing_bytes`,
    /// `recovered_by_scan`.
    fn verify<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let path = &self.path;
        let report = run_interruptible(py, |_| Ok(ArchiveReader::open(path)?.verify()))?;
        let d = PyDict::new_bound(py);
        d.set_item("clean", report.is_clean())?;
        d.set_item("good", report.good)?;
        d.set_item("damaged", report.damaged)?;
        d.set_item("damage", report.damage)?;
        d.set_item("trailing_bytes", report.trailing_bytes)?;
        d.set_item("recovered_by_scan", report.recovered_by_scan)?;
        Ok(d)
    }

    fn __repr__(&self) -> String {
        format!("<meniscus.Archive {}>", self.path.display())
    }
}

/// Joins the archives `inputs` into `output` without re-encoding (`meniscus archive
/// merge`): frames in increasing order, records copied byte for byte, so the result is
/// the archive one writer appending every frame in order would have written. Returns
/// `inputs`, `frames` and `bytes`.
#[pyfunction]
pub fn merge_archives<'py>(
    py: Python<'py>,
    inputs: Vec<PathBuf>,
    output: PathBuf,
) -> PyResult<Bound<'py, PyDict>> {
    let stats = run_interruptible(py, |_| meniscus::archive::merge(&inputs, &output))?;
    let d = PyDict::new_bound(py);
    d.set_item("inputs", stats.inputs)?;
    d.set_item("frames", stats.frames)?;
    d.set_item("bytes", stats.bytes)?;
    Ok(d)
}
