//! The command line: single frames, sequences, statistics, and clear failures that leave
//! no output behind.

mod support;

use std::path::{Path, PathBuf};
use support::archive::{decoded, Decoded};
use support::{dataset, meniscus, names_in, run, splash};

/// `meniscus reconstruct INPUT -r RADIUS -q -o OUTPUT FLAGS...`: success and stderr.
fn reconstruct(input: &Path, radius: &str, output: &Path, flags: &[&str]) -> (bool, String) {
    let mut args = vec![
        "reconstruct",
        input.to_str().unwrap(),
        "-r",
        radius,
        "-q",
        "-o",
        output.to_str().unwrap(),
    ];
    args.extend_from_slice(flags);
    run(&args)
}

/// Copies double dam break frames 1, 6 and 13 to `dir` as `f_<k>.xyz` (zero-padded to
/// three digits when `padded`) and returns the `{}` pattern naming them.
fn sequence_in(dir: &Path, padded: bool) -> String {
    for k in [1, 6, 13] {
        let name = if padded {
            format!("f_{k:03}.xyz")
        } else {
            format!("f_{k}.xyz")
        };
        std::fs::copy(
            dataset(&format!("double_dambreak/ParticleData_Fluid_{k}.xyz")),
            dir.join(name),
        )
        .unwrap();
    }
    format!("{}/f_{{}}.xyz", dir.display())
}

#[test]
fn reconstructs_a_frame_with_stats() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s.glb");
    let stats = dir.path().join("stats.json");
    let input = dataset("double_dambreak/ParticleData_Fluid_9.vtk");
    let (ok, err) = run(&[
        "reconstruct",
        input.to_str().unwrap(),
        "--particle-radius",
        "0.025",
        "-o",
        out.to_str().unwrap(),
        "--stats",
        stats.to_str().unwrap(),
        "--threads",
        "2",
    ]);
    assert!(ok, "{err}");
    assert!(
        err.contains("marching cubes") && err.contains("total"),
        "timing table: {err}"
    );
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
    let frame = &json["frames"][0];
    assert!(frame["reconstruction"]["fluid_triangles"].as_u64().unwrap() > 10_000);
    assert!(frame["reconstruction"]["stages"].as_array().unwrap().len() >= 4);
    assert!(json["peak_rss_bytes"].as_u64().unwrap() > 0);
    assert!(std::fs::metadata(&out).unwrap().len() > 10_000);
}

#[test]
fn reconstructs_a_sequence_and_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let input = sequence_in(dir.path(), true);
    let output = format!("{}/out/s_{{}}.ply", dir.path().display());
    let (ok, err) = run(&["reconstruct", &input, "-r", "0.025", "-o", &output, "-q"]);
    assert!(ok, "{err}");
    assert_eq!(
        names_in(&dir.path().join("out")),
        ["s_001.ply", "s_006.ply", "s_013.ply"]
    );
    // A range that is partly missing fails and names the missing frame.
    let (ok, err) = run(&[
        "reconstruct",
        &input,
        "-r",
        "0.025",
        "-o",
        &output,
        "--start",
        "1",
        "--end",
        "2",
        "-q",
    ]);
    assert!(!ok && err.contains("missing"), "{err}");
    // Resume: existing outputs are skipped.
    std::fs::remove_file(dir.path().join("out/s_006.ply")).unwrap();
    let (ok, err) = run(&[
        "reconstruct",
        &input,
        "-r",
        "0.025",
        "-o",
        &output,
        "--skip-existing",
    ]);
    assert!(ok, "{err}");
    assert!(err.contains("2 skipped"), "{err}");
    assert!(dir.path().join("out/s_006.ply").exists());
}

#[test]
fn bad_input_fails_clearly_without_output() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, bytes: &[u8]| {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    };
    let mut nan = Vec::new();
    for v in [0.0f32, 0.0, 0.0, f32::NAN, 1.0, 1.0] {
        nan.extend_from_slice(&v.to_le_bytes());
    }
    let cases: Vec<(PathBuf, &str, &str)> = vec![
        (write("empty.xyz", b""), "0.1", "no particles"),
        (write("cut.xyz", &[0u8; 13]), "0.1", "multiple of 12"),
        (write("nan.xyz", &nan), "0.1", "non-finite"),
        (
            write("frame.abc", b"123"),
            "0.1",
            "unknown particle file extension",
        ),
        (dataset("analytic/box.xyz"), "0", "--particle-radius"),
        (dataset("analytic/box.xyz"), "-0.5", "--particle-radius"),
    ];
    for (input, radius, expected) in cases {
        let out = dir.path().join("out.glb");
        let output = meniscus()
            .args([
                "reconstruct",
                input.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
                "-q",
            ])
            .arg(format!("--particle-radius={radius}"))
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&output.stderr);
        assert!(!output.status.success(), "{}: must fail", input.display());
        assert!(err.contains(expected), "{}: {err}", input.display());
        assert!(!out.exists(), "{}: no output on failure", input.display());
    }
    assert!(names_in(dir.path()).iter().all(|f| !f.contains(".tmp-")));
}

#[test]
fn archives_collect_a_sequence_and_extract_frames() {
    let dir = tempfile::tempdir().unwrap();
    let input = sequence_in(dir.path(), false);
    let archive = dir.path().join("run.mseq");
    let a = archive.to_str().unwrap();
    let (ok, err) = run(&[
        "reconstruct",
        &input,
        "-r",
        "0.025",
        "-o",
        a,
        "-q",
        "--end",
        "6",
    ]);
    assert!(ok, "{err}");
    // Resume with the rest of the sequence.
    let (ok, err) = run(&[
        "reconstruct",
        &input,
        "-r",
        "0.025",
        "-o",
        a,
        "-q",
        "--skip-existing",
    ]);
    assert!(ok, "{err}");
    let out = meniscus().args(["archive", "list", a]).output().unwrap();
    let listing = String::from_utf8_lossy(&out.stdout);
    assert_eq!(listing.lines().count(), 4, "{listing}");
    let out = meniscus().args(["archive", "verify", a]).output().unwrap();
    assert!(out.status.success());
    let glb = dir.path().join("f6.glb");
    let (ok, err) = run(&[
        "archive",
        "extract",
        a,
        "--frame",
        "6",
        "-o",
        glb.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(std::fs::metadata(&glb).unwrap().len() > 1000);
    // Every frame at once, into a directory that does not exist yet.
    let pattern = dir.path().join("all/frame_{}.ply");
    let (ok, err) = run(&["archive", "extract", a, "-o", pattern.to_str().unwrap()]);
    assert!(ok, "{err}");
    let extracted = names_in(&dir.path().join("all"));
    assert_eq!(extracted.len(), 3, "{extracted:?}");
    assert!(extracted
        .iter()
        .all(|f| f.starts_with("frame_") && f.ends_with(".ply")));
    // Several frames need a {} in the output.
    let (ok, err) = run(&["archive", "extract", a, "-o", glb.to_str().unwrap()]);
    assert!(!ok && err.contains("{}"), "{err}");
    // Pack the extracted mesh back into a second archive.
    let packed = dir.path().join("packed.mseq");
    let pattern = format!("{}/f{{}}.glb", dir.path().display());
    let (ok, err) = run(&[
        "archive",
        "pack",
        &pattern,
        "-o",
        packed.to_str().unwrap(),
        "--error-bound",
        "0.0005",
    ]);
    assert!(ok, "{err}");
    // A damaged archive fails verification and names the frame.
    let mut bytes = std::fs::read(&archive).unwrap();
    let n = bytes.len();
    bytes[n / 2] ^= 0x55;
    std::fs::write(&archive, &bytes).unwrap();
    let out = meniscus().args(["archive", "verify", a]).output().unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stdout).contains("DAMAGED"));
}

