//! The `.mseq` archive: round trips within the error bound with identical connectivity,
//! random access, truncation and bit flips detected, interrupted appends recovered.

use meniscus::archive::{ArchiveFrame, ArchiveOptions, ArchiveReader, ArchiveWriter};
use meniscus::io::particles::read_particles;
use meniscus::mesh::{Surface, TriMesh};
use meniscus::pipeline::{reconstruct, ReconstructOptions};
use meniscus::subdivision::{subdivide, SubdivideOptions};
use std::path::{Path, PathBuf};

const R: f32 = 0.012;
const BOUND: f64 = 0.01 * R as f64;
/// Length and CRC-32 of the archive `write_synthetic_archive` writes, as the code before
/// attributes (commit 2e68ce4) wrote it.
const GOLDEN_LEN: usize = 182_772;
const GOLDEN_CRC: u32 = 0x28c8_574f;

fn particles(rel: &str) -> Vec<glam::Vec3> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("datasets");
    read_particles(&root.join(rel), None).unwrap().positions
}

/// The six shipped frames reconstructed the way `reconstruct … -o run.mseq` archives
/// them: the pipeline without its Loop step (the control mesh) and the spheres.
fn frames() -> Vec<(i64, Surface)> {
    // Control meshes as the CLI archives them: subdivision left to the decoder.
    let mut options = ReconstructOptions::new(R);
    options.subdivide.levels = 0;
    options.deferred_subdivision = 1;
    [1i64, 9, 17, 25, 31, 45]
        .iter()
        .map(|k| {
            let p = particles(&format!("dambreak_small/ParticleData_Fluid_{k}.xyz"));
            (*k, reconstruct(&p, &options).unwrap().0)
        })
        .collect()
}

fn archive_frame(surface: &Surface) -> ArchiveFrame<'_> {
    ArchiveFrame {
        fluid: &surface.fluid,
        subdivision_levels: 1,
        spheres: &surface.spheres,
    }
}

/// The triangles as a sorted list of vertex-index triples, each in its smallest rotation.
fn canonical_triangles(triangles: impl Iterator<Item = [u32; 3]>) -> Vec<[u32; 3]> {
    let mut list: Vec<[u32; 3]> = triangles
        .map(|t| {
            (0..3)
                .map(|r| [t[r], t[(r + 1) % 3], t[(r + 2) % 3]])
                .min()
                .unwrap()
        })
        .collect();
    list.sort_unstable();
    list
}

const UNSET: u32 = u32::MAX;

/// A partial matching of decoded to original vertices.
#[derive(Clone)]
struct Matching {
    map: Vec<u32>,
    taken: Vec<bool>,
}

struct MatchContext<'a> {
    candidates: &'a [Vec<u32>],
    incident: &'a [Vec<u32>],
    triangles: &'a [[u32; 3]],
    original_set: &'a hashbrown::HashSet<[u32; 3]>,
}

impl MatchContext<'_> {
    /// The free candidates of `i` whose triangles with matched neighbours exist.
    fn fits(&self, m: &Matching, i: usize) -> Vec<u32> {
        self.candidates[i]
            .iter()
            .copied()
            .filter(|&o| !m.taken[o as usize])
            .filter(|&o| {
                self.incident[i].iter().all(|&t| {
                    let tri = self.triangles[t as usize].map(|v| {
                        if v as usize == i {
                            o
                        } else {
                            m.map[v as usize]
                        }
                    });
                    tri.contains(&UNSET)
                        || self
                            .original_set
                            .contains(&canonical_triangles(std::iter::once(tri))[0])
                })
            })
            .collect()
    }

    /// Completes the matching of the vertices in `unset`: forced choices first, then a
    /// search over the few clusters of vertices within the bound of each other.
    fn solve(&self, m: &mut Matching, mut unset: Vec<u32>) -> bool {
        loop {
            let mut progress = false;
            let mut still = Vec::with_capacity(unset.len());
            let mut best: Option<(usize, Vec<u32>)> = None;
            for &i in &unset {
                let fits = self.fits(m, i as usize);
                match fits.len() {
                    0 => return false,
                    1 => {
                        m.map[i as usize] = fits[0];
                        m.taken[fits[0] as usize] = true;
                        progress = true;
                    }
                    n => {
                        still.push(i);
                        if best.as_ref().is_none_or(|b| n < b.1.len()) {
                            best = Some((i as usize, fits));
                        }
                    }
                }
            }
            unset = still;
            if unset.is_empty() {
                return true;
            }
            if progress {
                continue;
            }
            let (i, fits) = best.expect("an unmatched vertex");
            for o in fits {
                let mut trial = m.clone();
                trial.map[i] = o;
                trial.taken[o as usize] = true;
                let rest: Vec<u32> = unset.iter().copied().filter(|&u| u as usize != i).collect();
                if self.solve(&mut trial, rest) {
                    *m = trial;
                    return true;
                }
            }
            return false;
        }
    }
}

/// Asserts that `back` is `original` up to a renumbering of the vertices, an order of the
/// triangles and a rotation of each triangle's corners (orientation kept), with every
/// coordinate within `bound` (plus f32 rounding). Vertices are matched by position; where
/// several originals lie within the bound (vertices closer than twice the bound), by the
/// triangles they share with vertices already matched (a small search where such
/// vertices cluster).
fn assert_same_up_to_permutation(back: &TriMesh, original: &TriMesh, bound: f64, what: &str) {
    assert_eq!(
        back.vertex_count(),
        original.vertex_count(),
        "{what}: vertices"
    );
    assert_eq!(
        back.triangle_count(),
        original.triangle_count(),
        "{what}: triangles"
    );
    let tolerance = bound * 1.001 + 1e-7;
    let cell_of = |p: glam::Vec3| {
        p.to_array()
            .map(|c| (c as f64 / (4.0 * bound)).floor() as i64)
    };
    let mut grid: hashbrown::HashMap<[i64; 3], Vec<u32>> = hashbrown::HashMap::new();
    for (i, p) in original.positions.iter().enumerate() {
        grid.entry(cell_of(*p)).or_default().push(i as u32);
    }
    let candidates: Vec<Vec<u32>> = back
        .positions
        .iter()
        .map(|p| {
            let c = cell_of(*p);
            let mut found = Vec::new();
            for d in 0..27 {
                let key = [c[0] + d % 3 - 1, c[1] + d / 3 % 3 - 1, c[2] + d / 9 - 1];
                for &o in grid.get(&key).map(|v| v.as_slice()).unwrap_or(&[]) {
                    let err = (original.positions[o as usize] - *p).abs().max_element() as f64;
                    if err <= tolerance {
                        found.push(o);
                    }
                }
            }
            found
        })
        .collect();
    for (i, c) in candidates.iter().enumerate() {
        assert!(
            !c.is_empty(),
            "{what}: decoded vertex {i} has no original within the bound"
        );
    }
    let original_set: hashbrown::HashSet<[u32; 3]> =
        canonical_triangles(original.triangles.iter().copied())
            .into_iter()
            .collect();
    let mut incident: Vec<Vec<u32>> = vec![Vec::new(); back.vertex_count()];
    for (t, tri) in back.triangles.iter().enumerate() {
        for &v in tri {
            incident[v as usize].push(t as u32);
        }
    }
    let mut matching = Matching {
        map: vec![UNSET; back.vertex_count()],
        taken: vec![false; original.vertex_count()],
    };
    let unset: Vec<u32> = (0..back.vertex_count() as u32).collect();
    let context = MatchContext {
        candidates: &candidates,
        incident: &incident,
        triangles: &back.triangles,
        original_set: &original_set,
    };
    assert!(
        context.solve(&mut matching, unset),
        "{what}: no matching of the vertices keeps the triangles"
    );
    let map = matching.map;
    assert_eq!(
        canonical_triangles(back.triangles.iter().map(|t| t.map(|v| map[v as usize]))),
        canonical_triangles(original.triangles.iter().copied()),
        "{what}: connectivity"
    );
}

fn write_archive(path: &Path, frames: &[(i64, Surface)]) {
    let mut w = ArchiveWriter::create(path, &ArchiveOptions::new(BOUND)).unwrap();
    for (n, s) in frames {
        w.append_frame(*n, &archive_frame(s)).unwrap();
    }
    w.finish().unwrap();
}

#[test]
fn every_frame_round_trips_within_the_bound() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mseq");
    let mut frames = frames();
    // The droplets: a blob and 500 spheres (radius 0.025).
    let mut droplet_options = ReconstructOptions::new(0.025);
    droplet_options.subdivide.levels = 0;
    let droplets = reconstruct(&particles("analytic/droplets.xyz"), &droplet_options)
        .unwrap()
        .0;
    assert_eq!(droplets.spheres.centers.len(), 500);
    frames.push((1000, droplets));
    write_archive(&path, &frames);
    let reader = ArchiveReader::open(&path).unwrap();
    assert!(!reader.recovered_by_scan());
    assert_eq!(reader.version(), 3);
    assert_eq!(
        reader.frames().iter().map(|f| f.number).collect::<Vec<_>>(),
        [1, 9, 17, 25, 31, 45, 1000]
    );
    let (mut stored, mut triangles) = (0u64, 0u64);
    let full_pipeline = ReconstructOptions::new(R);
    for (n, control) in &frames {
        // What the archive must give back: the Loop step of the control mesh, which is
        // exactly what the full pipeline makes.
        let mut expected = control.clone();
        subdivide(&mut expected.fluid, &SubdivideOptions::default());
        if *n == 25 {
            let p = particles("dambreak_small/ParticleData_Fluid_25.xyz");
            let full = reconstruct(&p, &full_pipeline).unwrap().0;
            assert_eq!(full.fluid.positions, expected.fluid.positions);
            assert_eq!(full.fluid.triangles, expected.fluid.triangles);
        }
        let back = reader.read_surface(*n).unwrap();
        assert_same_up_to_permutation(&back.fluid, &expected.fluid, BOUND, &format!("frame {n}"));
        assert_eq!(back.spheres.centers.len(), expected.spheres.centers.len());
        // Merged with the spheres, as extract writes them.
        let merged = back.merged();
        assert_same_up_to_permutation(
            &merged,
            &expected.merged(),
            BOUND,
            &format!("frame {n} with spheres"),
        );
        assert_eq!(merged.normals.len(), merged.positions.len());
        let info = reader.frames().iter().find(|f| f.number == *n).unwrap();
        assert_eq!(info.triangles as usize, merged.triangle_count());
        assert_eq!(info.vertices as usize, merged.vertex_count());
        if *n != 1000 {
            stored += info.payload_bytes + 48;
            triangles += merged.triangle_count() as u64;
        }
    }
    let per_triangle = stored as f64 / triangles as f64;
    println!("{per_triangle:.3} bytes per triangle");
    // Loop's control mesh holds a quarter of the triangles: far below the plain coding's
    // 1.5 bytes per triangle.
    assert!(per_triangle < 0.6, "{per_triangle} bytes per triangle");
    // Random access equals sequential decoding.
    let sequential: Vec<TriMesh> = [1i64, 9, 17, 25, 31, 45]
        .iter()
        .map(|n| reader.read_frame(*n).unwrap())
        .collect();
    assert_eq!(reader.read_frame(31).unwrap(), sequential[4]);
    assert!(reader.read_frame(2).is_err());
    assert!(reader.verify().damaged.is_empty());
}

