//! The `.mseq` archive's round trips: every frame within the error bound with identical
//! connectivity (up to a renumbering), random access equal to sequential decoding, and
//! archives without attributes byte-identical to version 3's.

mod support;

use meniscus::archive::{ArchiveFrame, ArchiveOptions, ArchiveReader, ArchiveWriter};
use meniscus::isolated::icosphere;
use meniscus::mesh::{SphereInstances, TriMesh};
use meniscus::pipeline::{reconstruct, ReconstructOptions};
use meniscus::subdivision::{subdivide, SubdivideOptions};
use std::path::Path;
use support::archive::{bumpy, frames, write_archive, BOUND, R};
use support::positions;

/// Length and CRC-32 of the archive `write_synthetic_archive` writes, as the code before
/// attributes (commit 2e68ce4) wrote it.
const GOLDEN_LEN: usize = 182_772;
const GOLDEN_CRC: u32 = 0x28c8_574f;

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

#[test]
fn every_frame_round_trips_within_the_bound() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mseq");
    let mut frames = frames();
    // The droplets: a blob and 500 spheres (radius 0.025).
    let mut droplet_options = ReconstructOptions::new(0.025);
    droplet_options.subdivide.levels = 0;
    let droplets = reconstruct(&positions("analytic/droplets.xyz"), &droplet_options)
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
            let p = positions("dambreak_small/ParticleData_Fluid_25.xyz");
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

/// Frames of synthetic meshes without attributes: a control mesh stored in parts, a
/// small one stored whole with two Loop steps and spheres, an open one, a plain mesh.
fn write_synthetic_archive(path: &Path) {
    let big = bumpy(6, 1.0);
    let small = bumpy(3, 0.5);
    let spheres = SphereInstances {
        template: icosphere(1, 0.05),
        scales: Vec::new(),
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