#[test]
fn a_sequence_into_one_gltf_plays_frame_by_frame() {
    let dir = tempfile::tempdir().unwrap();
    let input = sequence_in(dir.path(), false);
    let out = dir.path().join("seq.glb");
    let (ok, err) = run(&[
        "reconstruct",
        &input,
        "-r",
        "0.025",
        "-o",
        out.to_str().unwrap(),
        "-q",
        "--fps",
        "10",
    ]);
    assert!(ok, "{err}");
    let gltf = gltf::Gltf::from_slice(&std::fs::read(&out).unwrap()).unwrap();
    assert_eq!(gltf.nodes().count(), 3);
    assert_eq!(gltf.meshes().count(), 3);
    let animation = gltf.animations().next().expect("one animation");
    assert_eq!(animation.channels().count(), 3);
    for (i, channel) in animation.channels().enumerate() {
        assert_eq!(channel.target().node().index(), i);
        assert_eq!(
            channel.target().property(),
            gltf::animation::Property::Scale
        );
        assert_eq!(
            channel.sampler().interpolation(),
            gltf::animation::Interpolation::Step
        );
        assert_eq!(channel.sampler().input().count(), 3);
    }
    // Frames 1, 6 and 13 at 10 fps: keyed from 0.1 to 1.3 s, Blender's frames 1 to 13.
    let input = animation.channels().next().unwrap().sampler().input();
    let bound = |v: Option<gltf::json::Value>| v.unwrap()[0].as_f64().unwrap() as f32;
    assert_eq!((bound(input.min()), bound(input.max())), (0.1, 1.3));
    // Only the first frame is visible before the animation starts.
    let scales: Vec<[f32; 3]> = gltf.nodes().map(|n| n.transform().decomposed().2).collect();
    assert_eq!(scales, [[1.0; 3], [0.0; 3], [0.0; 3]]);
}

