//! Mesh writers (and readers for round trips and for meshes from other tools), one file
//! per format: `gltf.rs`, `ply.rs`, `obj.rs`, `vtk.rs`, each with its reader and writer.
//!
//! | format | extension | what is written | attributes |
//! |---|---|---|---|
//! | glTF 2.0 binary | `.glb` | fluid mesh node + one sphere mesh instanced by a node per isolated particle (its `translation`, and its `scale` when the spheres have sizes of their own); POSITION (with min/max), NORMAL, u32 indices | `_NAME` float accessors (SCALAR/VEC2/VEC3/VEC4; `_NAME_0 … _NAME_k` scalars beyond 4 components); spheres with attributes become one merged mesh node `isolated_particles` |
//! | glTF 2.0 | `.gltf` | the same, with the buffer embedded as a base64 data URI (one self-contained file, so the write stays atomic) | as `.glb` |
//! | PLY | `.ply` | binary little-endian, float x y z (+ nx ny nz), uchar/uint face lists | float vertex properties `name` / `name_x name_y [name_z [name_w]]` / `name_0 … name_k` |
//! | OBJ | `.obj` | `v`, `vn`, `f a//a` (1-based) | none: listed in [`MeshWriteStats::dropped_attributes`] |
//! | legacy VTK | `.vtk` | binary POLYDATA with POLYGONS and NORMALS point data | in the one `POINT_DATA` section after NORMALS: `SCALARS name float 1` (1 component), `VECTORS name float` (3), a `FIELD` array otherwise |
//!
//! Attribute naming is detailed in `columns.rs`; [`read_mesh`] reads the attributes of
//! PLY, glTF and VTK back. PLY and VTK hold fluid and spheres in one vertex table, so
//! they carry the attributes both have (the others are reported as dropped). Attributes
//! with a wrong value count or whose names collide in the format are refused before
//! anything is written.
//!
//! Formats without instancing get the spheres as [`Surface::merged`] has them (each
//! instance scaled about its centre by its [`crate::mesh::SphereInstances::scales`]
//! factor). Sphere scales that do not fit the centres are refused before anything is
//! written. Every write is atomic: a failed write leaves no partial file and keeps an
//! existing target.

mod columns;
mod gltf;
mod gltf_check;
mod obj;
mod parts;
mod ply;
mod vtk;

use crate::error::{Error, Result};
use crate::io::atomic::write_atomically;
use crate::mesh::{Surface, TriMesh};
use std::path::Path;

/// Mesh file formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum MeshFormat {
    /// glTF 2.0 binary container.
    Glb,
    /// glTF 2.0 JSON with an embedded buffer.
    Gltf,
    /// Binary little-endian PLY.
    Ply,
    /// Wavefront OBJ.
    Obj,
    /// Legacy VTK, binary POLYDATA.
    Vtk,
}

const SUPPORTED: &str = "supported: .glb, .gltf, .ply, .obj, .vtk";

impl MeshFormat {
    /// The format named by a file's extension.
    pub fn from_path(path: &Path) -> Result<Self> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or_default()
            .to_ascii_lowercase();
        ext.parse().map_err(|_| Error::UnsupportedFormat {
            path: path.to_path_buf(),
            message: format!("unknown mesh file extension {ext:?}; {SUPPORTED}"),
        })
    }
}

impl std::str::FromStr for MeshFormat {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "glb" => Ok(MeshFormat::Glb),
            "gltf" => Ok(MeshFormat::Gltf),
            "ply" => Ok(MeshFormat::Ply),
            "obj" => Ok(MeshFormat::Obj),
            "vtk" => Ok(MeshFormat::Vtk),
            other => Err(format!("unknown mesh format {other:?}; {SUPPORTED}")),
        }
    }
}

