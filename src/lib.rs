//! # meniscus
//!
//! Surface reconstruction for particle-based fluids (SPH, FLIP), following the pipeline of
//! Akinci, Ihmsen, Akinci, Solenthaler and Teschner, "An Efficient Surface Reconstruction
//! Pipeline for Particle-Based Fluids" (VRIPHYS 2012 / 2013), built as a sparse-grid engine.
//!
//! ```text
//!  particles ─► plan ─► store ─► tiles: isolate ─► kernels ─► field ─► marching cubes ─► sink
//!  (io)         (tiles)  (tiles)  (tiles, field::compute_tile, marching_cubes)            │
//!      ┌───────────────────────────────────────────────────────────────────────────────────┘
//!      └► decimation ─► smoothing ─► containment ─► subdivision ─► spheres ─► normals ─► attributes ─► write
//!         (decimation)  (smoothing)  (containment)  (subdivision)  (isolated)  (shading) (transfer)    (io, job)
//! ```
//!
//! [`pipeline::reconstruct`] runs that list for one frame ([`pipeline::ReconstructOptions`]
//! holds every stage's options, [`pipeline::ReconstructionStats`] what each stage did);
//! [`pipeline::reconstruct_sized`] is the same for a streamed source with per-particle
//! radii, the entry the front ends reach. [`job::run_frames`] runs it over files and `{}`
//! sequences into an output (files, one animated glTF, a `.mseq` archive, USD stages). The
//! modules, bottom up:
//!
//! * [`error`], [`cancel`]: typed errors naming the input; cancellation between stages.
//! * [`grid`]: the global lattice, its sparse 8³ blocks and half-blocks.
//! * [`mesh`]: the indexed triangle mesh, normals, topology checks, inside test.
//! * [`attributes`]: particle attributes (velocity, ...) and which a run carries.
//! * [`io`]: particle readers (xyz, VTK legacy and XML, `.pvd`, PLY, BGEO), mesh readers
//!   and writers (glTF, PLY, OBJ, VTK) and USD stages.
//! * [`radius`]: the particle radius a frame's spacing implies, per-particle radii from a
//!   point attribute, and the policy every front end follows to choose a run's radius.
//! * [`field`]: the scalar field (the paper's isotropic one and anisotropic kernels).
//! * [`marching_cubes`]: surface extraction with globally keyed vertices.
//! * [`decimation`], [`smoothing`], [`containment`], [`subdivision`], [`isolated`],
//!   [`shading`] (the written normals): the
//!   post-processing stages, each usable on its own mesh.
//! * [`tiles`]: the out-of-core engine (tiles under a memory budget, spill files,
//!   stitching).
//! * [`pipeline`]: one frame, stage by stage, with its options and timings.
//! * [`settings`]: the reconstruction options as the command line and the Python package
//!   take them (names, defaults, units: [`settings::SETTINGS`]).
//! * [`sequence`], [`job`]: frame patterns and selections; runs over many frames, with
//!   their job-level settings ([`job::settings`]: fps, threads, error bounds, up axis,
//!   memory budget).
//! * [`archive`]: the `.mseq` container for whole mesh sequences.
//!
//! `docs/architecture.md` draws the engine and its invariants.
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
pub mod radius;
pub mod sequence;
pub mod settings;
pub mod shading;
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
