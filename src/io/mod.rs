//! File input and output.
//!
//! * [`particles`]: particle readers (raw `.xyz`, legacy VTK, PLY, classic BGEO) behind one
//!   [`particles::read_particles`] entry that picks the format by extension.
//! * [`mesh`]: mesh writers (glTF `.glb`/`.gltf`, PLY, OBJ, legacy VTK) behind
//!   [`mesh::write_surface`]; every write is atomic (temporary file + rename).

pub(crate) mod atomic;
pub(crate) mod base64;
pub mod mesh;
pub mod particles;
pub(crate) mod ply_header;
pub(crate) mod tempfiles;
pub(crate) mod text;
pub mod usd;
pub(crate) mod vtk_legacy;