#[test]
fn plain_meshes_round_trip_within_the_bound() {
    // Meshes from any tool (`archive pack`): stored as they are.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("plain.mseq");
    let meshes: Vec<(i64, TriMesh)> = frames()
        .into_iter()
        .take(3)
        .map(|(n, s)| {
            let mut m = s.merged();
            subdivide(&mut m, &SubdivideOptions::default());
            (n, m)
        })
        .collect();
    let mut w = ArchiveWriter::create(&path, &ArchiveOptions::new(BOUND)).unwrap();
    for (n, m) in &meshes {
        w.append(*n, m).unwrap();
    }
    w.finish().unwrap();
    let reader = ArchiveReader::open(&path).unwrap();
    for (n, m) in &meshes {
        let back = reader.read_frame(*n).unwrap();
        assert_same_up_to_permutation(&back, m, BOUND, &format!("plain frame {n}"));
    }
}

#[test]
fn truncation_and_bit_flips_are_detected() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mseq");
    let frames: Vec<(i64, Surface)> = frames().into_iter().take(3).collect();
    write_archive(&path, &frames);
    let bytes = std::fs::read(&path).unwrap();
    let reader = ArchiveReader::open(&path).unwrap();
    let offsets: Vec<u64> = reader.frames().iter().map(|f| f.offset).collect();
    // Truncation at every frame boundary and in the middle of every frame: the complete
    // frames before the cut remain readable, nothing after it is claimed.
    let cut_path = dir.path().join("cut.mseq");
    for (k, &offset) in offsets.iter().enumerate() {
        for cut in [offset as usize, offset as usize + 30, offset as usize + 200] {
            std::fs::write(&cut_path, &bytes[..cut]).unwrap();
            let r = ArchiveReader::open(&cut_path).unwrap();
            assert!(r.recovered_by_scan());
            assert_eq!(r.frames().len(), k, "cut at {cut}");
            let report = r.verify();
            assert_eq!(report.good.len(), k);
            // The missing index is damage; a record cut in its payload names its frame.
            assert!(!report.is_clean(), "cut at {cut}");
            let cut_frame = report.damaged.iter().map(|d| d.0).collect::<Vec<_>>();
            if cut == offset as usize + 200 {
                assert_eq!(cut_frame, [frames[k].0], "cut at {cut}");
            } else {
                assert!(cut_frame.is_empty(), "cut at {cut}");
            }
        }
    }
    // A bit flip in each frame's payload: that frame is reported by number, the others
    // still decode.
    let flip_path = dir.path().join("flip.mseq");
    for (k, f) in reader.frames().iter().enumerate() {
        let mut damaged = bytes.clone();
        let at = f.offset as usize + 48 + (f.payload_bytes as usize) / 2;
        damaged[at] ^= 0x10;
        std::fs::write(&flip_path, &damaged).unwrap();
        let r = ArchiveReader::open(&flip_path).unwrap();
        let report = r.verify();
        assert_eq!(report.damaged.len(), 1, "flip in frame {k}");
        assert_eq!(report.damaged[0].0, f.number);
        assert!(
            report.damaged[0].1.contains("checksum"),
            "{}",
            report.damaged[0].1
        );
        assert_eq!(report.good.len(), frames.len() - 1);
        let msg = r.read_frame(f.number).unwrap_err().to_string();
        assert!(msg.contains(&format!("frame {}", f.number)), "{msg}");
    }
    // A flip in a record header: the frames before it remain (by scan if need be).
    let mut damaged = bytes.clone();
    damaged[offsets[2] as usize + 5] ^= 1;
    std::fs::write(&flip_path, &damaged).unwrap();
    let r = ArchiveReader::open(&flip_path).unwrap();
    assert_eq!(r.frames().len(), 2);
    let report = r.verify();
    assert_eq!(report.damaged.len(), 1);
    assert_eq!(report.damaged[0].0, frames[2].0);
    // Not an archive at all.
    std::fs::write(&flip_path, b"hello").unwrap();
    assert!(ArchiveReader::open(&flip_path).is_err());
}

#[test]
fn appends_resume_after_interruption_and_refuse_damage() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mseq");
    let frames = frames();
    write_archive(&path, &frames[..2]);
    // A normal append keeps the earlier frames byte for byte.
    let before = std::fs::read(&path).unwrap();
    let first_index = ArchiveReader::open(&path).unwrap().frames()[1].offset as usize;
    let mut w = ArchiveWriter::open_append(&path, &ArchiveOptions::new(BOUND)).unwrap();
    assert_eq!(w.frame_numbers(), [1, 9]);
    w.append_frame(frames[2].0, &archive_frame(&frames[2].1))
        .unwrap();
    assert!(
        w.append_frame(frames[2].0, &archive_frame(&frames[2].1))
            .is_err(),
        "duplicate frame numbers are refused"
    );
    // Dropped without finish (the caller failed after the refusal): the writer writes
    // the index itself, of the frames before and the one appended.
    drop(w);
    let after = std::fs::read(&path).unwrap();
    assert_eq!(&after[..first_index], &before[..first_index]);
    let r = ArchiveReader::open(&path).unwrap();
    assert!(!r.recovered_by_scan() && r.verify().is_clean());
    assert_eq!(r.frames().len(), 3);
    // A crash mid-append (the process killed): no index, and a half-written record at
    // the end.
    let n = after.len();
    let index_offset = u64::from_le_bytes(after[n - 16..n - 8].try_into().unwrap()) as usize;
    let mut crashed = after[..index_offset].to_vec();
    crashed.extend_from_slice(&after[first_index..first_index + 100]);
    std::fs::write(&path, &crashed).unwrap();
    let r = ArchiveReader::open(&path).unwrap();
    assert!(r.recovered_by_scan());
    assert_eq!(r.frames().len(), 3);
    // The next run resumes: the incomplete record is cut, new frames follow.
    let mut w = ArchiveWriter::open_append(&path, &ArchiveOptions::new(BOUND)).unwrap();
    w.append_frame(frames[3].0, &archive_frame(&frames[3].1))
        .unwrap();
    w.finish().unwrap();
    let r = ArchiveReader::open(&path).unwrap();
    assert!(!r.recovered_by_scan());
    assert_eq!(
        r.frames().iter().map(|f| f.number).collect::<Vec<_>>(),
        [1, 9, 17, 25]
    );
    assert!(r.verify().damaged.is_empty());
    // A damaged frame makes appending refuse instead of losing anything.
    let mut bytes = std::fs::read(&path).unwrap();
    let f = &r.frames()[1];
    bytes[f.offset as usize + 60] ^= 0xff;
    std::fs::write(&path, &bytes).unwrap();
    let err = ArchiveWriter::open_append(&path, &ArchiveOptions::new(BOUND))
        .err()
        .expect("refused");
    assert!(err.to_string().contains("damaged"), "{err}");
    assert_eq!(
        std::fs::read(&path).unwrap(),
        bytes,
        "a refused append changes nothing"
    );
}

// ---------------------------------------------------------------------------------------
// Attributes.

use meniscus::archive::{AttributeInfo, AttributeTarget};
use meniscus::isolated::icosphere;
use meniscus::mesh::{Attribute, SphereInstances};

/// A sphere of uneven radius (vertices far apart compared with any bound here).
fn bumpy(level: u32, radius: f32) -> TriMesh {
    let mut m = icosphere(level, radius);
    for (i, p) in m.positions.iter_mut().enumerate() {
        *p *= 1.0 + 0.03 * ((i * 7919 % 101) as f32 / 101.0);
    }
    m
}

/// Frames of synthetic meshes without attributes: a control mesh stored in parts, a
/// small one stored whole with two Loop steps and spheres, an open one, a plain mesh.
fn write_synthetic_archive(path: &Path) {
    let big = bumpy(6, 1.0);
    let small = bumpy(3, 0.5);
    let spheres = SphereInstances {
        template: icosphere(1, 0.05),
        centers: (0..20)
            .map(|i| glam::Vec3::new(2.0 + 0.1 * i as f32, (i % 3) as f32, 0.5))
            .collect(),
        attributes: Vec::new(),
    };
    let mut open = bumpy(3, 0.7);
    open.triangles.truncate(open.triangles.len() - 9);
    let plain = bumpy(2, 0.3);
    let none = SphereInstances::default();
    let mut w = ArchiveWriter::create(path, &ArchiveOptions::new(1e-4)).unwrap();
    for (n, fluid, levels, spheres) in [
        (0, &big, 1, &none),
        (1, &small, 2, &spheres),
        (2, &open, 1, &none),
    ] {
        w.append_frame(
            n,
            &ArchiveFrame {
                fluid,
                subdivision_levels: levels,
                spheres,
            },
        )
        .unwrap();
    }
    w.append(3, &plain).unwrap();
    w.finish().unwrap();
}

