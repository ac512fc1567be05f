//! `meniscus.Mesh`: a reconstructed or decoded surface, its arrays, figures and writer.

use crate::arrays::{attribute_array, vec3s};
use crate::edges::{flat_pairs, number_edges};
use crate::interrupt::run_interruptible;
use meniscus::io::mesh::{write_surface, MeshWriteOptions};
use meniscus::io::usd::{write_stage, UsdFormat, UsdOptions};
use meniscus::mesh::Surface;
use meniscus::pipeline::ReconstructionStats;
use numpy::ndarray::Array2;
use numpy::IntoPyArray;
use numpy::{PyArray1, PyArray2};
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use std::path::PathBuf;

/// A reconstructed surface: the fluid and the isolated-particle spheres, merged into
/// `vertices` / `triangles` as the CLI's PLY/OBJ/VTK output holds them.
///
/// It holds the surface only (spheres as instances); the getters merge it each time they
/// are called. Keeping the merged copy as well took a mesh from 2.0 to 5.3 MiB on frame
/// 25, and a caller's previous mesh is alive while the next call works.
#[pyclass(module = "meniscus", frozen)]
pub struct Mesh {
    pub(crate) surface: Surface,
    stats: Option<ReconstructionStats>,
    /// The particle radius it was reconstructed with (unknown for an archive's frame).
    pub(crate) particle_radius: Option<f32>,
    /// The Loop steps it was reconstructed with (unknown for an archive's frame).
    pub(crate) subdivided: Option<u32>,
}

impl Mesh {
    /// A mesh read from an archive: no figures, radius or subdivision known.
    pub(crate) fn decoded(surface: Surface) -> Self {
        Mesh::new(surface, None, None, None)
    }

    pub(crate) fn new(
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
        let count = edges.len();
        let edges = Array2::from_shape_vec((count, 2), flat_pairs(edges))
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