#[test]
fn an_archived_frame_extracts_to_the_mesh_reconstruct_writes() {
    // reconstruct -o run.mseq stops before the Loop step and lets the archive redo it: the
    // extracted frame must have the direct run's vertices and triangles, every vertex
    // within the bound (0.01 r) of the direct run's nearest one, with the same volume.
    let dir = tempfile::tempdir().unwrap();
    let input = dataset("dambreak_small/ParticleData_Fluid_25.xyz");
    let input = input.to_str().unwrap();
    let direct = dir.path().join("direct.ply");
    let archive = dir.path().join("run.mseq");
    let extracted = dir.path().join("extracted.ply");
    for out in [&direct, &archive] {
        let (ok, err) = run(&[
            "reconstruct",
            input,
            "-r",
            "0.012",
            "-q",
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(ok, "{err}");
    }
    let (ok, err) = run(&[
        "archive",
        "extract",
        archive.to_str().unwrap(),
        "--frame",
        "0",
        "-o",
        extracted.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let a = meniscus::io::mesh::read_mesh(&direct).unwrap();
    let b = meniscus::io::mesh::read_mesh(&extracted).unwrap();
    assert_eq!(a.triangle_count(), b.triangle_count());
    assert_eq!(a.vertex_count(), b.vertex_count());
    let bound = 0.01 * 0.012 * 1.001 + 1e-7;
    let cell = |p: glam::Vec3| (p / 0.002).floor().as_ivec3();
    let mut grid: std::collections::HashMap<glam::IVec3, Vec<glam::Vec3>> = Default::default();
    for p in &a.positions {
        grid.entry(cell(*p)).or_default().push(*p);
    }
    for p in &b.positions {
        let c = cell(*p);
        let near = (0..27).any(|d| {
            let key = c + glam::IVec3::new(d % 3 - 1, d / 3 % 3 - 1, d / 9 - 1);
            grid.get(&key).is_some_and(|v| {
                v.iter()
                    .any(|q| (*q - *p).abs().max_element() as f64 <= bound)
            })
        });
        assert!(
            near,
            "extracted vertex {p} has no direct vertex within the bound"
        );
    }
    let (va, vb) = (a.signed_volume(), b.signed_volume());
    assert!((va - vb).abs() <= 1e-3 * va.abs(), "volumes {va} and {vb}");
}

/// A row of the error table: arguments, exit code, fragments stderr must hold, fragments
/// it must not hold.
type Case<'a> = (Vec<&'a str>, i32, Vec<&'a str>, Vec<&'a str>);

/// What a user gets wrong, and what the CLI answers: one table of (arguments, exit code,
/// fragments stderr must hold, fragments it must not hold). Exit codes: 0 done, 1 a file
/// or its content, 2 an option or argument. Errors name the cause and the input, and
/// never an option the user did not give; warnings name the option that has no effect.
#[test]
fn new_user_errors_name_the_real_cause() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let path = |name: &str| d.join(name).to_str().unwrap().to_string();
    let sphere = dataset("analytic/sphere.xyz");
    let sphere = sphere.to_str().unwrap();
    std::fs::create_dir(d.join("frames.xyz")).unwrap();
    let folder = path("frames.xyz");
    let missing = path("missing.xyz");
    // Text saved as .xyz (a multiple of 12 bytes, so only the content gives it away).
    std::fs::write(d.join("junk.xyz"), "0.5 1.5 2.5\n0.5 1.5 2.5\n").unwrap();
    let junk = path("junk.xyz");
    // A PLY header announcing 2^64 - 1 vertices and no data: the counts are checked
    // against the file before any room is sought for them.
    std::fs::write(
        d.join("huge.ply"),
        "ply\nformat binary_little_endian 1.0\nelement vertex 18446744073709551615\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
    )
    .unwrap();
    let huge = path("huge.ply");
    let out = path("s.ply");
    let foo = path("s.foo");
    // A one-frame sequence, and an archive holding the sphere as frame 0.
    std::fs::create_dir(d.join("seq")).unwrap();
    std::fs::copy(sphere, d.join("seq/f_1.xyz")).unwrap();
    let seq = path("seq/f_{}.xyz");
    let archive = path("run.mseq");
    let (ok, err) = run(&["reconstruct", sphere, "-r", "0.025", "-q", "-o", &archive]);
    assert!(ok, "{err}");
    let mut bytes = std::fs::read(&archive).unwrap();
    let n = bytes.len();
    bytes[n / 2] ^= 0x55;
    std::fs::write(d.join("damaged.mseq"), &bytes).unwrap();
    let damaged = path("damaged.mseq");
    // The archive with a NaN quantization step (its header re-checksummed).
    let mut bytes = std::fs::read(&archive).unwrap();
    bytes[16 + 20..16 + 28].copy_from_slice(&f64::NAN.to_le_bytes());
    let crc = crc32fast::hash(&bytes[16..16 + 44]);
    bytes[16 + 44..16 + 48].copy_from_slice(&crc.to_le_bytes());
    std::fs::write(d.join("nan.mseq"), &bytes).unwrap();
    let nan = path("nan.mseq");
    let hashed = path("seq/f_#.xyz");
    let meshes = path("mesh_{}.ply");
    let packed = path("packed.mseq");
    let anim = path("anim.glb");
    let fresh = path("fresh.mseq");
    let fresh2 = path("fresh2.mseq");
    let fresh3 = path("fresh3.mseq");
    let r = ["-r", "0.025"];
    let cases: Vec<Case> = vec![
        // Files and their content: exit 1, naming the file.
        (
            vec!["reconstruct", &missing, "-o", &out],
            1,
            vec!["missing.xyz", "No such file"],
            vec!["invalid option", "--particle-radius"],
        ),
        (
            vec!["reconstruct", &folder, "-o", &out],
            1,
            vec![
                "frames.xyz",
                "is a directory",
                "a sequence is one pattern with {} where the frame number goes",
            ],
            vec!["byte offset", "invalid option"],
        ),
        // A sequence written as a directory, a `#` pattern or a glob: the `{}` pattern.
        (
            vec!["reconstruct", &folder, "-o", "o_{}.ply"],
            2,
            vec!["frames.xyz", "a sequence is one pattern with {}"],
            vec!["os error"],
        ),
        (
            vec!["reconstruct", &hashed, "-o", &out],
            1,
            vec!["f_#.xyz", "no such file", "e.g. \"", "seq/f_{}.xyz\""],
            vec!["os error", "invalid option"],
        ),
        (
            vec!["reconstruct", sphere, &junk, "-o", &out],
            2,
            vec![
                "junk.xyz",
                "did the shell expand a glob",
                "quoted pattern with {}",
            ],
            vec![],
        ),
        // Every missing frame of a range is named.
        (
            vec![
                "reconstruct",
                &seq,
                "--start",
                "1",
                "--end",
                "4",
                "-o",
                "o_{}.ply",
            ],
            1,
            vec!["3 frames of the range 1..=4 are missing: 2-4"],
            vec!["invalid option"],
        ),
        // An input error prints no (empty) stage table before the message.
        (
            vec!["reconstruct", &junk, "-o", &out],
            1,
            vec!["junk.xyz", "looks like text"],
            vec![
                "invalid option",
                "--particle-radius",
                "--input-format",
                "time [ms]",
            ],
        ),
        (
            vec!["reconstruct", &huge, "-r", "0.025", "-o", &out],
            1,
            vec!["huge.ply", "claims 18446744073709551615 rows"],
            vec!["free space", "invalid option"],
        ),
        // A radius far too small for the coordinates blames the radius, not --cell-size
        // (when the radius check is off).
        (
            vec![
                "reconstruct",
                sphere,
                "-r",
                "1e-9",
                "--no-radius-check",
                "-o",
                &out,
            ],
            1,
            vec!["sphere.xyz", "the particle radius is too small"],
            vec!["--cell-size", "invalid option"],
        ),
        (
            vec!["reconstruct", sphere, "--attributes", "nosuch", "-o", &out],
            1,
            vec!["sphere.xyz", "\"nosuch\""],
            vec!["invalid option"],
        ),
        // Re-running into an archive: the frames it holds, and a hint, not blame.
        (
            vec!["reconstruct", sphere, "-o", &archive],
            1,
            vec![
                "run.mseq: already holds frame 0",
                "hint: --skip-existing skips",
            ],
            vec!["invalid option"],
        ),
        (
            vec!["archive", "verify", &damaged],
            1,
            vec!["damaged.mseq", "damaged", "meniscus archive repair"],
            vec!["invalid option"],
        ),
        (
            vec!["archive", "info", &nan],
            1,
            vec![
                "nan.mseq",
                "quantization step NaN",
                "meniscus archive repair",
            ],
            vec!["error bound NaN"],
        ),
        // An unknown output extension is a usage error here too, before any reading.
        (
            vec!["archive", "extract", &damaged, "-o", "x_{}.foo"],
            2,
            vec!["x_{}.foo", "unknown output extension", ".usdc"],
            vec![],
        ),
        (
            vec!["archive", "extract", &archive, "--frame", "6", "-o", &out],
            1,
            vec!["frame 6", "it holds 1 frame(s): 0"],
            vec![],
        ),
        (
            vec![
                "archive",
                "pack",
                &meshes,
                "-o",
                &packed,
                "--error-bound",
                "1e-4",
                "--start",
                "1",
                "--end",
                "1",
            ],
            1,
            vec!["mesh_1.ply", "frame 1 of the range 1..=1 is missing"],
            vec!["invalid option"],
        ),
        // The old option name still runs.
        (
            vec![
                "archive",
                "pack",
                &meshes,
                "-o",
                &packed,
                "--error-bound-world",
                "1e-4",
            ],
            1,
            vec!["mesh_{}.ply", "no file", "matches"],
            vec!["invalid option"],
        ),
        // Options: exit 2, naming the option given.
        (
            vec!["reconstruct", sphere, "-r", "0", "-o", &out],
            2,
            vec!["--particle-radius", "must be a finite number > 0, got 0"],
            vec!["--cell-size", "--influence-radius"],
        ),
        // A negative radius is a bad value, not a stray argument.
        (
            vec!["reconstruct", sphere, "-r", "-1", "-o", &out],
            2,
            vec!["--particle-radius: must be a finite number > 0"],
            vec!["-- -1", "unexpected argument"],
        ),
        // A radius far from the one the spacing implies (0.0248 for the sphere, r = 0.025)
        // is refused before any work with the library's message, naming both values,
        // what the run would do and the flag that forces it: 100x too large would run for
        // minutes, 1e-9 would fail deep in the lattice.
        (
            vec!["reconstruct", sphere, "-r", "2.5", "-o", &out],
            2,
            vec![
                "sphere.xyz: a particle radius of 2.5 is refused: it is 100.",
                "the 0.0248",
                "r is half the rest spacing",
                "one blob",
                "give about 0.0248",
                "or --no-radius-check to run with 2.5 anyway",
            ],
            vec!["--cell-size", "warning", "radius_check"],
        ),
        (
            vec!["reconstruct", sphere, "-r", "1e-9", "-o", &out],
            2,
            vec![
                "a particle radius of 1e-9 is refused: it is 4.02e-8 × the 0.0248",
                "100% of the fluid's particles would have no neighbour within the kernel's reach (4 r)",
                "--no-radius-check",
            ],
            vec!["--cell-size", "lattice"],
        ),
        // Outside 0.5x-2x: a warning, and the run goes on.
        (
            vec!["reconstruct", sphere, "-r", "0.06", "-q", "-o", &out],
            0,
            vec![
                "warning: ",
                "sphere.xyz: a particle radius of 0.06 is 2.41 × the 0.0248",
                "the particles' spacing implies",
                "(--no-radius-check silences this)",
            ],
            vec!["error"],
        ),
        (
            vec![
                "reconstruct",
                sphere,
                "-r",
                "0.2",
                "--no-radius-check",
                "-q",
                "-o",
                &out,
            ],
            0,
            vec![],
            vec!["warning", "error"],
        ),
        // Cells too small for the influence radius: the pair is named, either may be set.
        (
            vec!["reconstruct", sphere, "-c", "0.05", "-o", &out],
            2,
            vec!["--influence-radius/--cell-size", "64 cells of 0.05 r"],
            vec![],
        ),
        // An unknown output extension fails before any work and lists .mseq.
        (
            vec!["reconstruct", sphere, "-o", &foo],
            2,
            vec!["s.foo", "unknown output extension", ".mseq"],
            vec!["invalid option"],
        ),
        (
            vec!["reconstruct", sphere, "--decimate", "2", "-o", &out],
            2,
            vec!["--decimate", "fraction", "\"2\""],
            vec!["--decimate-error"],
        ),
        (
            vec!["reconstruct", sphere, "--memory-budget", "2g", "-o", &out],
            2,
            vec![
                "--memory-budget",
                "\"2g\" is ambiguous: write 2GiB (2^30 bytes) or 2GB (10^9 bytes)",
            ],
            vec!["--tile-size"],
        ),
        (
            vec![
                "reconstruct",
                sphere,
                "--memory-budget",
                "2 parsecs",
                "-o",
                &out,
            ],
            2,
            vec!["--memory-budget", "unknown size unit \"parsecs\""],
            vec!["--tile-size"],
        ),
        // Anisotropic kernels: a stretch below 1, and kernels reaching too many cells.
        (
            vec![
                "reconstruct",
                sphere,
                "--kernel",
                "anisotropic",
                "--max-stretch",
                "0.5",
                "-o",
                &out,
            ],
            2,
            vec!["--max-stretch", "between 1 and 16, got 0.5"],
            vec!["--kernel-radius", "anisotropy."],
        ),
        (
            vec![
                "reconstruct",
                sphere,
                "--kernel",
                "anisotropic",
                "--kernel-radius",
                "60",
                "-o",
                &out,
            ],
            2,
            vec!["--kernel-radius/--cell-size", "more than 64 cells"],
            vec!["--influence-radius", "anisotropy."],
        ),
        (
            vec!["reconstruct", sphere, "--threads", "0", "-o", &out],
            2,
            vec!["--threads", "at least 1"],
            vec![],
        ),
        (
            vec![
                "reconstruct",
                sphere,
                "--attributes",
                "velocity,",
                "-o",
                &out,
            ],
            2,
            vec!["--attributes", "empty name"],
            vec![],
        ),
        (
            vec!["reconstruct", sphere, "--fps", "0", "-o", &out],
            2,
            vec!["--fps", "got 0"],
            vec![],
        ),
        (
            vec!["reconstruct", &seq, "-o", "o_{}.mseq"],
            2,
            vec!["o_{}.mseq", "one .mseq archive holds the whole sequence"],
            vec![],
        ),
        // Options without effect: a warning naming the option and why; the run goes on.
        (
            vec![
                "reconstruct",
                sphere,
                "-q",
                "--error-bound",
                "1e-4",
                "--attribute-error-bound",
                "0.01",
                "--fps",
                "30",
                "--usd-droplets",
                "instancer",
                "-o",
                &out,
            ],
            0,
            vec![
                "warning: --error-bound has no effect",
                "warning: --attribute-error-bound has no effect",
                "warning: --fps has no effect",
                "warning: --usd-droplets has no effect",
                "s.ply",
            ],
            vec!["error:"],
        ),
        (
            vec![
                "reconstruct",
                &seq,
                "-q",
                "--fps",
                "10",
                "--skip-existing",
                "-o",
                &anim,
            ],
            0,
            vec![
                "warning: --fps has no effect: \"",
                "anim.glb\" holds a single frame",
                "warning: --skip-existing has no effect",
                "written whole",
            ],
            vec!["error:"],
        ),
        (
            vec!["reconstruct", sphere, "-q", "--no-normals", "-o", &fresh],
            0,
            vec!["warning: --no-normals has no effect", "fresh.mseq"],
            vec!["error:"],
        ),
        (
            vec![
                "reconstruct",
                sphere,
                "-q",
                "--normal-smoothing",
                "2",
                "--paper",
                "--smooth-method",
                "laplacian",
                "-o",
                &fresh3,
            ],
            0,
            vec![
                "warning: --normal-smoothing has no effect",
                "fresh3.mseq",
                "warning: --smooth-method has no effect: smoothing is off",
            ],
            vec!["error:"],
        ),
        (
            vec!["reconstruct", sphere, "-q", "--keep-going", "-o", &out],
            0,
            vec!["warning: --keep-going has no effect: a single file"],
            vec!["error:"],
        ),
        (
            vec![
                "reconstruct",
                sphere,
                "-q",
                "--attributes",
                "all",
                "--attribute-error-bound",
                "0.01",
                "-o",
                &fresh2,
            ],
            0,
            vec![
                "warning: --attributes all has no effect: raw .xyz",
                "warning: --attribute-error-bound has no effect: raw .xyz",
            ],
            vec!["error:"],
        ),
        // Options that do take effect draw no warning.
        (
            vec![
                "reconstruct",
                sphere,
                "-q",
                "--error-bound",
                "0.00025",
                "--skip-existing",
                "-o",
                &archive,
            ],
            0,
            vec![],
            vec!["warning", "error:"],
        ),
        // A negative iso offset is allowed.
        (
            vec![
                "reconstruct",
                sphere,
                "--iso-offset",
                "-0.1",
                "-q",
                "-o",
                &out,
            ],
            0,
            vec![],
            vec!["error", "warning"],
        ),
    ];
    for (args, code, wanted, unwanted) in cases {
        let mut command = meniscus();
        command.args(&args);
        if args[0] == "reconstruct" && !args.contains(&"-r") {
            command.args(r);
        }
        let result = command.output().unwrap();
        let err = String::from_utf8_lossy(&result.stderr);
        assert_eq!(result.status.code(), Some(code), "{args:?}: {err}");
        for w in wanted {
            assert!(err.contains(w), "{args:?}: wanted {w:?} in {err}");
        }
        for u in unwanted {
            assert!(!err.contains(u), "{args:?}: unwanted {u:?} in {err}");
        }
        if code != 0 {
            assert!(
                !Path::new(&out).exists()
                    && !Path::new(&foo).exists()
                    && !Path::new(&packed).exists(),
                "{args:?}: no output on failure"
            );
        } else if Path::new(&out).exists() {
            std::fs::remove_file(&out).unwrap();
        }
    }
    // The run that skipped frame 0 left the archive as it was, and whole.
    let out = meniscus()
        .args(["archive", "verify", &archive])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    // The help says how sizes are read.
    let help = meniscus().args(["reconstruct", "--help"]).output().unwrap();
    let help = String::from_utf8_lossy(&help.stdout);
    assert!(
        help.contains("ambiguous") && help.contains("powers of 10"),
        "{help}"
    );
}

/// A second run over an archive's frames is refused before the archive is touched; with
/// --skip-existing those frames are skipped and the new ones appended.
#[test]
fn rerunning_into_an_archive_names_its_frames_and_leaves_it_intact() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("seq")).unwrap();
    let sphere = dataset("analytic/sphere.xyz");
    for k in [1, 2, 3] {
        std::fs::copy(&sphere, dir.path().join(format!("seq/f_{k}.xyz"))).unwrap();
    }
    let input = format!("{}/seq/f_{{}}.xyz", dir.path().display());
    let archive = dir.path().join("run.mseq");
    let a = archive.to_str().unwrap();
    let reconstruct = |extra: &[&str]| {
        let out = meniscus()
            .args(["reconstruct", &input, "-r", "0.025", "-o", a])
            .args(extra)
            .output()
            .unwrap();
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let (code, err) = reconstruct(&["-q", "--end", "2"]);
    assert_eq!(code, Some(0), "{err}");
    let before = std::fs::read(&archive).unwrap();
    let (code, err) = reconstruct(&["-q"]);
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains("run.mseq: already holds frames 1 and 2 (2 of the 3 frames of this run)"),
        "{err}"
    );
    assert!(err.contains("hint: --skip-existing"), "{err}");
    assert!(!err.contains("invalid option"), "{err}");
    assert_eq!(
        std::fs::read(&archive).unwrap(),
        before,
        "archive untouched"
    );
    // The default bound (0.01 r) in world units, given explicitly, appends.
    let (code, err) = reconstruct(&["--skip-existing", "--error-bound", "0.00025"]);
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains("1 frame(s) reconstructed, 2 skipped"), "{err}");
    let info = meniscus().args(["archive", "info", a]).output().unwrap();
    let info = String::from_utf8_lossy(&info.stdout);
    assert!(
        info.contains("3 frames") && info.contains("error bound 0.00025 (world units)"),
        "{info}"
    );
    // Another bound is refused, in world units.
    std::fs::remove_file(dir.path().join("seq/f_3.xyz")).unwrap();
    std::fs::copy(&sphere, dir.path().join("seq/f_4.xyz")).unwrap();
    let (code, err) = reconstruct(&["-q", "--skip-existing", "--error-bound", "0.001"]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("0.001") && err.contains("0.00025"), "{err}");
}