#[test]
fn archives_without_attributes_are_byte_identical_to_version_3() {
    // The length and CRC-32 pinned below were measured with the code before attributes
    // (commit 2e68ce4) running this same `write_synthetic_archive`.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("plain.mseq");
    write_synthetic_archive(&path);
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(
        (bytes.len(), crc32fast::hash(&bytes)),
        (GOLDEN_LEN, GOLDEN_CRC),
        "the archive differs from version 3's"
    );
    let r = ArchiveReader::open(&path).unwrap();
    assert_eq!(r.version(), 3);
    for f in r.frames() {
        assert!(f.attributes.is_empty() && f.attribute_error_bound.is_none());
        let s = r.read_surface(f.number).unwrap();
        assert!(s.fluid.attributes.is_empty() && s.spheres.attributes.is_empty());
    }
}

/// A smooth, non-linear 3-component field (a velocity, m/s) and a density (kg/m³).
fn velocity_at(p: glam::Vec3) -> [f32; 3] {
    [
        2.5 * (3.0 * p.y).sin() + 0.3,
        -1.7 * (2.0 * p.x + p.z).cos(),
        0.9 * p.x * p.y - 0.2,
    ]
}

fn density_at(p: glam::Vec3) -> f32 {
    1000.0 + 4.0 * (5.0 * p.z).sin()
}

fn with_attributes(mut mesh: TriMesh) -> TriMesh {
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

fn spheres_with_attributes(count: usize) -> SphereInstances {
    let centers: Vec<glam::Vec3> = (0..count)
        .map(|i| glam::Vec3::new(2.0 + 0.13 * i as f32, (i % 5) as f32 * 0.2, -0.4))
        .collect();
    SphereInstances {
        template: icosphere(1, 0.05),
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

/// Largest `|got − want| − bound` over the items, when positive: `bound` plus the f32
/// rounding of the decoded value is allowed.
fn check_within(got: &[f32], want: &[f32], bound: f64, what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: values");
    for (i, (&g, &w)) in got.iter().zip(want).enumerate() {
        let allowed = bound * (1.0 + 1e-9) + (w.abs() as f64) * f32::EPSILON as f64;
        let err = (g as f64 - w as f64).abs();
        assert!(
            err <= allowed,
            "{what}: value {i}: {g} vs {w} ({err} > {bound})"
        );
    }
}

/// The original vertex of every decoded vertex (the nearest: vertices here are far
/// apart compared with the bound).
fn nearest_original(back: &TriMesh, original: &TriMesh, bound: f64) -> Vec<usize> {
    back.positions
        .iter()
        .map(|p| {
            let (i, d) = original
                .positions
                .iter()
                .map(|o| (*o - *p).abs().max_element())
                .enumerate()
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .unwrap();
            assert!(d as f64 <= bound * 1.001 + 1e-7);
            i
        })
        .collect()
}

#[test]
fn attributes_round_trip_within_their_bound() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("attributes.mseq");
    let bound = 1e-4;
    let options = ArchiveOptions::new(bound);
    let attribute_bound = options.attribute_error_bound;
    assert_eq!(attribute_bound, 1e-3);
    let closed = with_attributes(bumpy(3, 0.5));
    let mut open = with_attributes(bumpy(3, 0.7));
    open.triangles.truncate(open.triangles.len() - 9);
    let spheres = spheres_with_attributes(30);
    let none = SphereInstances::default();
    let mut w = ArchiveWriter::create(&path, &options).unwrap();
    for (n, fluid, spheres) in [(0, &closed, &spheres), (1, &open, &none)] {
        w.append_frame(
            n,
            &ArchiveFrame {
                fluid,
                subdivision_levels: 0,
                spheres,
            },
        )
        .unwrap();
    }
    // A plain mesh (`archive pack`) keeps its attributes too.
    w.append(2, &closed).unwrap();
    w.finish().unwrap();
    let r = ArchiveReader::open(&path).unwrap();
    assert_eq!(r.version(), 4);
    let info = &r.frames()[0];
    assert_eq!(info.attribute_error_bound, Some(attribute_bound));
    let listed = |name: &str, components, target| AttributeInfo {
        name: name.into(),
        components,
        target,
    };
    assert_eq!(
        info.attributes,
        [
            listed("velocity", 3, AttributeTarget::FluidVertices),
            listed("density", 1, AttributeTarget::FluidVertices),
            listed("velocity", 3, AttributeTarget::SphereInstances),
            listed("density", 1, AttributeTarget::SphereInstances),
        ]
    );
    assert_eq!(r.frames()[1].attributes.len(), 2);
    for (n, original) in [(0, &closed), (1, &open), (2, &closed)] {
        let back = r.read_surface(n).unwrap();
        assert_eq!(back.fluid.attributes.len(), 2, "frame {n}");
        let map = nearest_original(&back.fluid, original, bound);
        for (a, o) in back.fluid.attributes.iter().zip(&original.attributes) {
            assert_eq!((&a.name, a.components), (&o.name, o.components));
            assert_eq!(a.len(), back.fluid.vertex_count());
            let want: Vec<f32> = map.iter().flat_map(|&v| o.item(v).to_vec()).collect();
            check_within(
                &a.values,
                &want,
                attribute_bound,
                &format!("frame {n} {}", a.name),
            );
        }
    }
    let back = r.read_surface(0).unwrap();
    assert_eq!(back.spheres.centers.len(), 30);
    assert_eq!(back.spheres.attributes.len(), 2);
    for (a, o) in back.spheres.attributes.iter().zip(&spheres.attributes) {
        assert_eq!((&a.name, a.components), (&o.name, o.components));
        check_within(
            &a.values,
            &o.values,
            attribute_bound,
            &format!("spheres {}", a.name),
        );
    }
    // Merged (what extract writes): every sphere vertex has its instance's values.
    let merged = r.read_frame(0).unwrap();
    assert_eq!(merged.attributes.len(), 2);
    assert_eq!(merged.attributes[0].len(), merged.vertex_count());
    assert!(r.verify().damaged.is_empty());
}

/// `a = A·x + b` of a position, 3 components and 1.
const A: [[f32; 3]; 4] = [
    [2.0, -1.0, 0.5],
    [0.0, 1.5, 1.0],
    [-0.75, 0.25, 2.0],
    [1.0, 1.0, -1.0],
];
const B: [f32; 4] = [0.3, -2.0, 1.0, 4.0];

fn linear_at(p: glam::Vec3) -> [f32; 4] {
    [0, 1, 2, 3].map(|r| A[r][0] * p.x + A[r][1] * p.y + A[r][2] * p.z + B[r])
}

fn with_linear_and_constant(mut mesh: TriMesh) -> TriMesh {
    mesh.attributes = vec![
        Attribute {
            name: "linear3".into(),
            components: 3,
            values: mesh
                .positions
                .iter()
                .flat_map(|&p| linear_at(p)[..3].to_vec())
                .collect(),
        },
        Attribute {
            name: "linear1".into(),
            components: 1,
            values: mesh.positions.iter().map(|&p| linear_at(p)[3]).collect(),
        },
        Attribute {
            name: "constant".into(),
            components: 2,
            values: [1.25f32, -0.5].repeat(mesh.positions.len()),
        },
    ];
    mesh
}

#[test]
fn subdivided_attributes_follow_the_positions() {
    // Loop's masks are affine: a linear function of the control positions subdivides to
    // the same linear function of the subdivided positions. The decoded values are the
    // stored ones (each within the attribute bound) through the masks, the decoded
    // positions the stored ones (each within the position bound) through the same
    // masks: at every decoded vertex, |a − (A·x + b)| ≤ attribute bound + Σ|A_r|·position
    // bound, plus rounding. A different stencil (or vertex order) errs by about an edge
    // length times A (0.01 and more here).
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("subdivided.mseq");
    let position_bound = 1e-5;
    let options = ArchiveOptions::new(position_bound);
    let attribute_bound = options.attribute_error_bound;
    // Stored in parts (81920 control triangles), whole (closed), open.
    let big = with_linear_and_constant(bumpy(6, 1.0));
    let small = with_linear_and_constant(bumpy(3, 0.5));
    let mut open = with_linear_and_constant(bumpy(3, 0.7));
    open.triangles.truncate(open.triangles.len() - 9);
    let spheres = spheres_with_attributes(12);
    let mut w = ArchiveWriter::create(&path, &options).unwrap();
    let mut expected_triangles = Vec::new();
    let mut n = 0;
    for levels in [1u32, 2] {
        for (fluid, spheres) in [
            (&big, &SphereInstances::default()),
            (&small, &spheres),
            (&open, &SphereInstances::default()),
        ] {
            w.append_frame(
                n,
                &ArchiveFrame {
                    fluid,
                    subdivision_levels: levels,
                    spheres,
                },
            )
            .unwrap();
            expected_triangles.push(fluid.triangle_count() << (2 * levels));
            n += 1;
        }
    }
    w.finish().unwrap();
    let r = ArchiveReader::open(&path).unwrap();
    let sequential: Vec<Surface> = (0..n).map(|k| r.read_geometry(k).unwrap()).collect();
    for k in 0..n {
        let back = &sequential[k as usize];
        let fluid = &back.fluid;
        assert_eq!(fluid.triangle_count(), expected_triangles[k as usize]);
        assert_eq!(fluid.attributes.len(), 3, "frame {k}");
        for a in &fluid.attributes {
            assert_eq!(a.len(), fluid.vertex_count(), "frame {k} {}", a.name);
        }
        let [l3, l1, constant] = &fluid.attributes[..] else {
            unreachable!()
        };
        let mut worst = 0f64;
        for (v, &p) in fluid.positions.iter().enumerate() {
            let want = linear_at(p);
            let got = [l3.item(v), l1.item(v)].concat();
            for r in 0..4 {
                let spread: f32 = A[r].iter().map(|x| x.abs()).sum();
                let allowed = attribute_bound + spread as f64 * position_bound + 2e-6;
                let err = (got[r] as f64 - want[r] as f64).abs();
                worst = worst.max(err);
                assert!(
                    err <= allowed,
                    "frame {k}, vertex {v}, component {r}: {} vs A·x + b = {} ({err} > {allowed})",
                    got[r],
                    want[r]
                );
            }
            assert_eq!(constant.item(v), [1.25, -0.5], "frame {k}, vertex {v}");
        }
        assert!(worst > 0.0);
        if k % 3 == 1 {
            // Instances are not subdivided: their values as stored.
            for (a, o) in back.spheres.attributes.iter().zip(&spheres.attributes) {
                check_within(&a.values, &o.values, attribute_bound, "spheres");
            }
        }
    }
    // Random access equals sequential decoding, attributes included.
    for k in [4i64, 0, 5, 2] {
        assert_eq!(
            r.read_geometry(k).unwrap(),
            sequential[k as usize],
            "frame {k}"
        );
    }
    assert!(r.verify().damaged.is_empty());
}

/// Where frame `f`'s attribute streams lie in the file (after descriptor and geometry).
fn attribute_stream_range(
    bytes: &[u8],
    f: &meniscus::archive::FrameInfo,
) -> std::ops::Range<usize> {
    let start = f.offset as usize + 48;
    let end = start + f.payload_bytes as usize;
    let descriptor = u32::from_le_bytes(bytes[start..start + 4].try_into().unwrap()) as usize;
    let at = start + 4 + descriptor + 4;
    let geometry = u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap()) as usize;
    at + 8 + geometry..end
}

#[test]
fn verify_finds_damage_in_attribute_streams() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("a.mseq");
    let frames = [
        with_attributes(bumpy(3, 0.5)),
        with_attributes(bumpy(2, 0.4)),
    ];
    let spheres = spheres_with_attributes(8);
    let mut w = ArchiveWriter::create(&path, &ArchiveOptions::new(1e-4)).unwrap();
    for (n, fluid) in frames.iter().enumerate() {
        let frame = ArchiveFrame {
            fluid,
            subdivision_levels: 1,
            spheres: &spheres,
        };
        w.append_frame(n as i64, &frame).unwrap();
    }
    w.finish().unwrap();
    let r = ArchiveReader::open(&path).unwrap();
    let report = r.verify();
    assert_eq!((report.good.len(), report.damaged.len()), (2, 0));
    let bytes = std::fs::read(&path).unwrap();
    let flip_path = dir.path().join("flip.mseq");
    for f in r.frames() {
        let streams = attribute_stream_range(&bytes, f);
        assert!(streams.len() > 100, "{streams:?}");
        let mut damaged = bytes.clone();
        damaged[streams.start + streams.len() / 2] ^= 0x04;
        std::fs::write(&flip_path, &damaged).unwrap();
        let flipped = ArchiveReader::open(&flip_path).unwrap();
        let report = flipped.verify();
        assert_eq!(report.good.len(), 1);
        assert_eq!(report.damaged.len(), 1);
        assert_eq!(report.damaged[0].0, f.number);
        let msg = flipped.read_surface(f.number).unwrap_err().to_string();
        assert!(msg.contains(&format!("frame {}", f.number)), "{msg}");
        assert!(msg.contains("flip.mseq"), "{msg}");
        // A flip in the descriptor: the listing drops the damaged names, decoding fails.
        let mut damaged = bytes.clone();
        damaged[f.offset as usize + 48 + 20] ^= 0x01;
        std::fs::write(&flip_path, &damaged).unwrap();
        let flipped = ArchiveReader::open(&flip_path).unwrap();
        let k = flipped
            .frames()
            .iter()
            .position(|g| g.number == f.number)
            .unwrap();
        assert!(flipped.frames()[k].attributes.is_empty());
        assert_eq!(flipped.verify().damaged.len(), 1);
    }
}

