//! What the archive tests (`tests/archive_*.rs`) share: the shipped frames as
//! `reconstruct … -o run.mseq` stores them, and synthetic meshes with and without
//! attributes.

use meniscus::archive::{ArchiveFrame, ArchiveOptions, ArchiveReader, ArchiveWriter};
use meniscus::isolated::icosphere;
use meniscus::mesh::{Attribute, SphereInstances, Surface, TriMesh};
use meniscus::pipeline::{reconstruct, ReconstructOptions};
use std::path::Path;
use std::sync::LazyLock;

/// The particle radius of the `dambreak_small` frames.
pub const R: f32 = 0.012;
/// The archives' error bound: 0.01 r.
pub const BOUND: f64 = 0.01 * R as f64;

/// The six shipped frames reconstructed the way `reconstruct … -o run.mseq` archives
/// them: the pipeline without its Loop step (the control mesh) and the spheres.
/// Reconstructed once per test crate.
pub fn frames() -> Vec<(i64, Surface)> {
    static FRAMES: LazyLock<Vec<(i64, Surface)>> = LazyLock::new(|| {
        // Control meshes as the CLI archives them: subdivision left to the decoder.
        let mut options = ReconstructOptions::new(R);
        options.subdivide.levels = 0;
        options.deferred_subdivision = 1;
        [1i64, 9, 17, 25, 31, 45]
            .iter()
            .map(|k| {
                let p = super::positions(&format!("dambreak_small/ParticleData_Fluid_{k}.xyz"));
                (*k, reconstruct(&p, &options).unwrap().0)
            })
            .collect()
    });
    FRAMES.clone()
}

/// A frame as the CLI stores a reconstruction: its control mesh with one Loop step.
pub fn archive_frame(surface: &Surface) -> ArchiveFrame<'_> {
    ArchiveFrame {
        fluid: &surface.fluid,
        subdivision_levels: 1,
        spheres: &surface.spheres,
    }
}

/// A new archive at `path` of `frames` (as [`archive_frame`] stores them), error bound
/// [`BOUND`].
pub fn write_archive(path: &Path, frames: &[(i64, Surface)]) {
    let mut w = ArchiveWriter::create(path, &ArchiveOptions::new(BOUND)).unwrap();
    for (n, s) in frames {
        w.append_frame(*n, &archive_frame(s)).unwrap();
    }
    w.finish().unwrap();
}

/// Every frame of an archive, decoded: number, positions and triangles.
pub type Decoded = Vec<(i64, Vec<glam::Vec3>, Vec<[u32; 3]>)>;

/// Every frame of the archive at `path`, decoded.
pub fn decoded(path: &Path) -> Decoded {
    let r = ArchiveReader::open(path).unwrap();
    r.frames()
        .iter()
        .map(|f| {
            let m = r.read_frame(f.number).unwrap();
            (f.number, m.positions, m.triangles)
        })
        .collect()
}

/// A sphere of uneven radius (vertices far apart compared with any bound here).
pub fn bumpy(level: u32, radius: f32) -> TriMesh {
    let mut m = icosphere(level, radius);
    for (i, p) in m.positions.iter_mut().enumerate() {
        *p *= 1.0 + 0.03 * ((i * 7919 % 101) as f32 / 101.0);
    }
    m
}

/// A smooth, non-linear 3-component field (a velocity, m/s) ...
pub fn velocity_at(p: glam::Vec3) -> [f32; 3] {
    [
        2.5 * (3.0 * p.y).sin() + 0.3,
        -1.7 * (2.0 * p.x + p.z).cos(),
        0.9 * p.x * p.y - 0.2,
    ]
}

/// ... and a density (kg/m³).
pub fn density_at(p: glam::Vec3) -> f32 {
    1000.0 + 4.0 * (5.0 * p.z).sin()
}

/// `mesh` with a `velocity` ([`velocity_at`]) and a `density` ([`density_at`]) per
/// vertex.
pub fn with_attributes(mut mesh: TriMesh) -> TriMesh {
    mesh.attributes = vec![
        Attribute {
            name: "velocity".into(),
            components: 3,
            values: mesh
                .positions
                .iter()
                .flat_map(|&p| velocity_at(p))
                .collect(),
        },
        Attribute {
            name: "density".into(),
            components: 1,
            values: mesh.positions.iter().map(|&p| density_at(p)).collect(),
        },
    ];
    mesh
}

/// `count` small spheres in a row, with a `velocity` and a `density` per instance.
pub fn spheres_with_attributes(count: usize) -> SphereInstances {
    let centers: Vec<glam::Vec3> = (0..count)
        .map(|i| glam::Vec3::new(2.0 + 0.13 * i as f32, (i % 5) as f32 * 0.2, -0.4))
        .collect();
    SphereInstances {
        template: icosphere(1, 0.05),
        scales: Vec::new(),
        attributes: vec![
            Attribute {
                name: "velocity".into(),
                components: 3,
                values: centers.iter().flat_map(|&p| velocity_at(p)).collect(),
            },
            Attribute {
                name: "density".into(),
                components: 1,
                values: centers.iter().map(|&p| density_at(p)).collect(),
            },
        ],
        centers,
    }
}

/// A small mesh of its own per frame number (an uneven sphere moved along x).
pub fn small_mesh(k: i64) -> TriMesh {
    let mut m = icosphere(2, 1.0 + 0.1 * k as f32);
    for p in &mut m.positions {
        p.x += k as f32;
    }
    m
}

/// Recomputes the checksum of the record header at `offset` (after a field of it was
/// changed), so that the change is not caught by the header's checksum.
pub fn reseal_header(bytes: &mut [u8], offset: usize) {
    let crc = crc32fast::hash(&bytes[offset..offset + 44]);
    bytes[offset + 44..offset + 48].copy_from_slice(&crc.to_le_bytes());
}

/// The payload length the record header at `offset` gives.
pub fn payload_len(bytes: &[u8], offset: usize) -> u64 {
    u64::from_le_bytes(bytes[offset + 28..offset + 36].try_into().unwrap())
}

/// Sets the payload length of the record header at `offset` to `len` and re-checksums
/// the header: a record whose length field lies.
pub fn set_payload_len(bytes: &mut [u8], offset: usize, len: u64) {
    bytes[offset + 28..offset + 36].copy_from_slice(&len.to_le_bytes());
    reseal_header(bytes, offset);
}

/// Where the index of a finished archive starts (from its trailer).
pub fn index_offset(bytes: &[u8]) -> usize {
    let n = bytes.len();
    u64::from_le_bytes(bytes[n - 16..n - 8].try_into().unwrap()) as usize
}

/// Every frame the archive at `path` can decode, with its surface (none when the
/// archive cannot be opened).
pub fn readable(path: &Path) -> Vec<(i64, Surface)> {
    let Ok(r) = ArchiveReader::open(path) else {
        return Vec::new();
    };
    r.frames()
        .iter()
        .filter_map(|f| Some((f.number, r.read_surface(f.number).ok()?)))
        .collect()
}

/// Panics unless every frame of `before` still decodes from the archive at `path` to
/// the same surface (`what` names the case).
pub fn assert_still_readable(path: &Path, before: &[(i64, Surface)], what: &str) {
    let r = ArchiveReader::open(path).unwrap_or_else(|e| panic!("{what}: {e}"));
    for (n, surface) in before {
        match r.read_surface(*n) {
            Ok(s) => assert!(s == *surface, "{what}: frame {n} decodes differently"),
            Err(e) => panic!("{what}: frame {n} was readable and is not: {e}"),
        }
    }
}