#[test]
fn a_failed_run_leaves_no_empty_archive() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("frame_1.xyz");
    std::fs::write(&input, [0u8; 13]).unwrap();
    let archive = dir.path().join("run.mseq");
    let output = meniscus()
        .args([
            "reconstruct",
            input.to_str().unwrap(),
            "-r",
            "0.025",
            "-q",
            "-o",
        ])
        .arg(&archive)
        .output()
        .unwrap();
    assert!(!output.status.success());
    assert!(
        String::from_utf8_lossy(&output.stderr).contains("multiple of 12"),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(!archive.exists(), "no archive is left behind");
}

/// Writes frame `k` of a small mesh sequence as OBJ text.
fn write_obj(path: &Path, k: i64) {
    let m = meniscus::isolated::icosphere(1, 1.0 + 0.1 * k as f32);
    let mut text = String::new();
    for p in &m.positions {
        text.push_str(&format!("v {} {} {}\n", p.x + k as f32, p.y, p.z));
    }
    for t in &m.triangles {
        text.push_str(&format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1));
    }
    std::fs::write(path, text).unwrap();
}

/// Opens the archive, checks that it verifies clean through its index and holds exactly
/// `numbers`, and decodes it.
fn clean_archive(path: &Path, numbers: &[i64]) -> Decoded {
    let r = meniscus::archive::ArchiveReader::open(path).unwrap();
    let v = r.verify();
    assert!(v.is_clean() && !r.recovered_by_scan(), "{v:?}");
    assert_eq!(v.good, numbers);
    decoded(path)
}