/// Reads a triangle mesh; the format comes from the extension.
///
/// PLY (ASCII, binary LE / BE, any scalar types, polygon faces fan-triangulated), OBJ
/// (`v`, `f` with `v`, `v/t`, `v//n`, `v/t/n` and negative indices, polygons
/// fan-triangulated), glTF (`.glb`, `.gltf` with embedded buffers: every triangle
/// primitive of the default scene, node transforms applied) and legacy VTK (ASCII or
/// BINARY, `POINTS` and `POLYGONS`, polygons fan-triangulated). Attributes come back as
/// `columns.rs` names them (each format's file says which); OBJ has none.
pub fn read_mesh(path: &Path) -> Result<TriMesh> {
    let input = path.display().to_string();
    crate::error::guard(move || input, || read_mesh_unguarded(path))
}

fn read_mesh_unguarded(path: &Path) -> Result<TriMesh> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or_default()
        .to_ascii_lowercase();
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let mesh = match ext.as_str() {
        "ply" => ply::read(path, &bytes)?,
        "obj" => obj::read(path, &bytes)?,
        "glb" | "gltf" => gltf::read(path, &bytes)?,
        "vtk" => vtk::read(path, &bytes)?,
        _ => {
            return Err(Error::UnsupportedFormat {
                path: path.to_path_buf(),
                message: "mesh input must be .ply, .obj, .glb, .gltf or .vtk".into(),
            })
        }
    };
    let n = mesh.positions.len() as u32;
    if let Some(t) = mesh
        .triangles
        .iter()
        .position(|t| t.iter().any(|&i| i >= n))
    {
        return Err(Error::parse(
            path,
            format!("face {t}"),
            format!("vertex index out of range (the mesh has {n} vertices)"),
        ));
    }
    Ok(mesh)
}

/// Options of [`write_surface`].
#[derive(Clone, Debug, PartialEq)]
pub struct MeshWriteOptions {
    /// Format override; `None` chooses by extension. Default `None`.
    pub format: Option<MeshFormat>,
    /// Write vertex normals when the mesh has them. Default `true`.
    pub normals: bool,
}

impl Default for MeshWriteOptions {
    fn default() -> Self {
        MeshWriteOptions {
            format: None,
            normals: true,
        }
    }
}

/// What [`write_surface`] wrote.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct MeshWriteStats {
    /// Bytes of the output file.
    pub bytes: u64,
    /// Vertices written (all meshes and instances counted once per vertex stored).
    pub vertices: usize,
    /// Triangles represented (fluid plus every sphere instance).
    pub triangles: usize,
    /// Names of the attributes the file does not hold, each once: all of them for OBJ;
    /// for PLY and VTK those the fluid and the spheres do not both carry (one vertex
    /// table holds both). Empty when everything was written. The mesh is written anyway;
    /// callers warn about these.
    pub dropped_attributes: Vec<String>,
}

/// Writes a whole sequence, `(frame number, mesh)` in any order of the numbers, as one
/// glTF (`.glb` or `.gltf`), atomically: one node per frame named `frame_N` (fluid and
/// spheres merged), shown in turn by a step-interpolated scale animation at `fps` frames
/// per second, frame N from time N/`fps` (Blender's importer keys it at its frame N; a
/// gap in the numbering stays a gap; a sequence starting below 0 is shifted to start at
/// time 0), which Blender and three.js play back. A number given twice fails with
/// [`Error::FramesExist`]. Every frame is held in memory; for long sequences prefer a USD
/// stage ([`crate::io::usd`]) or a `.mseq` archive.
pub fn write_sequence_gltf(
    path: &Path,
    frames: &[(i64, TriMesh)],
    fps: f64,
    options: &MeshWriteOptions,
) -> Result<MeshWriteStats> {
    let format = match options.format {
        Some(f) => f,
        None => MeshFormat::from_path(path)?,
    };
    if !matches!(format, MeshFormat::Glb | MeshFormat::Gltf) {
        return Err(Error::UnsupportedFormat {
            path: path.to_path_buf(),
            message: "a sequence in one file needs .glb, .gltf or .mseq; use a {} pattern for one file per frame".into(),
        });
    }
    let mut ordered: Vec<&(i64, TriMesh)> = frames.iter().collect();
    ordered.sort_by_key(|(number, _)| *number);
    if let Some(pair) = ordered.windows(2).find(|w| w[0].0 == w[1].0) {
        return Err(Error::FramesExist {
            path: path.to_path_buf(),
            frames: vec![pair[0].0],
            planned: frames.len(),
        });
    }
    if !(fps.is_finite() && fps > 0.0) {
        return Err(Error::InvalidOption {
            option: "fps",
            message: format!("{fps} is not a positive finite number"),
        });
    }
    columns::check_frames(path, frames)?;
    let doc = gltf::build_sequence(&ordered, fps, options.normals);
    Ok(MeshWriteStats {
        bytes: write_document(path, &doc, format)?,
        vertices: doc.vertices,
        triangles: frames.iter().map(|(_, f)| f.triangle_count()).sum(),
        dropped_attributes: Vec::new(),
    })
}

