//! USD stages from `meniscus reconstruct`: one stage for a `{}` sequence (time samples at
//! the frame numbers, a gap kept), a stage per frame with `{}` in the output's name, the
//! stage options, spheres on and off, tiled runs identical to untiled, and the error
//! cases (a failed frame, `--skip-existing`, an unwritable path). The stage's content is
//! read here from the text format; `tests/usd/run.sh` reads both formats with Pixar's
//! library.

mod support;

use std::path::Path;
use support::particle_sequence::write_particle_sequence;
use support::{meniscus, names_in};

/// Runs `meniscus reconstruct PATTERN -r 0.025 -q ARGS…` and returns its exit code and
/// stderr.
fn reconstruct(pattern: &str, args: &[&str]) -> (Option<i32>, String) {
    let out = meniscus()
        .args(["reconstruct", pattern, "-r", "0.025", "-q"])
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The time codes of the samples of `property` (`point3f[] points`) in a `.usda` stage.
fn sample_times(text: &str, property: &str) -> Vec<i64> {
    let start = text
        .find(&format!("{property}.timeSamples = {{"))
        .unwrap_or_else(|| panic!("no {property} samples"));
    let block = &text[start..];
    let end = block.find("\n        }").unwrap();
    block[..end]
        .lines()
        .skip(1)
        .map(|l| {
            let (time, _) = l.trim_start().split_once(':').unwrap();
            time.parse().unwrap()
        })
        .collect()
}

/// The stage at `path`, as text.
fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn a_sequence_with_a_gap_is_one_stage_sampled_at_its_frame_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let pattern = write_particle_sequence(dir.path());
    let out = dir.path().join("shot.usda");
    let options = [
        "--attributes",
        "all",
        "--fps",
        "30",
        "--up-axis",
        "z",
        "--meters-per-unit",
        "0.01",
    ];
    let (code, err) = reconstruct(
        &pattern,
        &[&["-o", out.to_str().unwrap()], &options[..]].concat(),
    );
    assert_eq!(code, Some(0), "{err}");
    assert!(
        !err.contains("warning"),
        "no option is without effect: {err}"
    );
    let text = read(&out);
    for metadata in [
        "startTimeCode = 1.0",
        "endTimeCode = 4.0",
        "timeCodesPerSecond = 30.0",
        "framesPerSecond = 30.0",
        "upAxis = \"Z\"",
        "metersPerUnit = 0.01",
    ] {
        assert!(text.contains(metadata), "{metadata}");
    }
    // Attributes of 1 to 4 components: the velocity as `velocities`, the others primvars.
    for property in [
        "point3f[] points",
        "int[] faceVertexIndices",
        "vector3f[] velocities",
        "float[] primvars:density",
        "float2[] primvars:uv",
        "float4[] primvars:color",
    ] {
        assert_eq!(sample_times(&text, property), [1, 2, 4], "{property}");
    }
    assert!(!text.contains("primvars:velocity"));
    assert_eq!(
        names_in(dir.path()).len(),
        4,
        "the frames and the stage, nothing else"
    );
}

#[test]
fn braces_in_the_output_write_a_stage_per_frame_which_skip_existing_skips() {
    let dir = tempfile::tempdir().unwrap();
    let pattern = write_particle_sequence(dir.path());
    let out = dir.path().join("out");
    let stages = format!("{}/s_{{}}.usda", out.display());
    let (code, err) = reconstruct(&pattern, &["-o", &stages]);
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(names_in(&out), ["s_1.usda", "s_2.usda", "s_4.usda"]);
    let text = read(&out.join("s_2.usda"));
    assert_eq!(sample_times(&text, "point3f[] points"), [2]);
    assert!(text.contains("startTimeCode = 2.0") && text.contains("endTimeCode = 2.0"));
    // A stage per frame is a file per frame: one that exists is skipped.
    let kept = std::fs::read(out.join("s_1.usda")).unwrap();
    std::fs::write(out.join("s_1.usda"), "kept").unwrap();
    std::fs::remove_file(out.join("s_4.usda")).unwrap();
    let (code, err) = reconstruct(&pattern, &["-o", &stages, "--skip-existing"]);
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(read(&out.join("s_1.usda")), "kept");
    assert_eq!(names_in(&out), ["s_1.usda", "s_2.usda", "s_4.usda"]);
    assert_ne!(kept.len(), 4);
}

#[test]
fn tiled_runs_write_the_same_stage_and_droplets_are_points_an_instancer_or_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let pattern = write_particle_sequence(dir.path());
    let stage = |name: &str, args: &[&str]| {
        let out = dir.path().join(name);
        let (code, err) = reconstruct(&pattern, &[&["-o", out.to_str().unwrap()], args].concat());
        assert_eq!(code, Some(0), "{err}");
        std::fs::read(out).unwrap()
    };
    // Without decimation, smoothing and containment (whose choices depend on the tiles)
    // the surface is the same for every tiling, and so must the stage be, byte for byte.
    let raw = [
        "--decimate",
        "off",
        "--smooth",
        "0",
        "--keep-inside",
        "off",
        "--subdivide",
        "1",
    ];
    let whole = stage("whole.usdc", &raw);
    let tiled = stage("tiled.usdc", &[&raw[..], &["--tile-size", "16"]].concat());
    assert!(whole == tiled, "a tiled run writes the same stage");
    let with = String::from_utf8(stage("with.usda", &[])).unwrap();
    assert!(with.contains("def Points \"Droplets\""));
    assert!(!with.contains("PointInstancer"));
    assert!(!sample_times(&with, "float[] widths").is_empty());
    let instanced = stage("inst.usda", &["--usd-droplets", "instancer"]);
    let instanced = String::from_utf8(instanced).unwrap();
    assert!(instanced.contains("def PointInstancer \"Spheres\""));
    assert!(!sample_times(&instanced, "point3f[] positions").is_empty());
    let without = String::from_utf8(stage("without.usda", &["--isolated-spheres", "off"])).unwrap();
    assert!(!without.contains("PointInstancer") && !without.contains("def Points"));
    assert_eq!(sample_times(&without, "point3f[] points"), [1, 2, 4]);
}