/// Makes a mesh file unreadable.
type Damage = fn(&Path);

/// `archive pack` over five meshes whose 3rd is corrupt or missing fails naming it, and
/// leaves the archive (new or existing) clean, with every frame packed before the failure
/// and the earlier frames unchanged.
#[test]
fn a_failed_pack_leaves_a_clean_archive_with_every_complete_frame() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pack = |pattern: &str, archive: &Path| {
        let out = meniscus()
            .args(["archive", "pack", pattern, "--error-bound", "0.001", "-o"])
            .arg(archive)
            .output()
            .unwrap();
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    // An archive that exists already, with frames 10 and 11.
    std::fs::create_dir(d.join("old")).unwrap();
    for k in [10, 11] {
        write_obj(&d.join(format!("old/g_{k}.obj")), k);
    }
    let existing = d.join("existing.mseq");
    let (code, err) = pack(&format!("{}/old/g_{{}}.obj", d.display()), &existing);
    assert_eq!(code, Some(0), "{err}");
    let old_frames = clean_archive(&existing, &[10, 11]);
    let old_bytes = std::fs::read(&existing).unwrap();
    let n = old_bytes.len();
    let old_index = u64::from_le_bytes(old_bytes[n - 16..n - 8].try_into().unwrap()) as usize;
    // What frames 1 and 2 pack to.
    std::fs::create_dir(d.join("two")).unwrap();
    for k in [1, 2] {
        write_obj(&d.join(format!("two/f_{k}.obj")), k);
    }
    let reference = d.join("reference.mseq");
    let (code, err) = pack(&format!("{}/two/f_{{}}.obj", d.display()), &reference);
    assert_eq!(code, Some(0), "{err}");
    let reference_frames = clean_archive(&reference, &[1, 2]);

    let cases: &[(&str, Damage)] = &[
        ("corrupt", |p| {
            std::fs::write(p, "v 1 x 3\nf 1 2 3\n").unwrap()
        }),
        #[cfg(unix)]
        ("missing", |p| {
            // Listed by the pattern, gone when read.
            std::os::unix::fs::symlink(p.with_extension("gone"), p).unwrap()
        }),
    ];
    for (what, damage) in cases {
        let seq = d.join(what);
        std::fs::create_dir(&seq).unwrap();
        for k in [1, 2, 4, 5] {
            write_obj(&seq.join(format!("f_{k}.obj")), k);
        }
        let third = seq.join("f_3.obj");
        damage(&third);
        let pattern = format!("{}/f_{{}}.obj", seq.display());

        // Into a new archive.
        let archive = d.join(format!("{what}-new.mseq"));
        let (code, err) = pack(&pattern, &archive);
        assert_eq!(code, Some(1), "{what}: {err}");
        assert!(err.contains("f_3.obj"), "{what}: names the file: {err}");
        let frames = clean_archive(&archive, &[1, 2]);
        assert_eq!(frames, reference_frames, "{what}");
        assert_eq!(
            std::fs::read(&archive).unwrap(),
            std::fs::read(&reference).unwrap(),
            "{what}: the archive a pack of frames 1 and 2 writes"
        );
        let verify = meniscus()
            .args(["archive", "verify"])
            .arg(&archive)
            .output();
        assert!(verify.unwrap().status.success(), "{what}: archive verify");

        // Into an existing archive.
        let archive = d.join(format!("{what}-existing.mseq"));
        std::fs::copy(&existing, &archive).unwrap();
        let (code, err) = pack(&pattern, &archive);
        assert_eq!(code, Some(1), "{what}: {err}");
        assert!(err.contains("f_3.obj"), "{what}: names the file: {err}");
        let frames = clean_archive(&archive, &[10, 11, 1, 2]);
        assert_eq!(frames[..2], old_frames[..], "{what}: earlier frames");
        assert_eq!(frames[2..], reference_frames[..], "{what}: appended frames");
        let bytes = std::fs::read(&archive).unwrap();
        assert_eq!(bytes[..old_index], old_bytes[..old_index], "{what}");

        // A new archive whose first mesh fails is not left behind.
        let first = d.join(format!("{what}-first"));
        std::fs::create_dir(&first).unwrap();
        damage(&first.join("f_3.obj"));
        write_obj(&first.join("f_4.obj"), 4);
        let archive = d.join(format!("{what}-first.mseq"));
        let (code, err) = pack(&format!("{}/f_{{}}.obj", first.display()), &archive);
        assert_eq!(code, Some(1), "{what}: {err}");
        assert!(!archive.exists(), "{what}: no archive without a frame");
    }
}