/// Writes a glTF document as `.glb` or `.gltf`, atomically; returns the bytes written.
fn write_document(path: &Path, doc: &gltf::Document, format: MeshFormat) -> Result<u64> {
    write_atomically(path, |w| {
        if format == MeshFormat::Glb {
            doc.write_glb(w)
        } else {
            doc.write_gltf(w)
        }
    })
}

/// Writes `surface` to `path`, atomically.
pub fn write_surface(
    path: &Path,
    surface: &Surface,
    options: &MeshWriteOptions,
) -> Result<MeshWriteStats> {
    let format = match options.format {
        Some(f) => f,
        None => MeshFormat::from_path(path)?,
    };
    let triangles = surface.fluid.triangle_count()
        + surface.spheres.template.triangle_count() * surface.spheres.centers.len();
    let naming = match format {
        MeshFormat::Glb | MeshFormat::Gltf => Some(columns::Column::Gltf),
        MeshFormat::Ply => Some(columns::Column::Ply),
        MeshFormat::Vtk => Some(columns::Column::Vtk),
        MeshFormat::Obj => None,
    };
    columns::check_surface(path, surface, naming)?;
    surface
        .spheres
        .check_scales()
        .map_err(|message| Error::UnsupportedFormat {
            path: path.to_path_buf(),
            message,
        })?;
    let mut dropped_attributes = Vec::new();
    let (bytes, vertices) = match format {
        MeshFormat::Glb | MeshFormat::Gltf => {
            let doc = gltf::build(surface, options.normals);
            (write_document(path, &doc, format)?, doc.vertices)
        }
        other => {
            // The fluid as it is, then the spheres instance after instance (instancing is
            // glTF's only); nothing is merged in memory.
            let mut parts = vec![parts::Part::Mesh(&surface.fluid)];
            if !surface.spheres.centers.is_empty() {
                parts.push(parts::Part::Spheres(&surface.spheres));
            }
            let normals = options.normals && parts.iter().all(|p| p.has_normals());
            let shared = if other == MeshFormat::Obj {
                dropped_attributes = columns::all_names(surface);
                parts::Shared::new(&[], &mut Vec::new())
            } else {
                parts::Shared::new(&parts, &mut dropped_attributes)
            };
            let bytes = write_atomically(path, |w| match other {
                MeshFormat::Ply => ply::write(w, &parts, normals, &shared),
                MeshFormat::Obj => obj::write(w, &parts, normals),
                MeshFormat::Vtk => vtk::write(w, &parts, normals, &shared),
                MeshFormat::Glb | MeshFormat::Gltf => unreachable!(),
            })?;
            (
                bytes,
                surface.fluid.vertex_count()
                    + surface.spheres.template.vertex_count() * surface.spheres.centers.len(),
            )
        }
    };
    Ok(MeshWriteStats {
        bytes,
        vertices,
        triangles,
        dropped_attributes,
    })
}
