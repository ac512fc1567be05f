//! Unit tests of the archive reader and writer (older versions, attributes).

use super::container::{HEADER_LEN, MAGIC, RECORD_HEADER_LEN, VERSION};
use super::*;
use crate::isolated::icosphere;
use crate::mesh::{SphereInstances, TriMesh};

#[test]
fn version_1_archives_are_read_and_appended_in_their_format() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("old.mseq");
    // An empty version-1 archive, as the first release wrote it.
    let mut header = [0u8; HEADER_LEN as usize];
    header[0..8].copy_from_slice(MAGIC);
    header[8..12].copy_from_slice(&1u32.to_le_bytes());
    std::fs::write(&path, header).unwrap();
    let options = ArchiveOptions::new(1e-4);
    let mut w = ArchiveWriter::open_append(&path, &options).unwrap();
    let control = icosphere(1, 1.0);
    let spheres = SphereInstances {
        template: icosphere(0, 0.1),
        scales: Vec::new(),
        centers: vec![glam::Vec3::new(5.0, 0.0, 0.0)],
        attributes: Vec::new(),
    };
    let frame = ArchiveFrame {
        fluid: &control,
        subdivision_levels: 1,
        spheres: &spheres,
    };
    w.append_frame(3, &frame).unwrap();
    w.finish().unwrap();
    let r = ArchiveReader::open(&path).unwrap();
    assert_eq!(r.version(), 1);
    // Stored flat: the subdivided fluid and the sphere merged into one mesh.
    let back = r.read_surface(3).unwrap();
    assert!(back.spheres.centers.is_empty());
    assert_eq!(back.fluid.triangle_count(), 80 * 4 + 20);
    assert_eq!(r.frames()[0].triangles, 80 * 4 + 20);
    // The same frame in a new archive: control mesh and one sphere instance.
    let new_path = dir.path().join("new.mseq");
    let mut w = ArchiveWriter::create(&new_path, &options).unwrap();
    w.append_frame(3, &frame).unwrap();
    w.finish().unwrap();
    let r2 = ArchiveReader::open(&new_path).unwrap();
    assert_eq!(r2.version(), VERSION);
    let back2 = r2.read_surface(3).unwrap();
    assert_eq!(back2.spheres.centers.len(), 1);
    assert_eq!(back2.merged().triangle_count(), 80 * 4 + 20);
    assert!(std::fs::metadata(&new_path).unwrap().len() < std::fs::metadata(&path).unwrap().len());
}

#[test]
fn version_1_archives_refuse_attributes() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("old.mseq");
    let mut header = [0u8; HEADER_LEN as usize];
    header[0..8].copy_from_slice(MAGIC);
    header[8..12].copy_from_slice(&1u32.to_le_bytes());
    std::fs::write(&path, header).unwrap();
    let mut w = ArchiveWriter::open_append(&path, &ArchiveOptions::new(1e-4)).unwrap();
    let mut mesh = icosphere(1, 1.0);
    mesh.attributes = vec![crate::mesh::Attribute {
        name: "density".into(),
        components: 1,
        values: vec![1.0; mesh.vertex_count()],
    }];
    let err = w.append(5, &mesh).unwrap_err().to_string();
    assert!(
        err.contains("frame 5") && err.contains("version-1"),
        "{err}"
    );
    mesh.attributes.clear();
    w.append(5, &mesh).unwrap();
    w.finish().unwrap();
    assert_eq!(ArchiveReader::open(&path).unwrap().version(), 1);
}

#[test]
fn version_2_archives_keep_control_meshes_whole() {
    let dir = tempfile::tempdir().unwrap();
    // A control mesh big enough for ten parts.
    let control = icosphere(6, 1.0);
    let frame = ArchiveFrame {
        fluid: &control,
        subdivision_levels: 1,
        spheres: &SphereInstances::default(),
    };
    let options = ArchiveOptions::new(1e-5);
    let mut decoded = Vec::new();
    for version in [2u32, VERSION] {
        let path = dir.path().join(format!("v{version}.mseq"));
        let mut header = [0u8; HEADER_LEN as usize];
        header[0..8].copy_from_slice(MAGIC);
        header[8..12].copy_from_slice(&version.to_le_bytes());
        std::fs::write(&path, header).unwrap();
        let mut w = ArchiveWriter::open_append(&path, &options).unwrap();
        w.append_frame(7, &frame).unwrap();
        w.finish().unwrap();
        let r = ArchiveReader::open(&path).unwrap();
        assert_eq!(r.version(), version);
        // The shape byte after the level varint: 1 whole, 2 in parts.
        let f = &r.frames()[0];
        let start = f.offset as usize + RECORD_HEADER_LEN;
        let bytes = std::fs::read(&path).unwrap();
        let payload = &bytes[start..start + f.payload_bytes as usize];
        let raw = zstd::bulk::decompress(payload, 1 << 24).unwrap();
        assert_eq!(raw[1], if version == 2 { 1 } else { 2 });
        decoded.push(r.read_geometry(7).unwrap().fluid);
    }
    assert_eq!(decoded[0].triangle_count(), 4 * control.triangle_count());
    assert_eq!(decoded[0].triangle_count(), decoded[1].triangle_count());
    assert_eq!(decoded[0].vertex_count(), decoded[1].vertex_count());
    let area = |m: &TriMesh| m.area();
    assert!((area(&decoded[0]) - area(&decoded[1])).abs() < 1e-6 * area(&decoded[0]));
}

#[test]
fn a_control_mesh_loop_counts_cannot_describe_is_stored_subdivided() {
    // Two triangles on the same three vertices: one Loop step shares their inner
    // edges, so the counts of a clean mesh would be wrong.
    let mut control = icosphere(0, 1.0);
    control.triangles.push([0, 5, 11]);
    let mut expected = control.clone();
    crate::subdivision::subdivide(
        &mut expected,
        &crate::subdivision::SubdivideOptions { levels: 1 },
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("odd.mseq");
    let mut w = ArchiveWriter::create(&path, &ArchiveOptions::new(1e-4)).unwrap();
    let frame = ArchiveFrame {
        fluid: &control,
        subdivision_levels: 1,
        spheres: &SphereInstances::default(),
    };
    w.append_frame(0, &frame).unwrap();
    w.finish().unwrap();
    let r = ArchiveReader::open(&path).unwrap();
    let back = r.read_surface(0).unwrap();
    assert_eq!(back.fluid.triangle_count(), expected.triangle_count());
    assert_eq!(back.fluid.vertex_count(), expected.vertex_count());
    assert_eq!(r.frames()[0].vertices as usize, expected.vertex_count());
}

#[test]
fn the_default_error_bound_takes_the_radius_as_written() {
    for (radius, written) in [
        (0.012f32, 0.012f64),
        (0.025, 0.025),
        (0.1, 0.1),
        (1e-7, 1e-7),
    ] {
        assert_eq!(default_error_bound(radius), 0.01 * written, "r = {radius}");
    }
    // The f32 widened as it is would give another bound, which would not merge.
    assert_ne!(0.01 * (0.012f32 as f64), default_error_bound(0.012));
}