/// `reconstruct -o run.mseq` whose 3rd frame fails leaves the archive clean with the
/// frames before it; the re-run with --skip-existing continues after them.
#[test]
fn a_failed_reconstruct_into_an_archive_keeps_the_frames_before() {
    let dir = tempfile::tempdir().unwrap();
    let sphere = dataset("analytic/sphere.xyz");
    for k in [1, 2, 3, 4] {
        std::fs::copy(&sphere, dir.path().join(format!("f_{k}.xyz"))).unwrap();
    }
    std::fs::write(dir.path().join("f_3.xyz"), [0u8; 13]).unwrap();
    let input = format!("{}/f_{{}}.xyz", dir.path().display());
    let archive = dir.path().join("run.mseq");
    let reconstruct = |extra: &[&str]| {
        let out = meniscus()
            .args(["reconstruct", &input, "-r", "0.025", "-q", "-o"])
            .arg(&archive)
            .args(extra)
            .output()
            .unwrap();
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let (code, err) = reconstruct(&[]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("f_3.xyz"), "{err}");
    let before = clean_archive(&archive, &[1, 2]);
    std::fs::copy(&sphere, dir.path().join("f_3.xyz")).unwrap();
    let (code, err) = reconstruct(&["--skip-existing"]);
    assert_eq!(code, Some(0), "{err}");
    let after = clean_archive(&archive, &[1, 2, 3, 4]);
    assert_eq!(after[..2], before[..]);
    // Every frame held: nothing is opened for writing, so another error bound does not
    // matter and the archive is untouched.
    let bytes = std::fs::read(&archive).unwrap();
    let (code, err) = reconstruct(&["--skip-existing", "--error-bound", "0.001"]);
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(std::fs::read(&archive).unwrap(), bytes, "untouched");
    // With a frame to write, the bound is compared and refused.
    std::fs::copy(&sphere, dir.path().join("f_5.xyz")).unwrap();
    let (code, err) = reconstruct(&["--skip-existing", "--error-bound", "0.001"]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("0.001") && err.contains("0.00025"), "{err}");
    assert_eq!(std::fs::read(&archive).unwrap(), bytes, "untouched");
}

/// Runs `meniscus` and returns its exit code, stdout and stderr.
fn run_full(args: &[&str]) -> (Option<i32>, String, String) {
    let out = meniscus().args(args).output().unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The `--json-progress` lines of stdout, parsed.
fn progress_lines(stdout: &str) -> Vec<serde_json::Value> {
    stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{l:?}: {e}")))
        .collect()
}

/// A 3-frame sequence (1, 6, 13) whose frame 6 is a truncated file.
fn sequence_with_a_broken_frame(dir: &Path) -> String {
    let pattern = sequence_in(dir, false);
    std::fs::write(dir.join("f_6.xyz"), [0u8; 10]).unwrap();
    pattern
}

#[test]
fn keep_going_reports_a_broken_frame_as_json_and_writes_the_others() {
    let dir = tempfile::tempdir().unwrap();
    let pattern = sequence_with_a_broken_frame(dir.path());
    let out = dir.path().join("out");
    let (code, stdout, stderr) = run_full(&[
        "reconstruct",
        &pattern,
        "-r",
        "0.025",
        "-o",
        &format!("{}/s_{{}}.ply", out.display()),
        "--json-progress",
        "--keep-going",
        "--threads",
        "2",
    ]);
    assert_eq!(code, Some(1), "a failed frame makes the run fail: {stderr}");
    let lines = progress_lines(&stdout);
    let status: Vec<&str> = lines
        .iter()
        .map(|l| l["status"].as_str().unwrap())
        .collect();
    assert_eq!(status, ["done", "failed", "done"], "{stdout}");
    let frames: Vec<i64> = lines.iter().map(|l| l["frame"].as_i64().unwrap()).collect();
    assert_eq!(frames, [1, 6, 13]);
    for line in [&lines[0], &lines[2]] {
        assert!(line["triangles"].as_u64().unwrap() > 1000, "{line}");
        assert!(line["seconds"].as_f64().unwrap() > 0.0, "{line}");
        assert!(line["peak_rss_bytes"].as_u64().unwrap() > 0, "{line}");
        assert!(line.get("error").is_none(), "{line}");
        assert!(line["output"].as_str().unwrap().ends_with(".ply"), "{line}");
    }
    let failed = &lines[1];
    assert!(failed["input"].as_str().unwrap().ends_with("f_6.xyz"));
    let error = failed["error"].as_str().unwrap();
    assert!(
        error.contains("f_6.xyz") && error.contains("not a multiple of 12"),
        "{error}"
    );
    assert!(failed["triangles"].is_null());
    assert_eq!(names_in(&out), ["s_1.ply", "s_13.ply"]);
    assert!(
        stderr.contains("1 of 3 frames failed (frame 6)"),
        "{stderr}"
    );
    assert!(!stderr.contains("--"), "names no flag: {stderr}");
}

#[test]
fn a_failed_frame_is_not_appended_and_the_archive_stays_whole() {
    let dir = tempfile::tempdir().unwrap();
    let pattern = sequence_with_a_broken_frame(dir.path());
    let list = |archive: &Path| -> Vec<i64> {
        meniscus::archive::ArchiveReader::open(archive)
            .unwrap()
            .frames()
            .iter()
            .map(|f| f.number)
            .collect()
    };
    let clean = |archive: &Path| {
        let r = meniscus::archive::ArchiveReader::open(archive).unwrap();
        assert!(!r.recovered_by_scan(), "finished with its index");
        assert!(r.verify().is_clean());
    };
    // --keep-going: frames 1 and 13.
    let kept = dir.path().join("kept.mseq");
    let (code, stdout, stderr) = run_full(&[
        "reconstruct",
        &pattern,
        "-r",
        "0.025",
        "-o",
        kept.to_str().unwrap(),
        "--json-progress",
        "--keep-going",
        "-q",
    ]);
    assert_eq!(code, Some(1), "{stderr}");
    assert_eq!(progress_lines(&stdout).len(), 3);
    assert_eq!(list(&kept), [1, 13]);
    clean(&kept);
    // Default: the run stops at frame 6, with frame 1 archived and the failure reported.
    let stopped = dir.path().join("stopped.mseq");
    let (code, stdout, stderr) = run_full(&[
        "reconstruct",
        &pattern,
        "-r",
        "0.025",
        "-o",
        stopped.to_str().unwrap(),
        "--json-progress",
        "-q",
    ]);
    assert_eq!(code, Some(1), "{stderr}");
    let lines = progress_lines(&stdout);
    let status: Vec<&str> = lines
        .iter()
        .map(|l| l["status"].as_str().unwrap())
        .collect();
    assert_eq!(status, ["done", "failed"], "stops at the failure: {stdout}");
    assert!(stderr.contains("f_6.xyz"), "{stderr}");
    assert_eq!(list(&stopped), [1]);
    clean(&stopped);
    // Frame 6 repaired: a re-run with --skip-existing fills the gap; skipped frames are
    // reported as such.
    std::fs::copy(
        dataset("double_dambreak/ParticleData_Fluid_6.xyz"),
        dir.path().join("f_6.xyz"),
    )
    .unwrap();
    let (code, stdout, stderr) = run_full(&[
        "reconstruct",
        &pattern,
        "-r",
        "0.025",
        "-o",
        kept.to_str().unwrap(),
        "--json-progress",
        "--skip-existing",
        "-q",
    ]);
    assert_eq!(code, Some(0), "{stderr}");
    let lines = progress_lines(&stdout);
    let status: Vec<&str> = lines
        .iter()
        .map(|l| l["status"].as_str().unwrap())
        .collect();
    assert_eq!(status, ["skipped", "done", "skipped"]);
    assert_eq!(list(&kept), [1, 13, 6]);
    clean(&kept);
}

#[test]
fn frames_and_shards_on_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let pattern = sequence_in(dir.path(), true);
    let out = |name: &str| format!("{}/{name}/s_{{}}.ply", dir.path().display());
    let base = |output: &str| {
        vec![
            "reconstruct".to_string(),
            pattern.clone(),
            "-r".into(),
            "0.025".into(),
            "-o".into(),
            output.to_string(),
            "-q".into(),
        ]
    };
    let go = |extra: &[&str], output: &str| {
        let mut args = base(output);
        args.extend(extra.iter().map(|s| s.to_string()));
        let args: Vec<&str> = args.iter().map(|s| s.as_str()).collect();
        run_full(&args)
    };
    // A stepped range; padded names (`f_013.xyz`) are found.
    let (code, _, stderr) = go(&["--frames", "1-13:12"], &out("a"));
    assert_eq!(code, Some(0), "{stderr}");
    assert_eq!(names_in(&dir.path().join("a")), ["s_001.ply", "s_013.ply"]);
    // Shards: round-robin over the frames.
    for (shard, expected) in [
        ("0/2", vec!["s_001.ply", "s_013.ply"]),
        ("1/2", vec!["s_006.ply"]),
    ] {
        let name = format!("shard{}", &shard[..1]);
        let (code, _, stderr) = go(&["--shard", shard], &out(&name));
        assert_eq!(code, Some(0), "{stderr}");
        assert_eq!(names_in(&dir.path().join(&name)), expected);
    }
    // Usage errors (exit 2), naming the bad text; missing frames are an error (exit 1).
    for (extra, says) in [
        (
            &["--frames", "1-13", "--start", "1"][..],
            "cannot be used with",
        ),
        (&["--frames", "13-1"][..], "\"13-1\": the range is reversed"),
        (&["--frames", "1,x"][..], "\"x\" is not a frame number"),
        (&["--shard", "2/2"][..], "shard 2 does not exist"),
        (&["--shard", "3/4"][..], "shard 3/4 of 3 frames is empty"),
    ] {
        let (code, _, stderr) = go(extra, &out("bad"));
        assert_eq!(code, Some(2), "{extra:?}: {stderr}");
        assert!(stderr.contains(says), "{extra:?}: {stderr}");
    }
    let (code, _, stderr) = go(&["--frames", "1-6"], &out("bad"));
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains("no file for 4 of the 6 selected frames: 2, 3, 4, 5"),
        "{stderr}"
    );
    assert!(!dir.path().join("bad").exists());
}