#[test]
fn a_failed_frame_leaves_the_stage_with_the_frames_done() {
    let dir = tempfile::tempdir().unwrap();
    let pattern = write_particle_sequence(dir.path());
    std::fs::write(
        dir.path().join("f_2.vtk"),
        "# vtk DataFile Version 4.2\nbroken\n",
    )
    .unwrap();
    let out = dir.path().join("shot.usda");
    // Going on: frames 1 and 4.
    let (code, err) = reconstruct(&pattern, &["-o", out.to_str().unwrap(), "--keep-going"]);
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains("f_2.vtk") && err.contains("1 of 3 frames failed"),
        "{err}"
    );
    let text = read(&out);
    assert_eq!(sample_times(&text, "point3f[] points"), [1, 4]);
    assert!(text.contains("endTimeCode = 4.0"));
    // Stopping at the failure: frame 1 only.
    let (code, err) = reconstruct(&pattern, &["-o", out.to_str().unwrap()]);
    assert_eq!(code, Some(1), "{err}");
    assert_eq!(sample_times(&read(&out), "point3f[] points"), [1]);
    // No frame done: no stage written, the existing one kept.
    let (code, err) = reconstruct(&pattern, &["-o", out.to_str().unwrap(), "--frames", "2"]);
    assert_eq!(code, Some(1), "{err}");
    assert_eq!(sample_times(&read(&out), "point3f[] points"), [1]);
    assert_eq!(names_in(dir.path()).len(), 4, "no temporary file left");
}

#[test]
fn a_stage_refuses_skip_existing_and_an_unwritable_path_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let pattern = write_particle_sequence(dir.path());
    let out = dir.path().join("shot.usdc");
    let (code, err) = reconstruct(&pattern, &["-o", out.to_str().unwrap(), "--skip-existing"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("--skip-existing") && err.contains("shot.usdc") && err.contains("{}"),
        "{err}"
    );
    // A directory where the stage's folder would be; the output a directory.
    let blocker = dir.path().join("blocker");
    std::fs::write(&blocker, "a file").unwrap();
    let under_a_file = blocker.join("shot.usdc");
    let (code, err) = reconstruct(&pattern, &["-o", under_a_file.to_str().unwrap()]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("blocker"), "{err}");
    let folder = dir.path().join("folder.usdc");
    std::fs::create_dir(&folder).unwrap();
    let (code, err) = reconstruct(&pattern, &["-o", folder.to_str().unwrap()]);
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains("folder.usdc") && err.contains("directory"),
        "{err}"
    );
    assert!(names_in(&folder).is_empty());
    assert_eq!(
        names_in(dir.path()),
        ["blocker", "f_1.vtk", "f_2.vtk", "f_4.vtk", "folder.usdc"],
        "nothing written"
    );
    // Two files of one frame number.
    std::fs::copy(dir.path().join("f_2.vtk"), dir.path().join("f_02.vtk")).unwrap();
    let (code, err) = reconstruct(&pattern, &["-o", out.to_str().unwrap()]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("f_02.vtk") && err.contains("both frame 2"),
        "{err}"
    );
    assert!(!out.exists());
}

#[test]
fn an_archive_extracts_into_one_stage_or_a_stage_per_frame() {
    let dir = tempfile::tempdir().unwrap();
    let pattern = write_particle_sequence(dir.path());
    let archive = dir.path().join("run.mseq");
    let (code, err) = reconstruct(&pattern, &["-o", archive.to_str().unwrap()]);
    assert_eq!(code, Some(0), "{err}");
    let extract = |args: &[&str]| {
        let out = meniscus()
            .args(["archive", "extract", archive.to_str().unwrap()])
            .args(args)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(out.status.success(), "{err}");
        err
    };
    let shot = dir.path().join("shot.usda");
    let err = extract(&["-o", shot.to_str().unwrap(), "--up-axis", "Z"]);
    assert!(err.contains("3 frame(s) written to 1 stage(s)"), "{err}");
    let text = read(&shot);
    assert!(text.contains("upAxis = \"Z\"") && text.contains("startTimeCode = 1.0"));
    for property in ["point3f[] points", "vector3f[] velocities"] {
        assert_eq!(sample_times(&text, property), [1, 2, 4], "{property}");
    }
    let one = dir.path().join("one.usdc");
    extract(&["-o", one.to_str().unwrap(), "--frame", "2"]);
    assert!(one.exists());
    let stages = dir.path().join("stages");
    extract(&["-o", &format!("{}/s_{{}}.usda", stages.display())]);
    assert_eq!(names_in(&stages), ["s_1.usda", "s_2.usda", "s_4.usda"]);
    assert_eq!(
        sample_times(&read(&stages.join("s_4.usda")), "point3f[] points"),
        [4]
    );
}
