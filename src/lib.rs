//! # meniscus
//!
//! Surface reconstruction for particle-based fluids (SPH, FLIP), following the pipeline of
//! Akinci, Ihmsen, Akinci, Solenthaler and Teschner, "An Efficient Surface Reconstruction
//! Pipeline for Particle-Based Fluids" (VRIPHYS 2012 / 2013), built as a sparse-grid engine.
//!
//! ```text
//!  particles ──► isolated split ──► Solenthaler field ──► marching cubes ──► decimation ──► Loop ──► write
//!  (io)          (isolated)         (field, grid)         (marching_cubes)   (decimation)  (subdivision) (io)
//!                     └───────────────────────── icospheres of radius r ───────────────────────────┘
//! ```
//!
//! * [`io`]: particle readers (xyz, VTK, PLY, BGEO) and mesh writers (glTF, PLY, OBJ, VTK).
//! * [`grid`]: the global lattice and its sparse blocks.
//! * [`field`]: the Solenthaler et al. 2007 scalar field on the sparse lattice.
//! * [`marching_cubes`]: surface extraction with globally keyed vertices.
//! * [`mesh`]: the indexed triangle mesh, normals and topology validation.
//! * [`decimation`], [`subdivision`], [`isolated`]: the post-processing stages.
//! * [`pipeline`]: the whole reconstruction, stage by stage, with timings.
#![deny(missing_docs)]

pub mod archive;
pub mod decimation;
pub mod error;
pub mod field;
pub mod grid;
pub mod io;
pub mod isolated;
pub mod job;
pub mod marching_cubes;
pub mod mesh;
pub mod neighbors;
pub mod pipeline;
pub mod sequence;
pub mod subdivision;
pub mod tiles;

pub use error::{Error, Result};
pub use mesh::TriMesh;
