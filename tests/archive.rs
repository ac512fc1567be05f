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

fn particles(rel: &str) -> Vec<glam::Vec3> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("datasets");
    read_particles(&root.join(rel), None).unwrap().positions
}

/// The six shipped frames reconstructed the way `reconstruct … -o run.mseq` archives
/// them: the pipeline without its Loop step (the control mesh) and the spheres.
fn frames() -> Vec<(i64, Surface)> {
    let mut options = ReconstructOptions::new(R);
    options.subdivide.levels = 0;
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
        subdivide(&mut expected.fluid, &SubdivideOptions { levels: 1 });
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
            subdivide(&mut m, &SubdivideOptions { levels: 1 });
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
            assert!(report.damaged.is_empty() && report.good.len() == k);
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
    assert!(r.frames().len() >= 2);
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
    // Interrupted: dropped without finish, so there is no index.
    drop(w);
    let after = std::fs::read(&path).unwrap();
    assert_eq!(&after[..first_index], &before[..first_index]);
    // A half-written record at the end, as a crash mid-append leaves it.
    let mut crashed = after.clone();
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
