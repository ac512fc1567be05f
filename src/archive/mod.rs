//! `.mseq`: one file for a whole sequence of meshes — quantized, compressed, randomly
//! accessible, checked. Byte layout in `docs/archive-format.md`.
//!
//! **Write:** [`ArchiveWriter::create`] or [`ArchiveWriter::open_append`], then
//! [`ArchiveWriter::append`] per frame and [`ArchiveWriter::finish`] (writes the index).
//! Frames are self-delimiting records with CRC-32 checksums, appended after the earlier
//! ones, which are never rewritten; a writer dropped without `finish` (an error, an
//! interruption, a panic) writes the index of the complete frames itself, so a failed
//! run leaves a consistent archive ([`ArchiveWriter`]). **Read:** [`ArchiveReader::open`]
//! uses the index, or — after an interrupted append — scans the records and keeps every
//! complete frame; [`ArchiveReader::read_frame`] is O(1) by frame number;
//! [`ArchiveReader::verify`] decodes everything and names damaged frames;
//! [`ArchiveReader::extract`] writes frames as mesh files, [`ArchiveReader::extract_stage`]
//! as USD stages.
//!
//! **Frames** ([`ArchiveFrame`]): the pipeline's fluid surface is stored as its Loop
//! control mesh (the decimated mesh, a quarter of the triangles) and subdivided again on
//! decoding, a big one in parts that decode in parallel; isolated-particle spheres as one
//! template and their centres. Meshes from other tools ([`ArchiveWriter::append`]) are
//! stored as they are.
//!
//! Round trip: connectivity exactly, up to a permutation of the triangles (traversal
//! order), a rotation of each triangle's corners (orientation kept) and a renumbering of
//! the vertices (order of first use; unreferenced vertices are dropped); every coordinate
//! within the error bound; normals recomputed (area-weighted) on decoding.
//!
//! **Attributes** (velocity for motion blur, density, ...): the fluid's per-vertex
//! attributes and the spheres' per-instance attributes are stored per frame, each value
//! quantized with [`ArchiveOptions::attribute_error_bound`] (absolute, in the attribute's
//! units; stored in the frame's record, so frames appended with another bound keep
//! theirs: [`FrameInfo::attribute_error_bound`]). Without subdivision every decoded value
//! is within that bound of the original. With `subdivision_levels > 0` the values are
//! stored for the control vertices and each Loop step gives every new vertex the same
//! linear combination of the control values as its position (vertex and edge masks,
//! boundary rules included): the decoded values are the Loop subdivision of the stored
//! control values, as the decoded positions are of the stored control positions, so they
//! are within the bound of the subdivision of the exact control values (the masks are
//! convex); a constant attribute stays constant and a linear function of the positions
//! stays that function of the subdivided positions. Decoded items follow the decoded
//! vertices (and instances) in order. A frame without attributes is stored exactly as
//! before attributes existed; a frame with them makes the archive version 4.
//!
//! **Sphere scales** (isolated particles of different sizes,
//! [`crate::mesh::SphereInstances::scales`]) are stored exactly, one f32 per instance,
//! and the template on a lattice finer by the largest scale, so that every scaled sphere
//! vertex stays within the error bound; a frame with them makes the archive version 5.
//! Frames without them are stored as before (their spheres decode with empty scales).

mod attributes;
mod codec;
mod container;
mod frame;
mod fused;
mod merge;
mod options;
mod parts;
mod reader;
mod repair;
mod to_usd;
mod writer;

pub use attributes::{AttributeInfo, AttributeTarget};
pub use container::{repair_advice, MAX_SUBDIVISION_LEVELS};
pub use frame::ArchiveFrame;
pub use merge::{merge, MergeStats};
pub use options::{
    default_error_bound, ArchiveOptions, DEFAULT_ATTRIBUTE_ERROR_BOUND, DEFAULT_ERROR_BOUND_RADII,
};
pub use reader::{ArchiveReader, FrameInfo, Unreadable, VerifyReport};
pub use repair::{repair, RepairReport};
pub use writer::ArchiveWriter;

#[cfg(test)]
mod tests;