#[test]
fn appended_frames_keep_their_own_attribute_bound() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("append.mseq");
    // A version-3 archive without attributes ...
    let plain = bumpy(2, 0.4);
    let mut w = ArchiveWriter::create(&path, &ArchiveOptions::new(1e-4)).unwrap();
    w.append(0, &plain).unwrap();
    w.finish().unwrap();
    let before = std::fs::read(&path).unwrap();
    assert_eq!(ArchiveReader::open(&path).unwrap().version(), 3);
    // ... gets frames with attributes at two bounds: it becomes version 4, its records
    // are kept byte for byte.
    let mesh = with_attributes(bumpy(3, 0.5));
    for (n, bound) in [(1, 1e-3), (2, 2e-2)] {
        let mut options = ArchiveOptions::new(1e-4);
        options.attribute_error_bound = bound;
        let mut w = ArchiveWriter::open_append(&path, &options).unwrap();
        w.append(n, &mesh).unwrap();
        w.finish().unwrap();
    }
    let after = std::fs::read(&path).unwrap();
    let r = ArchiveReader::open(&path).unwrap();
    assert_eq!(r.version(), 4);
    let first_end = r.frames()[1].offset as usize;
    assert_eq!(&after[16..first_end], &before[16..first_end]);
    assert_eq!(
        r.frames()
            .iter()
            .map(|f| f.attribute_error_bound)
            .collect::<Vec<_>>(),
        [None, Some(1e-3), Some(2e-2)]
    );
    assert!(r.read_surface(0).unwrap().fluid.attributes.is_empty());
    for (n, bound) in [(1, 1e-3), (2, 2e-2)] {
        let back = r.read_surface(n).unwrap();
        let map = nearest_original(&back.fluid, &mesh, 1e-4);
        let a = &back.fluid.attributes[0];
        let want: Vec<f32> = map
            .iter()
            .flat_map(|&v| mesh.attributes[0].item(v).to_vec())
            .collect();
        check_within(&a.values, &want, bound, &format!("frame {n}"));
        // The coarser bound is used, not just allowed.
        let worst = a
            .values
            .iter()
            .zip(&want)
            .map(|(g, w)| (g - w).abs() as f64)
            .fold(0.0, f64::max);
        assert!(worst > bound / 4.0, "frame {n}: worst error {worst}");
    }
    // Values that do not fit are refused, naming the frame.
    let mut bad = mesh.clone();
    bad.attributes[1].values.pop();
    let mut w = ArchiveWriter::open_append(&path, &ArchiveOptions::new(1e-4)).unwrap();
    let err = w.append(3, &bad).unwrap_err().to_string();
    assert!(err.contains("frame 3") && err.contains("density"), "{err}");
    bad.attributes[1].values.push(f32::NAN);
    let err = w.append(3, &bad).unwrap_err().to_string();
    assert!(err.contains("not finite"), "{err}");
    let mut options = ArchiveOptions::new(1e-4);
    options.attribute_error_bound = 0.0;
    assert!(ArchiveWriter::create(&dir.path().join("x.mseq"), &options).is_err());
}

/// The velocity of the nearest particle at every vertex of `mesh` (a realistic field on
/// the surface of the shipped frame 25).
fn nearest_particle_velocity(
    mesh: &TriMesh,
    particles: &[glam::Vec3],
    velocity: &Attribute,
) -> Attribute {
    let cell = 2.0 * R;
    let key = |p: glam::Vec3| (p / cell).floor().as_ivec3();
    let mut grid: hashbrown::HashMap<glam::IVec3, Vec<u32>> = hashbrown::HashMap::new();
    for (i, &p) in particles.iter().enumerate() {
        grid.entry(key(p)).or_default().push(i as u32);
    }
    let mut values = Vec::with_capacity(mesh.vertex_count() * 3);
    for &p in &mesh.positions {
        let c = key(p);
        let mut best = (f32::INFINITY, 0usize);
        for d in 0..27 {
            let k = c + glam::IVec3::new(d % 3 - 1, d / 3 % 3 - 1, d / 9 - 1);
            for &i in grid.get(&k).map(|v| v.as_slice()).unwrap_or(&[]) {
                let d2 = particles[i as usize].distance_squared(p);
                if d2 < best.0 {
                    best = (d2, i as usize);
                }
            }
        }
        if best.0.is_infinite() {
            best.1 = (0..particles.len())
                .min_by(|&a, &b| {
                    particles[a]
                        .distance_squared(p)
                        .total_cmp(&particles[b].distance_squared(p))
                })
                .unwrap();
        }
        values.extend_from_slice(velocity.item(best.1));
    }
    Attribute {
        name: "velocity".into(),
        components: 3,
        values,
    }
}

#[test]
fn velocities_of_the_shipped_frame_25() {
    // Frame 25 as `reconstruct … -o run.mseq` stores it, with the velocity of the nearest
    // particle at every control vertex, at the default attribute bound (1 mm/s).
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("datasets");
    let particles =
        read_particles(&root.join("dambreak_small/ParticleData_Fluid_25.vtk"), None).unwrap();
    let velocity = particles
        .attributes
        .iter()
        .find(|a| a.name == "velocity")
        .expect("the VTK has velocities");
    let mut options = ReconstructOptions::new(R);
    options.subdivide.levels = 0;
    let mut surface = reconstruct(&particles.positions, &options).unwrap().0;
    surface.fluid.attributes = vec![nearest_particle_velocity(
        &surface.fluid,
        &particles.positions,
        velocity,
    )];
    let (lo, hi) = velocity
        .values
        .chunks(3)
        .fold(([f32::MAX; 3], [f32::MIN; 3]), |(lo, hi), v| {
            (
                [0, 1, 2].map(|c| lo[c].min(v[c])),
                [0, 1, 2].map(|c| hi[c].max(v[c])),
            )
        });
    let dir = tempfile::tempdir().unwrap();
    let mut sizes = Vec::new();
    for with_velocity in [false, true] {
        let path = dir.path().join(format!("v{with_velocity}.mseq"));
        let mut frame_surface = surface.clone();
        if !with_velocity {
            frame_surface.fluid.attributes.clear();
        }
        let mut w = ArchiveWriter::create(&path, &ArchiveOptions::new(BOUND)).unwrap();
        let bytes = w.append_frame(25, &archive_frame(&frame_surface)).unwrap();
        w.finish().unwrap();
        sizes.push(bytes);
        let r = ArchiveReader::open(&path).unwrap();
        let back = r.read_geometry(25).unwrap();
        if with_velocity {
            // Loop's masks are convex: every decoded value lies within the particles'
            // range (plus the bound).
            let a = &back.fluid.attributes[0];
            assert_eq!(a.len(), back.fluid.vertex_count());
            for v in a.values.chunks(3) {
                for c in 0..3 {
                    assert!(
                        v[c] >= lo[c] - 1.001e-3 && v[c] <= hi[c] + 1.001e-3,
                        "{v:?}"
                    );
                }
            }
        }
    }
    let vertices = surface.fluid.vertex_count();
    println!(
        "frame 25: {} control vertices, {} bytes without velocity, {} with ({} bytes for the velocities, {:.2} bits per control vertex)",
        vertices,
        sizes[0],
        sizes[1],
        sizes[1] - sizes[0],
        8.0 * (sizes[1] - sizes[0]) as f64 / vertices as f64
    );
    assert!(sizes[1] > sizes[0]);
}