#[test]
fn shards_merged_are_byte_identical_to_one_run() {
    let dir = tempfile::tempdir().unwrap();
    let pattern = dataset("dambreak_small/ParticleData_Fluid_{}.xyz");
    let pattern = pattern.to_str().unwrap();
    let p = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    let reconstruct = |output: &str, extra: &[&str]| {
        let mut args = vec![
            "reconstruct",
            pattern,
            "-r",
            "0.012",
            "-o",
            output,
            "--frames",
            "1-25:8",
            "-q",
        ];
        args.extend(extra);
        let (code, _, stderr) = run_full(&args);
        assert_eq!(code, Some(0), "{args:?}: {stderr}");
    };
    reconstruct(&p("one.mseq"), &["--threads", "1"]);
    reconstruct(&p("shard0.mseq"), &["--shard", "0/2", "--threads", "2"]);
    reconstruct(&p("shard1.mseq"), &["--shard", "1/2", "--threads", "2"]);
    let frames = |path: &str| -> Vec<i64> {
        meniscus::archive::ArchiveReader::open(Path::new(path))
            .unwrap()
            .frames()
            .iter()
            .map(|f| f.number)
            .collect()
    };
    assert_eq!(frames(&p("one.mseq")), [1, 9, 17, 25]);
    assert_eq!(frames(&p("shard0.mseq")), [1, 17]);
    assert_eq!(frames(&p("shard1.mseq")), [9, 25]);
    let (code, _, stderr) = run_full(&[
        "archive",
        "merge",
        &p("shard1.mseq"),
        &p("shard0.mseq"),
        "-o",
        &p("all.mseq"),
    ]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        stderr.contains("4 frame(s) from 2 archive(s) merged"),
        "{stderr}"
    );
    assert!(
        std::fs::read(p("all.mseq")).unwrap() == std::fs::read(p("one.mseq")).unwrap(),
        "the merged shards are the bytes of the single run"
    );
    // A frame in two inputs: exit 1, both files named, no output.
    let (code, _, stderr) = run_full(&[
        "archive",
        "merge",
        &p("shard0.mseq"),
        &p("one.mseq"),
        "-o",
        &p("twice.mseq"),
    ]);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains("one.mseq: frame 1: also in") && stderr.contains("shard0.mseq"),
        "{stderr}"
    );
    assert!(!dir.path().join("twice.mseq").exists());
}

