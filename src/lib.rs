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
//! * [`neighbors`]: the cell hash behind isolation checks.
//! * [`tiles`]: field and marching cubes tile by tile, stitched bit-identically.
//! * [`decimation`], [`containment`], [`subdivision`], [`isolated`]: the post-processing
//!   stages.
//! * [`attributes`]: particle attributes (velocity, ...) carried to the surface vertices.
//! * [`pipeline`]: the whole reconstruction of one frame, stage by stage, with timings.
//! * [`job`], [`sequence`]: files and `{}` frame sequences, as the CLI runs them.
//! * [`settings`]: the options as the CLI and the Python package take them.
//! * [`archive`]: the `.mseq` container for whole mesh sequences.
//!
//! ```no_run
//! use meniscus::io::particles::read_particles;
//! use meniscus::pipeline::{reconstruct, ReconstructOptions};
//! # fn main() -> meniscus::Result<()> {
//! let particles = read_particles("frame.bgeo".as_ref(), None)?;
//! let (surface, stats) = reconstruct(&particles.positions, &ReconstructOptions::new(0.01))?;
//! assert!(meniscus::mesh::validate(&surface.fluid).is_closed_manifold());
//! print!("{}", stats.table());
//! # Ok(())
//! # }
//! ```
#![deny(missing_docs)]

mod allocator;
pub mod archive;
pub mod attributes;
pub mod cancel;
pub mod containment;
pub mod decimation;
pub mod error;
pub mod field;
pub mod grid;
pub mod io;
pub mod isolated;
pub mod job;
pub mod marching_cubes;
pub mod mesh;
pub(crate) mod neighbors;
pub mod pipeline;
pub mod sequence;
pub mod settings;
pub mod smoothing;
pub mod subdivision;
#[cfg(test)]
mod test_rng;
pub mod tiles;
mod transfer;

pub use allocator::tune_allocator;
pub use cancel::CancelToken;
pub use error::{Error, Result};
pub use mesh::TriMesh;