/// The frame as `archive extract` writes it.
fn extracted(r: &ArchiveReader, number: i64, dir: &Path) -> Vec<u8> {
    let path = dir.join(format!("x{number}.obj"));
    let surface = r.read_surface(number).unwrap();
    meniscus::io::mesh::write_surface(&path, &surface, &Default::default()).unwrap();
    std::fs::read(&path).unwrap()
}

#[test]
fn a_damaged_record_header_costs_only_its_frame_and_appends_lose_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mseq");
    let frames = frames();
    write_archive(&path, &frames[..5]);
    let r = ArchiveReader::open(&path).unwrap();
    let before: Vec<Vec<u8>> = frames[..5]
        .iter()
        .map(|(n, _)| extracted(&r, *n, dir.path()))
        .collect();
    let third = r.frames()[2].clone();
    let mut bytes = std::fs::read(&path).unwrap();
    bytes[third.offset as usize + 17] ^= 0x08; // the triangle count
    std::fs::write(&path, &bytes).unwrap();
    let check = |expect_new: bool| {
        let r = ArchiveReader::open(&path).unwrap();
        for (k, (n, _)) in frames[..5].iter().enumerate() {
            if k == 2 {
                let err = r.read_frame(*n).unwrap_err().to_string();
                assert!(
                    err.contains(&format!("frame {n}")) && err.contains("header"),
                    "{err}"
                );
            } else {
                assert_eq!(extracted(&r, *n, dir.path()), before[k], "frame {n}");
            }
        }
        let report = r.verify();
        assert!(!report.is_clean());
        assert_eq!(report.damaged.len(), 1, "{report:?}");
        assert_eq!(report.damaged[0].0, third.number);
        assert_eq!(report.good.len(), if expect_new { 5 } else { 4 });
        r
    };
    check(false);
    // Appending goes after the last record and keeps the damaged one where it is.
    let mut w = ArchiveWriter::open_append(&path, &ArchiveOptions::new(BOUND)).unwrap();
    w.append_frame(frames[5].0, &archive_frame(&frames[5].1))
        .unwrap();
    w.finish().unwrap();
    let r = check(true);
    let mut alone = dir.path().join("alone.mseq");
    write_archive(&alone, &frames[5..]);
    let a = ArchiveReader::open(&alone).unwrap();
    assert_eq!(
        extracted(&r, frames[5].0, dir.path()),
        extracted(&a, frames[5].0, dir.path())
    );
    // Without the index the scan finds the records after the damaged one.
    let mut cut = std::fs::read(&path).unwrap();
    cut.truncate(
        r.frames()
            .last()
            .map(|f| f.offset + 48 + f.payload_bytes)
            .unwrap() as usize,
    );
    alone.set_file_name("noindex.mseq");
    std::fs::write(&alone, &cut).unwrap();
    let s = ArchiveReader::open(&alone).unwrap();
    assert!(s.recovered_by_scan());
    assert_eq!(s.frames().len(), 5);
    let report = s.verify();
    assert_eq!(report.good.len(), 5);
    assert!(
        report.damage.iter().any(|d| d.contains("damaged record")),
        "{report:?}"
    );
    // The CLI exits non-zero.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_meniscus"))
        .args(["archive", "verify"])
        .arg(&path)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stdout).contains(&format!("frame {}: DAMAGED", third.number))
    );
}

#[test]
fn truncation_anywhere_is_damage_and_appends_keep_every_complete_frame() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mseq");
    let frames = frames();
    write_archive(&path, &frames[..4]);
    let bytes = std::fs::read(&path).unwrap();
    let r = ArchiveReader::open(&path).unwrap();
    let infos = r.frames().to_vec();
    let before: Vec<Vec<u8>> = infos
        .iter()
        .map(|f| extracted(&r, f.number, dir.path()))
        .collect();
    let cut_path = dir.path().join("cut.mseq");
    for sixteenth in 1..16 {
        let cut = bytes.len() * sixteenth / 16;
        std::fs::write(&cut_path, &bytes[..cut]).unwrap();
        let r = ArchiveReader::open(&cut_path).unwrap();
        assert!(!r.verify().is_clean(), "cut at {cut}");
        let complete: Vec<usize> = (0..infos.len())
            .filter(|&k| (infos[k].offset + 48 + infos[k].payload_bytes) as usize <= cut)
            .collect();
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_meniscus"))
            .args(["archive", "verify"])
            .arg(&cut_path)
            .output()
            .unwrap();
        assert!(!out.status.success(), "cut at {cut}");
        let mut w = ArchiveWriter::open_append(&cut_path, &ArchiveOptions::new(BOUND)).unwrap();
        w.append_frame(frames[5].0, &archive_frame(&frames[5].1))
            .unwrap();
        w.finish().unwrap();
        let r = ArchiveReader::open(&cut_path).unwrap();
        let report = r.verify();
        assert!(report.is_clean(), "cut at {cut}: {report:?}");
        assert_eq!(report.good.len(), complete.len() + 1, "cut at {cut}");
        for &k in &complete {
            assert_eq!(extracted(&r, infos[k].number, dir.path()), before[k]);
        }
    }
}

#[test]
fn a_record_length_that_wraps_the_scan_position_does_not_loop() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tiny.mseq");
    let mut bytes = Vec::new();
    bytes.extend_from_slice(b"MNSCMSEQ");
    bytes.extend_from_slice(&3u32.to_le_bytes());
    bytes.extend_from_slice(&0u32.to_le_bytes());
    let mut h = Vec::new();
    h.extend_from_slice(b"FRAM");
    h.extend_from_slice(&0i64.to_le_bytes());
    h.extend_from_slice(&0u32.to_le_bytes());
    h.extend_from_slice(&0u32.to_le_bytes());
    h.extend_from_slice(&1e-3f64.to_le_bytes());
    // 16 + 48 + this = 16 modulo 2^64: the next record would start where this one does.
    h.extend_from_slice(&(u64::MAX - 47).to_le_bytes());
    h.extend_from_slice(&0u32.to_le_bytes());
    h.extend_from_slice(&0u32.to_le_bytes());
    let crc = crc32fast::hash(&h);
    h.extend_from_slice(&crc.to_le_bytes());
    bytes.extend_from_slice(&h);
    assert_eq!(bytes.len(), 64);
    std::fs::write(&path, &bytes).unwrap();
    let r = ArchiveReader::open(&path).unwrap();
    assert!(r.frames().is_empty());
    let report = r.verify();
    assert!(!report.is_clean());
    assert_eq!(report.damaged.len(), 1, "{report:?}");
    assert!(ArchiveWriter::open_append(&path, &ArchiveOptions::new(BOUND)).is_ok());
}

/// An archive of one record (no index) with a hand-made payload and header fields.
fn hostile_archive(
    dir: &Path,
    payload: &[u8],
    vertices: u32,
    triangles: u32,
    step: f64,
) -> PathBuf {
    let mut bytes = Vec::new();
    bytes.extend_from_slice(b"MNSCMSEQ");
    bytes.extend_from_slice(&3u32.to_le_bytes());
    bytes.extend_from_slice(&0u32.to_le_bytes());
    let mut h = Vec::new();
    h.extend_from_slice(b"FRAM");
    h.extend_from_slice(&0i64.to_le_bytes());
    h.extend_from_slice(&vertices.to_le_bytes());
    h.extend_from_slice(&triangles.to_le_bytes());
    h.extend_from_slice(&step.to_le_bytes());
    h.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    h.extend_from_slice(&crc32fast::hash(payload).to_le_bytes());
    h.extend_from_slice(&0u32.to_le_bytes());
    let crc = crc32fast::hash(&h);
    h.extend_from_slice(&crc.to_le_bytes());
    bytes.extend_from_slice(&h);
    bytes.extend_from_slice(payload);
    let path = dir.join("hostile.mseq");
    std::fs::write(&path, &bytes).unwrap();
    path
}

fn varints(values: &[u64]) -> Vec<u8> {
    let mut out = Vec::new();
    for &v in values {
        let mut v = v;
        while v >= 0x80 {
            out.push((v as u8) | 0x80);
            v >>= 7;
        }
        out.push(v as u8);
    }
    out
}

/// The frame is refused as damaged, by `read_frame` and `verify`, with `what` in the
/// message.
fn assert_refused(path: &Path, what: &str) {
    let r = ArchiveReader::open(path).unwrap();
    let err = r.read_frame(0).unwrap_err().to_string();
    assert!(err.contains("frame 0") && err.contains(what), "{err}");
    let report = r.verify();
    assert_eq!(report.damaged.len(), 1, "{report:?}");
    assert!(report.good.is_empty());
}

#[test]
fn hostile_record_headers_are_errors_before_any_allocation() {
    let dir = tempfile::tempdir().unwrap();
    // A real frame with its step replaced: NaN, 1e300, negative, zero.
    let path = dir.path().join("real.mseq");
    let mut w = ArchiveWriter::create(&path, &ArchiveOptions::new(1e-3)).unwrap();
    w.append(0, &icosphere(1, 1.0)).unwrap();
    w.finish().unwrap();
    let good = std::fs::read(&path).unwrap();
    for step in [f64::NAN, 1e300, -2e-3, 0.0, f64::INFINITY] {
        let mut bytes = good.clone();
        bytes[16 + 20..16 + 28].copy_from_slice(&step.to_le_bytes());
        let crc = crc32fast::hash(&bytes[16..16 + 44]);
        bytes[16 + 44..16 + 48].copy_from_slice(&crc.to_le_bytes());
        std::fs::write(&path, &bytes).unwrap();
        assert_refused(&path, "quantization step");
    }
    // Counts far beyond what the payload holds, with and without a zstd content size.
    let raw = varints(&[0, 0, 4_000_000_000, 4_000_000_000, 0, 0, 0, 0]);
    let stated = zstd::bulk::compress(&raw, 3).unwrap();
    let path = hostile_archive(dir.path(), &stated, u32::MAX, u32::MAX, 2e-3);
    assert_refused(&path, "cannot fit");
    let unstated = zstd::stream::encode_all(&raw[..], 3).unwrap();
    assert!(zstd::zstd_safe::get_frame_content_size(&unstated)
        .unwrap()
        .is_none());
    let path = hostile_archive(dir.path(), &unstated, u32::MAX, u32::MAX, 2e-3);
    assert_refused(&path, "cannot fit");
    // A plain mesh (version-1 layout inside) asking for five Loop steps.
    let raw = varints(&[5, 0, 3, 1, 0, 0, 0, 0]);
    let path = hostile_archive(
        dir.path(),
        &zstd::bulk::compress(&raw, 3).unwrap(),
        3 * 4u32.pow(5),
        4u32.pow(5),
        2e-3,
    );
    assert_refused(&path, "subdivision levels");
    // The writer refuses such a frame instead of storing it.
    let mut w =
        ArchiveWriter::create(&dir.path().join("w.mseq"), &ArchiveOptions::new(1e-3)).unwrap();
    let mesh = icosphere(0, 1.0);
    let frame = ArchiveFrame {
        fluid: &mesh,
        subdivision_levels: 5,
        spheres: &SphereInstances::default(),
    };
    let err = w.append_frame(0, &frame).unwrap_err().to_string();
    assert!(
        err.contains("frame 0") && err.contains("subdivision levels"),
        "{err}"
    );
    // An error bound whose step a coordinate cannot be decoded with.
    assert!(
        ArchiveWriter::create(&dir.path().join("x.mseq"), &ArchiveOptions::new(1e300)).is_err()
    );
}