/// `--paper` is the paper's pipeline flag by flag, and a flag given beside it wins.
#[test]
fn the_paper_flag_is_the_papers_options() {
    let dir = tempfile::tempdir().unwrap();
    let input = dataset("double_dambreak/ParticleData_Fluid_6.xyz");
    let mesh = |name: &str, flags: &[&str]| {
        let out = dir.path().join(name);
        let (ok, err) = reconstruct(&input, "0.025", &out, flags);
        assert!(ok, "{flags:?}: {err}");
        std::fs::read(out).unwrap()
    };
    let paper = mesh("paper.ply", &["--paper"]);
    let flags = mesh(
        "flags.ply",
        &[
            "--kernel",
            "isotropic",
            "--particle-coverage",
            "0",
            "--decimate",
            "0.8",
            "--decimate-error",
            "off",
            "--smooth",
            "0",
            "--keep-inside",
            "off",
        ],
    );
    assert!(paper == flags, "--paper differs from its flags");
    // Smoothing is one of them: the paper's pipeline with it differs.
    assert!(mesh("smoothed.ply", &["--paper", "--smooth", "2"]) != paper);
    assert!(mesh("default.ply", &[]) != paper);
    let anisotropic = mesh("aniso.ply", &["--paper", "--kernel", "anisotropic"]);
    assert!(anisotropic != paper);
    let (ok, err) = run(&[
        "reconstruct",
        input.to_str().unwrap(),
        "-r",
        "0.025",
        "-o",
        dir.path().join("bad.ply").to_str().unwrap(),
        "--decimate-error",
        "most",
    ]);
    assert!(
        !ok && err.contains("--decimate-error") && err.contains("\"most\""),
        "{err}"
    );
}

/// A sequence (a `{}` pattern, whatever frames of it are chosen) takes the steady preset,
/// one file the still one; `--preset steady` is its flags, and a flag given beside it
/// wins.
#[test]
fn a_sequence_takes_the_steady_preset() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let pattern = dataset("dambreak_small/ParticleData_Fluid_{}.xyz");
    let one = dataset("dambreak_small/ParticleData_Fluid_25.xyz");
    let run_ok = |input: &std::path::Path, output: &str, flags: &[&str]| {
        let mut args = vec![
            "reconstruct",
            input.to_str().unwrap(),
            "-r",
            "0.012",
            "-o",
            output,
            "--quiet",
        ];
        args.extend_from_slice(flags);
        let (ok, err) = run(&args);
        assert!(ok, "{flags:?}: {err}");
    };
    run_ok(&pattern, &p("seq_{}.ply"), &["--frames", "25"]);
    run_ok(&one, &p("steady.ply"), &["--preset", "steady"]);
    run_ok(&one, &p("still.ply"), &[]);
    run_ok(
        &pattern,
        &p("still_{}.ply"),
        &["--frames", "25", "--preset", "still"],
    );
    let flags = [
        "-c",
        "0.71",
        "--iso-offset",
        "-0.05",
        "--decimate",
        "off",
        "--smooth",
        "10",
        "--smooth-method",
        "laplacian",
        "--smooth-max-inward",
        "0.2",
        "--smooth-feature-angle",
        "7",
        "--subdivide",
        "0",
        "--normal-smoothing",
        "3",
    ];
    run_ok(&one, &p("flags.ply"), &flags);
    run_ok(&one, &p("coarse.ply"), &["--preset", "steady", "-c", "1"]);
    let read = |name: &str| std::fs::read(p(name)).unwrap();
    let steady = read("steady.ply");
    assert!(
        read("seq_25.ply") == steady,
        "a sequence's frame is the steady surface"
    );
    assert!(read("flags.ply") == steady, "--preset steady is its flags");
    assert!(read("still.ply") != steady && read("still_25.ply") == read("still.ply"));
    assert!(read("coarse.ply") != steady, "-c beside --preset wins");
    // A preset that does not exist, and two presets at once: usage errors, nothing written.
    for flags in [
        &["--preset", "smooth"][..],
        &["--preset", "steady", "--paper"],
    ] {
        let mut args = vec!["reconstruct", one.to_str().unwrap(), "-r", "0.012"];
        let out = p("bad.ply");
        args.extend_from_slice(&["-o", &out]);
        args.extend_from_slice(flags);
        let (code, _, stderr) = run_full(&args);
        assert_eq!(code, Some(2), "{flags:?}: {stderr}");
    }
    assert!(!dir.path().join("bad.ply").exists());
}

/// Centres containment could not bring under the surface (unbounded decimation folds a
/// violent splash's sheets) draw a warning, exactly when the statistics count some.
#[test]
fn centres_left_shallow_are_warned_about() {
    let dir = tempfile::tempdir().unwrap();
    let mut positions = meniscus::io::particles::read_particles(
        &dataset("dambreak_small/ParticleData_Fluid_1.xyz"),
        None,
    )
    .unwrap()
    .positions;
    splash::splash(&mut positions);
    let input = dir.path().join("splash.xyz");
    let bytes: Vec<u8> = positions
        .iter()
        .flat_map(|p| p.to_array())
        .flat_map(f32::to_le_bytes)
        .collect();
    std::fs::write(&input, bytes).unwrap();
    let mut warned_once = false;
    for bound in ["0.1", "off"] {
        let stats = dir.path().join("s.json");
        let (ok, err) = reconstruct(
            &input,
            "0.012",
            &dir.path().join("s.ply"),
            &[
                "--decimate",
                "0.9",
                "--decimate-error",
                bound,
                "--stats",
                stats.to_str().unwrap(),
            ],
        );
        assert!(ok, "{err}");
        let json: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
        let left = json["frames"][0]["reconstruction"]["containment"]["remaining"]
            .as_u64()
            .unwrap();
        let warned = err.contains("particle centres stay less than the keep-inside depth");
        assert_eq!(warned, left > 0, "bound {bound}: {left} left, stderr {err}");
        warned_once |= warned;
    }
    // Unbounded, this splash leaves some (so the warning is seen at all).
    assert!(warned_once);
}
