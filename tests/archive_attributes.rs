//! Attributes in the `.mseq` archive: values within their bound, through Loop
//! subdivision the same masks as the positions, damage in their streams found, each
//! appended frame with its own bound, the velocities of a shipped frame.

mod support;

use meniscus::archive::{
    ArchiveFrame, ArchiveOptions, ArchiveReader, ArchiveWriter, AttributeInfo, AttributeTarget,
};
use meniscus::io::particles::read_particles;
use meniscus::mesh::{Attribute, SphereInstances, Surface, TriMesh};
use meniscus::pipeline::{reconstruct, ReconstructOptions};
use support::archive::{archive_frame, bumpy, spheres_with_attributes, with_attributes, BOUND, R};

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
    let particles = read_particles(
        &support::dataset("dambreak_small/ParticleData_Fluid_25.vtk"),
        None,
    )
    .unwrap();
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