#[test]
fn appending_with_another_error_bound_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mseq");
    let mut w = ArchiveWriter::create(&path, &ArchiveOptions::new(1e-3)).unwrap();
    w.append(0, &icosphere(1, 1.0)).unwrap();
    w.finish().unwrap();
    let before = std::fs::read(&path).unwrap();
    let err = ArchiveWriter::open_append(&path, &ArchiveOptions::new(2e-3))
        .err()
        .expect("refused")
        .to_string();
    assert!(
        err.contains("0.002") && err.contains("0.001") && err.contains("run.mseq"),
        "{err}"
    );
    assert!(!err.contains("--"), "names no flag: {err}");
    assert_eq!(std::fs::read(&path).unwrap(), before);
    let mut w = ArchiveWriter::open_append(&path, &ArchiveOptions::new(1e-3)).unwrap();
    w.append(1, &icosphere(1, 1.0)).unwrap();
    w.finish().unwrap();
    assert_eq!(ArchiveReader::open(&path).unwrap().verify().good, [0, 1]);
    // The same bound in world units computed another way (0.04 × an f32 radius, as
    // reconstruct's default is) appends, and the new frame keeps the archive's step.
    let computed = 0.04 * 0.025f32 as f64;
    assert_ne!(computed, 1e-3);
    let mut w = ArchiveWriter::open_append(&path, &ArchiveOptions::new(computed)).unwrap();
    w.append(2, &icosphere(1, 1.0)).unwrap();
    w.finish().unwrap();
    let r = ArchiveReader::open(&path).unwrap();
    assert!(r.frames().iter().all(|f| f.step == 2e-3), "one step");
    assert_eq!(r.verify().good, [0, 1, 2]);
}

#[test]
fn a_new_archive_is_written_only_when_its_first_frame_is() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mseq");
    let w = ArchiveWriter::create(&path, &ArchiveOptions::new(1e-3)).unwrap();
    drop(w);
    assert!(!path.exists());
    // finish makes an archive without frames.
    ArchiveWriter::create(&path, &ArchiveOptions::new(1e-3))
        .unwrap()
        .finish()
        .unwrap();
    let r = ArchiveReader::open(&path).unwrap();
    assert!(r.frames().is_empty() && r.verify().is_clean());
}

// ---------------------------------------------------------------------------------------
// Failures partway through appending: the archive stays consistent.

/// A small mesh of its own per frame number.
fn small_mesh(k: i64) -> TriMesh {
    let mut m = icosphere(2, 1.0 + 0.1 * k as f32);
    for p in &mut m.positions {
        p.x += k as f32;
    }
    m
}

/// Every frame of the archive at `path`, decoded.
fn decoded(path: &Path) -> Vec<(i64, Vec<glam::Vec3>, Vec<[u32; 3]>)> {
    let r = ArchiveReader::open(path).unwrap();
    r.frames()
        .iter()
        .map(|f| {
            let m = r.read_frame(f.number).unwrap();
            (f.number, m.positions, m.triangles)
        })
        .collect()
}

/// The archive verifies clean through its index and holds exactly `numbers`.
fn assert_clean(path: &Path, numbers: &[i64]) {
    let r = ArchiveReader::open(path).unwrap();
    let v = r.verify();
    assert!(v.is_clean(), "{v:?}");
    assert!(!r.recovered_by_scan(), "the index was written");
    assert_eq!(v.good, numbers);
}

/// Where the index of a finished archive starts (from its trailer).
fn index_offset(bytes: &[u8]) -> usize {
    let n = bytes.len();
    u64::from_le_bytes(bytes[n - 16..n - 8].try_into().unwrap()) as usize
}

static NO_SPHERES: std::sync::LazyLock<SphereInstances> =
    std::sync::LazyLock::new(SphereInstances::default);

fn refused_frame(mesh: &TriMesh) -> ArchiveFrame<'_> {
    // More Loop steps than an archive stores: refused before anything is written.
    ArchiveFrame {
        fluid: mesh,
        subdivision_levels: 5,
        spheres: &NO_SPHERES,
    }
}

#[test]
fn a_writer_dropped_after_an_error_keeps_every_complete_frame() {
    let dir = tempfile::tempdir().unwrap();
    let options = ArchiveOptions::new(1e-3);
    // What finish writes for frames 0 and 1.
    let reference = dir.path().join("reference.mseq");
    let mut w = ArchiveWriter::create(&reference, &options).unwrap();
    for k in [0, 1] {
        w.append(k, &small_mesh(k)).unwrap();
    }
    w.finish().unwrap();

    // A new archive: frames 0 and 1, then a duplicate number refused, the caller gives
    // up (as `archive pack` returns its error) and drops the writer.
    let path = dir.path().join("run.mseq");
    let mut w = ArchiveWriter::create(&path, &options).unwrap();
    for k in [0, 1] {
        w.append(k, &small_mesh(k)).unwrap();
    }
    assert!(w.append(1, &small_mesh(1)).is_err(), "duplicate refused");
    drop(w);
    assert_clean(&path, &[0, 1]);
    assert_eq!(
        std::fs::read(&path).unwrap(),
        std::fs::read(&reference).unwrap(),
        "the same archive finish writes"
    );
    let before = std::fs::read(&path).unwrap();
    let frames_before = decoded(&path);

    // Opened for appending and dropped without writing: nothing changes.
    drop(ArchiveWriter::open_append(&path, &options).unwrap());
    assert_eq!(std::fs::read(&path).unwrap(), before, "untouched");

    // An existing archive: a frame appended, one refused, the writer goes on after the
    // refusal, then another refusal and the writer is dropped.
    let mut w = ArchiveWriter::open_append(&path, &options).unwrap();
    w.append(2, &small_mesh(2)).unwrap();
    let mesh = small_mesh(3);
    assert!(w.append_frame(3, &refused_frame(&mesh)).is_err());
    w.append(4, &small_mesh(4)).unwrap();
    assert!(w.append(0, &small_mesh(0)).is_err(), "duplicate refused");
    drop(w);
    assert_clean(&path, &[0, 1, 2, 4]);
    let after = std::fs::read(&path).unwrap();
    let old_index = index_offset(&before);
    assert_eq!(&after[..old_index], &before[..old_index], "earlier records");
    let frames_after = decoded(&path);
    assert_eq!(
        &frames_after[..2],
        &frames_before[..],
        "earlier frames decode the same"
    );
    // The frames appended before the failure are complete: they decode to what a
    // finished archive of the same meshes holds.
    let full = dir.path().join("full.mseq");
    let mut w = ArchiveWriter::create(&full, &options).unwrap();
    for k in [0, 1, 2, 4] {
        w.append(k, &small_mesh(k)).unwrap();
    }
    w.finish().unwrap();
    assert_eq!(frames_after, decoded(&full));
    assert_eq!(after, std::fs::read(&full).unwrap());
}

#[test]
fn a_panic_while_appending_leaves_a_clean_archive() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mseq");
    let options = ArchiveOptions::new(1e-3);
    let mut w = ArchiveWriter::create(&path, &options).unwrap();
    w.append(0, &small_mesh(0)).unwrap();
    w.finish().unwrap();
    let before = decoded(&path);
    let unwound = std::panic::catch_unwind(|| {
        let mut w = ArchiveWriter::open_append(&path, &options).unwrap();
        w.append(1, &small_mesh(1)).unwrap();
        panic!("the caller fails after frame 1");
    });
    assert!(unwound.is_err());
    assert_clean(&path, &[0, 1]);
    assert_eq!(&decoded(&path)[..1], &before[..]);
}

#[test]
fn a_new_archive_whose_first_frame_fails_does_not_exist() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mseq");
    let mut w = ArchiveWriter::create(&path, &ArchiveOptions::new(1e-3)).unwrap();
    let mesh = small_mesh(0);
    assert!(w.append_frame(0, &refused_frame(&mesh)).is_err());
    assert!(!path.exists());
    drop(w);
    assert!(!path.exists(), "no archive without a frame");
    // Nor after a panic before the first frame.
    let unwound = std::panic::catch_unwind(|| {
        let _w = ArchiveWriter::create(&path, &ArchiveOptions::new(1e-3)).unwrap();
        panic!("before the first frame");
    });
    assert!(unwound.is_err());
    assert!(!path.exists());
}

/// `reconstruct … -o run.mseq` through the library, interrupted (its cancel token set,
/// as Ctrl-C does) when frame `cancel_at` starts.
fn run_into_archive(
    input: &str,
    archive: &Path,
    cancel_at: Option<i64>,
) -> meniscus::Result<Vec<meniscus::job::FrameReport>> {
    use meniscus::job::{plan_frames, run_frames, JobOptions};
    let cancel = meniscus::CancelToken::new();
    let job = JobOptions {
        input_format: None,
        write: Default::default(),
        skip_existing: true,
        archive_error_bound: 0.00025,
        archive_attribute_error_bound: 1e-3,
        fps: 24.0,
        attributes: Default::default(),
        keep_going: false,
        cancel: cancel.clone(),
    };
    let plan = plan_frames(input, archive.to_str().unwrap(), &Default::default())?;
    run_frames(
        &plan,
        &ReconstructOptions::new(0.025),
        &job,
        &mut |_, frame| {
            if Some(frame.number) == cancel_at {
                cancel.cancel();
            }
        },
        &mut |_| {},
        &mut |_| {},
    )
}

