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
//! * [`decimation`], [`subdivision`], [`isolated`]: the post-processing stages.
//! * [`pipeline`]: the whole reconstruction of one frame, stage by stage, with timings.
//! * [`job`], [`sequence`]: files and `{}` frame sequences, as the CLI runs them.
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
#[cfg(test)]
mod test_rng;
pub mod tiles;

pub use error::{Error, Result};
pub use mesh::TriMesh;

/// Sets the C allocator up for frame-after-frame work; call it once at the start of a
/// program, before other threads (the `meniscus` command does).
///
/// glibc by default maps every block over 128 KiB (a threshold it raises as such blocks
/// are freed) and trims the free top of its heaps, so a program that decodes or
/// reconstructs frame after frame gets fresh pages for its buffers each time; on the
/// development VM page faults took a third of archive decoding. After this call blocks
/// under 32 MiB (glibc's own largest dynamic threshold) come from the heap and up to
/// 64 MiB of freed heap is kept for reuse; larger blocks (a big run's arrays) are still
/// mapped and returned when freed. Peak memory of the pipeline is unchanged (measured on
/// 1M- and 4M-particle scenes). Does nothing on other platforms.
pub fn tune_allocator() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets allocator parameters.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 64 << 20);
    }
}
