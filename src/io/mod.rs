//! File input and output.
//!
//! * [`particles`]: particle readers (raw `.xyz`, legacy VTK, VTK XML `.vtu`/`.vtp` and
//!   ParaView `.pvd` collections, PLY, classic BGEO) behind one
//!   [`particles::read_particles`] entry that picks the format by extension, and streaming
//!   sources for the out-of-core engine.
//! * [`mesh`]: mesh readers and writers (glTF `.glb`/`.gltf`, PLY, OBJ, legacy VTK) behind
//!   [`mesh::write_surface`]; every write is atomic (temporary file + rename).
//! * [`usd`]: USD stages (`.usda` text, `.usdc` crate, `.usd`): the surface at each time
//!   code, with `upAxis` and `metersPerUnit`.
//!
//! Shared helpers stay crate-private: atomic writes, base64, PLY headers, temporary-file
//! hygiene, text parsing, the legacy VTK parser.

pub(crate) mod atomic;
pub(crate) mod base64;
pub mod mesh;
pub mod particles;
pub(crate) mod ply_header;
pub(crate) mod tempfiles;
pub(crate) mod text;
pub mod usd;
pub(crate) mod vtk_legacy;