#[test]
fn an_interrupted_run_leaves_a_clean_archive() {
    let dir = tempfile::tempdir().unwrap();
    let sphere = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("datasets/analytic/sphere.xyz");
    for k in 1..=4 {
        std::fs::copy(&sphere, dir.path().join(format!("f_{k}.xyz"))).unwrap();
    }
    let input = format!("{}/f_{{}}.xyz", dir.path().display());
    let archive = dir.path().join("run.mseq");
    // A new archive, interrupted at frame 3.
    let err = run_into_archive(&input, &archive, Some(3)).unwrap_err();
    assert!(matches!(err, meniscus::Error::Interrupted), "{err}");
    assert_clean(&archive, &[1, 2]);
    let before = decoded(&archive);
    // The re-run skips them, appends frame 3 and is interrupted at frame 4.
    let err = run_into_archive(&input, &archive, Some(4)).unwrap_err();
    assert!(matches!(err, meniscus::Error::Interrupted), "{err}");
    assert_clean(&archive, &[1, 2, 3]);
    assert_eq!(&decoded(&archive)[..2], &before[..]);
    // A new archive interrupted at its first frame is not left behind.
    let fresh = dir.path().join("fresh.mseq");
    assert!(run_into_archive(&input, &fresh, Some(1)).is_err());
    assert!(!fresh.exists());
    // The last run completes it.
    let reports = run_into_archive(&input, &archive, None).unwrap();
    assert_eq!(reports.iter().filter(|r| r.skipped).count(), 3);
    assert_clean(&archive, &[1, 2, 3, 4]);
}

// Merging.

/// An archive of small synthetic meshes as frames `numbers`, with error bound `bound`.
fn small_archive(path: &Path, numbers: &[i64], bound: f64) {
    let mut w = ArchiveWriter::create(path, &ArchiveOptions::new(bound)).unwrap();
    for &n in numbers {
        w.append(n, &bumpy(2, 0.3 + 0.01 * n as f32)).unwrap();
    }
    w.finish().unwrap();
}

fn names_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn merging_interleaves_frames_and_equals_one_writer() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n);
    small_archive(&p("even.mseq"), &[0, 2, 4], 1e-4);
    small_archive(&p("odd.mseq"), &[1, 3], 1e-4);
    small_archive(&p("one.mseq"), &[0, 1, 2, 3, 4], 1e-4);
    let stats =
        meniscus::archive::merge(&[p("odd.mseq"), p("even.mseq")], &p("all/merged.mseq")).unwrap();
    assert_eq!((stats.inputs, stats.frames), (2, 5));
    let merged = std::fs::read(p("all/merged.mseq")).unwrap();
    assert_eq!(stats.bytes, merged.len() as u64);
    assert!(
        merged == std::fs::read(p("one.mseq")).unwrap(),
        "byte-identical to one writer's archive"
    );
    let r = ArchiveReader::open(&p("all/merged.mseq")).unwrap();
    assert!(r.verify().is_clean());
    // One input: the same archive again.
    meniscus::archive::merge(&[p("one.mseq")], &p("copy.mseq")).unwrap();
    assert_eq!(std::fs::read(p("copy.mseq")).unwrap(), merged);
    // Into one of its inputs: replaced whole.
    small_archive(&p("later.mseq"), &[7], 1e-4);
    meniscus::archive::merge(&[p("copy.mseq"), p("later.mseq")], &p("copy.mseq")).unwrap();
    let numbers: Vec<i64> = ArchiveReader::open(&p("copy.mseq"))
        .unwrap()
        .frames()
        .iter()
        .map(|f| f.number)
        .collect();
    assert_eq!(numbers, [0, 1, 2, 3, 4, 7]);
}

#[test]
fn merging_refuses_conflicts_and_damage_and_leaves_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n);
    small_archive(&p("a.mseq"), &[0, 1], 1e-4);
    small_archive(&p("b.mseq"), &[1, 2], 1e-4);
    small_archive(&p("coarse.mseq"), &[5], 2e-4);
    let out = p("out.mseq");
    let refused = |inputs: &[&str]| -> String {
        let inputs: Vec<PathBuf> = inputs.iter().map(|n| p(n)).collect();
        let e = meniscus::archive::merge(&inputs, &out)
            .unwrap_err()
            .to_string();
        assert!(!out.exists(), "no output on error: {e}");
        e
    };
    let e = refused(&["a.mseq", "b.mseq"]);
    assert!(
        e.contains("b.mseq: frame 1: also in") && e.contains("a.mseq"),
        "{e}"
    );
    let e = refused(&["a.mseq", "coarse.mseq"]);
    assert!(
        e.contains("error bound 0.0002 differs from the error bound 0.0001")
            && e.contains("a.mseq")
            && e.contains("coarse.mseq"),
        "{e}"
    );
    let e = refused(&["a.mseq", "a.mseq"]);
    assert!(e.contains("a.mseq: frame 0: given twice"), "{e}");
    // A flipped payload byte: refused, naming the frame.
    let mut bytes = std::fs::read(p("b.mseq")).unwrap();
    let r = ArchiveReader::open(&p("b.mseq")).unwrap();
    let f = &r.frames()[1];
    bytes[(f.offset + 48 + f.payload_bytes / 2) as usize] ^= 0x10;
    std::fs::write(p("bad.mseq"), &bytes).unwrap();
    // (opening finds no damage in the headers: the payload checksum is checked on copy)
    let e = refused(&["bad.mseq"]);
    assert!(
        e.contains("bad.mseq") && e.contains("frame 2") && e.contains("checksum"),
        "{e}"
    );
    // An unfinished archive (no index, a record cut off): refused.
    let a = ArchiveReader::open(&p("a.mseq")).unwrap();
    let cut = &std::fs::read(p("a.mseq")).unwrap()[..(a.frames()[1].offset as usize + 10)];
    std::fs::write(p("cut.mseq"), cut).unwrap();
    let e = refused(&["cut.mseq"]);
    assert!(e.contains("cut.mseq") && e.contains("unfinished"), "{e}");
    // An existing output that is no input is not overwritten.
    std::fs::write(&out, b"keep").unwrap();
    let e = meniscus::archive::merge(&[p("a.mseq")], &out)
        .unwrap_err()
        .to_string();
    assert!(e.contains("exists"), "{e}");
    assert_eq!(std::fs::read(&out).unwrap(), b"keep");
    std::fs::remove_file(&out).unwrap();
    // No temporary file is left behind.
    assert!(
        names_in(dir.path()).iter().all(|n| !n.contains("merging")),
        "{:?}",
        names_in(dir.path())
    );
}

#[test]
fn merging_a_version_4_input_gives_what_one_writer_gives() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n);
    let plain = bumpy(2, 0.3);
    let carried = with_attributes(bumpy(2, 0.4));
    let write = |path: &Path, frames: &[(i64, &TriMesh)]| {
        let mut w = ArchiveWriter::create(path, &ArchiveOptions::new(1e-4)).unwrap();
        for (n, mesh) in frames {
            w.append(*n, mesh).unwrap();
        }
        w.finish().unwrap();
    };
    write(&p("plain.mseq"), &[(0, &plain), (2, &plain)]);
    write(&p("attrs.mseq"), &[(1, &carried)]);
    // One writer: version 3 until frame 1 makes it version 4.
    write(&p("one.mseq"), &[(0, &plain), (1, &carried), (2, &plain)]);
    assert_eq!(ArchiveReader::open(&p("plain.mseq")).unwrap().version(), 3);
    meniscus::archive::merge(&[p("plain.mseq"), p("attrs.mseq")], &p("merged.mseq")).unwrap();
    let merged = ArchiveReader::open(&p("merged.mseq")).unwrap();
    assert_eq!(merged.version(), 4);
    assert!(merged.verify().is_clean());
    assert!(std::fs::read(p("merged.mseq")).unwrap() == std::fs::read(p("one.mseq")).unwrap());
}

/// A deterministic generator (xorshift), so that every run mutates the same way.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// Recomputes the checksums of the records that follow each other from the file header
/// on and of an index that ends at the trailer, so that a mutation reaches the frame
/// decoders instead of stopping at a CRC mismatch.
fn reseal(b: &mut [u8]) {
    let u64_at = |b: &[u8], at: usize| u64::from_le_bytes(b[at..at + 8].try_into().unwrap());
    let mut pos = 16;
    while pos + 48 <= b.len() && &b[pos..pos + 4] == b"FRAM" {
        let Some(end) = usize::try_from(u64_at(b, pos + 28))
            .ok()
            .and_then(|len| (pos + 48).checked_add(len))
            .filter(|&end| end <= b.len())
        else {
            break;
        };
        let crc = crc32fast::hash(&b[pos + 48..end]);
        b[pos + 36..pos + 40].copy_from_slice(&crc.to_le_bytes());
        let crc = crc32fast::hash(&b[pos..pos + 44]);
        b[pos + 44..pos + 48].copy_from_slice(&crc.to_le_bytes());
        pos = end;
    }
    let len = b.len();
    if len >= 48 && &b[len - 8..] == b"MSEQEND!" {
        let index = usize::try_from(u64_at(b, len - 16)).unwrap_or(usize::MAX);
        if index >= 16 && index.checked_add(16).is_some_and(|e| e <= len - 16) {
            let crc = crc32fast::hash(&b[index..len - 20]);
            b[len - 20..len - 16].copy_from_slice(&crc.to_le_bytes());
        }
    }
}

/// Opens `path` and decodes everything in it; every error names the file.
fn read_everything(path: &Path, name: &str) {
    let r = match ArchiveReader::open(path) {
        Ok(r) => r,
        Err(e) => return assert!(e.to_string().contains(name), "{e}"),
    };
    let numbers: Vec<i64> = r.frames().iter().map(|f| f.number).collect();
    let report = r.verify();
    assert!(report.good.len() + report.damaged.len() >= numbers.len());
    for n in numbers {
        match r.read_surface(n) {
            Ok(s) => {
                let v = s.fluid.positions.len() as u32;
                assert!(s.fluid.triangles.iter().flatten().all(|&i| i < v));
            }
            Err(e) => assert!(e.to_string().contains(name), "{e}"),
        }
    }
}

#[test]
fn mutated_archives_are_read_or_rejected_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.mseq");
    // A frame with attributes, a Loop step and spheres, and a plain mesh: version 4.
    let fluid = with_attributes(bumpy(1, 1.0));
    let spheres = spheres_with_attributes(3);
    let mut w = ArchiveWriter::create(&path, &ArchiveOptions::new(1e-3)).unwrap();
    w.append_frame(
        7,
        &ArchiveFrame {
            fluid: &fluid,
            subdivision_levels: 1,
            spheres: &spheres,
        },
    )
    .unwrap();
    w.append(8, &icosphere(0, 0.5)).unwrap();
    w.finish().unwrap();
    let base = std::fs::read(&path).unwrap();
    assert!(base.len() < 8192, "{}", base.len());
    assert_eq!(ArchiveReader::open(&path).unwrap().verify().good, [7, 8]);
    let mut rng = Rng(0x6a09_e667_f3bc_c909);
    for round in 0..5000 {
        let mut b = base.clone();
        match rng.below(4) {
            0 => {
                for _ in 0..1 + rng.below(4) {
                    let i = rng.below(b.len());
                    b[i] ^= 1 << rng.below(8);
                }
            }
            1 => b.truncate(rng.below(b.len())),
            2 => {
                let i = rng.below(b.len() + 1);
                let n = 1 + rng.below(8);
                let bytes: Vec<u8> = (0..n).map(|_| rng.next() as u8).collect();
                b.splice(i..i, bytes);
            }
            _ => {
                // A header field or count: a little-endian u32 or u64 of extreme value.
                let i = rng.below(b.len() - 8);
                match rng.below(3) {
                    0 => b[i..i + 4].copy_from_slice(&u32::MAX.to_le_bytes()),
                    1 => b[i..i + 8]
                        .copy_from_slice(&(u64::MAX - rng.below(64) as u64).to_le_bytes()),
                    _ => b[i] = 0xff,
                }
            }
        }
        // Half the cases with their checksums recomputed, to reach the decoders.
        if round % 2 == 1 {
            reseal(&mut b);
        }
        std::fs::write(&path, &b).unwrap();
        if std::panic::catch_unwind(|| read_everything(&path, "m.mseq")).is_err() {
            let keep = std::env::temp_dir().join(format!("meniscus-crash-{round}-m.mseq"));
            std::fs::write(&keep, &b).unwrap();
            panic!(
                "round {round}: reading a mutated archive panicked (kept as {})",
                keep.display()
            );
        }
    }
}

#[test]
fn an_index_of_many_entries_over_many_records_opens_in_linear_time() {
    // 400 000 empty records and an index listing each: matching every entry against
    // every record (as the reader used to) is 8·10^10 comparisons.
    let n = 400_000usize;
    let mut bytes = Vec::with_capacity(16 + n * 64 + 36);
    bytes.extend_from_slice(b"MNSCMSEQ");
    bytes.extend_from_slice(&3u32.to_le_bytes());
    bytes.extend_from_slice(&0u32.to_le_bytes());
    let mut index = Vec::with_capacity(12 + 16 * n);
    index.extend_from_slice(b"INDX");
    index.extend_from_slice(&(n as u64).to_le_bytes());
    for k in 0..n {
        index.extend_from_slice(&(k as i64).to_le_bytes());
        index.extend_from_slice(&(bytes.len() as u64).to_le_bytes());
        let mut h = Vec::with_capacity(48);
        h.extend_from_slice(b"FRAM");
        h.extend_from_slice(&(k as i64).to_le_bytes());
        h.extend_from_slice(&[0; 8]); // vertices, triangles
        h.extend_from_slice(&1e-3f64.to_le_bytes());
        h.extend_from_slice(&0u64.to_le_bytes()); // payload length
        h.extend_from_slice(&crc32fast::hash(&[]).to_le_bytes());
        h.extend_from_slice(&0u32.to_le_bytes());
        h.extend_from_slice(&crc32fast::hash(&h).to_le_bytes());
        bytes.extend_from_slice(&h);
    }
    let index_offset = bytes.len() as u64;
    let crc = crc32fast::hash(&index);
    bytes.extend_from_slice(&index);
    bytes.extend_from_slice(&crc.to_le_bytes());
    bytes.extend_from_slice(&index_offset.to_le_bytes());
    bytes.extend_from_slice(b"MSEQEND!");
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("many.mseq");
    std::fs::write(&path, &bytes).unwrap();
    let start = std::time::Instant::now();
    let r = ArchiveReader::open(&path).unwrap();
    let took = start.elapsed();
    assert!(!r.recovered_by_scan());
    assert_eq!(r.frames().len(), n);
    // Linear: well under a second; quadratic: minutes.
    assert!(took.as_secs() < 30, "opening took {took:?}");
}

/// The first record's decompressed payload (`raw` of src/archive/frame.rs) and its
/// header's vertex and triangle counts.
fn first_raw(path: &Path) -> (Vec<u8>, u32, u32) {
    let b = std::fs::read(path).unwrap();
    let u32_at = |at: usize| u32::from_le_bytes(b[at..at + 4].try_into().unwrap());
    let len = u64::from_le_bytes(b[16 + 28..16 + 36].try_into().unwrap()) as usize;
    let raw = zstd::bulk::decompress(&b[64..64 + len], 1 << 24).unwrap();
    (raw, u32_at(16 + 12), u32_at(16 + 16))
}

fn read_varint(raw: &[u8], pos: &mut usize) -> u64 {
    let (mut v, mut shift) = (0u64, 0);
    loop {
        let b = raw[*pos];
        *pos += 1;
        v |= ((b & 0x7f) as u64) << shift;
        if b < 0x80 {
            return v;
        }
        shift += 7;
    }
}

/// Moves `pos` past the three length-prefixed streams of a mesh.
fn skip_streams(raw: &[u8], pos: &mut usize) {
    for _ in 0..3 {
        let len = read_varint(raw, pos) as usize;
        *pos += len;
    }
}

/// `raw` with the position stream of the mesh whose streams start at `*pos` replaced by
/// `n` residuals of `value` each.
fn replace_residuals(raw: &[u8], mut pos: usize, n: usize, value: u64) -> Vec<u8> {
    for _ in 0..2 {
        let len = read_varint(raw, &mut pos) as usize;
        pos += len;
    }
    let start = pos;
    let len = read_varint(raw, &mut pos) as usize;
    pos += len;
    let residuals = varints(&vec![value; n]);
    let mut out = raw[..start].to_vec();
    out.extend(varints(&[residuals.len() as u64]));
    out.extend(residuals);
    out.extend_from_slice(&raw[pos..]);
    out
}

#[test]
fn lattice_coordinates_that_overflow_are_decoded_or_refused_never_panic() {
    // Found by fuzzing (archive_payload): residuals of ±2^63 made `prediction + residual`
    // overflow i64 in the fused Loop decoder (a panic with overflow checks, as `cargo
    // test` builds; wrapped garbage otherwise). Predictions and residuals are now modular
    // on both sides, and a frame decoding to coordinates beyond f32 is refused.
    let dir = tempfile::tempdir().unwrap();
    let zigzag_max = u64::MAX - 1; // zigzag(i64::MAX)
    let spheres = SphereInstances {
        template: icosphere(0, 0.1),
        centers: vec![glam::Vec3::ZERO, glam::Vec3::X, glam::Vec3::Y],
        attributes: Vec::new(),
    };
    let none = SphereInstances::default();
    let closed = icosphere(0, 1.0);
    let mut open = icosphere(0, 1.0);
    open.triangles.truncate(5);
    // (fluid, Loop steps, spheres, what is damaged): the fused Loop decoder (closed mesh,
    // one step), the plain stream decoder (open mesh), the sphere centres.
    for (fluid, levels, spheres, centres) in [
        (&closed, 1, &none, false),
        (&open, 0, &none, false),
        (&closed, 0, &spheres, true),
    ] {
        let path = dir.path().join("real.mseq");
        let mut w = ArchiveWriter::create(&path, &ArchiveOptions::new(1e-3)).unwrap();
        let frame = ArchiveFrame {
            fluid,
            subdivision_levels: levels,
            spheres,
        };
        w.append_frame(0, &frame).unwrap();
        w.finish().unwrap();
        let (raw, vertices, triangles) = first_raw(&path);
        let mut pos = 0;
        let _levels = read_varint(&raw, &mut pos);
        pos += 1; // shape
        let fluid_vertices = read_varint(&raw, &mut pos) as usize;
        let _ = read_varint(&raw, &mut pos);
        let damaged = if centres {
            let mut raw = raw.clone();
            skip_streams(&raw, &mut pos);
            let count = read_varint(&raw, &mut pos) as usize;
            let _template_counts = (read_varint(&raw, &mut pos), read_varint(&raw, &mut pos));
            skip_streams(&raw, &mut pos);
            let centres = varints(&vec![zigzag_max; 3 * count]);
            raw.truncate(pos);
            raw.extend(centres);
            raw
        } else {
            replace_residuals(&raw, pos, 3 * fluid_vertices, zigzag_max)
        };
        // A step of 1e-3 keeps the wrapped coordinates within f32, one of f32::MAX
        // does not: decoded or refused, never a panic.
        for (step, refused) in [(2e-3, false), (f32::MAX as f64, true)] {
            let payload = zstd::bulk::compress(&damaged, 3).unwrap();
            let path = hostile_archive(dir.path(), &payload, vertices, triangles, step);
            let r = ArchiveReader::open(&path).unwrap();
            let result = r.read_surface(0);
            if refused {
                let e = result.unwrap_err().to_string();
                assert!(
                    e.contains("hostile.mseq") && e.contains("frame 0") && e.contains("beyond f32"),
                    "{e}"
                );
            } else if let Err(e) = result {
                panic!("levels {levels}, centres {centres}: {e}");
            }
        }
    }
}
