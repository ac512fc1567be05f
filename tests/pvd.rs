//! ParaView collections (`.pvd`) as frame sequences: the fixture in `tests/data/pvd/`
//! (three `.vtu` frames written by VTK, `make_fixtures.py`, listed out of time order)
//! reconstructs like the same files through a `{}` pattern, the frame choice works on it,
//! and broken collections are errors naming the collection and the entry's line.

mod support;

use meniscus::error::Error;
use meniscus::sequence::{choose, collection_frames, FrameChoice, Shard};
use std::path::{Path, PathBuf};
use support::{meniscus, names_in};

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/pvd")
        .join(name)
}

/// Runs `meniscus ARGS`: exit code, stdout, stderr.
fn run(args: &[&str]) -> (Option<i32>, String, String) {
    let out = meniscus().args(args).output().unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// `reconstruct INPUT -r 0.025 -q -o OUTPUT EXTRA...`.
fn reconstruct(input: &str, output: &str, extra: &[&str]) -> (Option<i32>, String, String) {
    let mut args = vec!["reconstruct", input, "-r", "0.025", "-q", "-o", output];
    args.extend_from_slice(extra);
    run(&args)
}

/// A collection `run.pvd` in `dir` holding `body` inside `<Collection>` (one line per
/// entry, from line 4), and the empty files `frame_0.vtu` … `frame_3.vtu` it may name.
fn collection(dir: &Path, body: &str) -> PathBuf {
    for k in 0..4 {
        std::fs::write(dir.join(format!("frame_{k}.vtu")), b"").unwrap();
    }
    let path = dir.join("run.pvd");
    std::fs::write(
        &path,
        format!(
            "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n  <Collection>\n{body}  </Collection>\n</VTKFile>\n"
        ),
    )
    .unwrap();
    path
}

fn entry(timestep: &str, part: &str, file: &str) -> String {
    format!("    <DataSet timestep=\"{timestep}\" group=\"\" part=\"{part}\" file=\"{file}\"/>\n")
}

#[test]
fn a_collection_gives_the_meshes_of_the_same_frames_through_a_pattern() {
    let dir = tempfile::tempdir().unwrap();
    let out = |name: &str| format!("{}/{name}/s_{{}}.ply", dir.path().display());
    let pvd = fixture("run.pvd");
    let (code, stdout, stderr) = reconstruct(
        pvd.to_str().unwrap(),
        &out("pvd"),
        &["--json-progress", "--no-radius-check"],
    );
    assert_eq!(code, Some(0), "{stderr}");
    let pattern = fixture("frame_{}.vtu");
    let (code, _, stderr) = reconstruct(
        pattern.to_str().unwrap(),
        &out("pattern"),
        &["--no-radius-check"],
    );
    assert_eq!(code, Some(0), "{stderr}");
    let names = ["s_0.ply", "s_1.ply", "s_2.ply"];
    assert_eq!(names_in(&dir.path().join("pvd")), names);
    let mut sizes = Vec::new();
    for name in names {
        let a = std::fs::read(dir.path().join("pvd").join(name)).unwrap();
        let b = std::fs::read(dir.path().join("pattern").join(name)).unwrap();
        assert!(a == b, "{name} differs from the pattern's");
        sizes.push(a.len());
    }
    // 40, 60 and 80 particles: three different meshes, in time order.
    assert!(sizes[0] < sizes[1] && sizes[1] < sizes[2], "{sizes:?}");
    // Each frame's progress line carries its timestep.
    let times: Vec<(i64, f64)> = stdout
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .map(|v| (v["frame"].as_i64().unwrap(), v["time"].as_f64().unwrap()))
        .collect();
    assert_eq!(times, [(0, 0.0), (1, 0.05), (2, 0.1)]);
}

#[test]
fn frames_of_a_collection_are_chosen_as_those_of_a_pattern() {
    let pvd = fixture("run.pvd");
    let all = collection_frames(&pvd).unwrap();
    let files: Vec<_> = all
        .iter()
        .map(|f| f.input.file_name().unwrap().to_str().unwrap().to_string())
        .collect();
    assert_eq!(files, ["frame_0.vtu", "frame_1.vtu", "frame_2.vtu"]);
    assert_eq!(
        all.iter().map(|f| f.label.as_str()).collect::<Vec<_>>(),
        ["0", "1", "2"]
    );
    let numbers = |choice: FrameChoice| -> Vec<i64> {
        choose(pvd.to_str().unwrap(), &choice)
            .unwrap()
            .iter()
            .map(|f| f.number)
            .collect()
    };
    let frames = |text: &str| FrameChoice {
        frames: Some(text.parse().unwrap()),
        ..FrameChoice::default()
    };
    assert_eq!(numbers(FrameChoice::default()), [0, 1, 2]);
    assert_eq!(numbers(frames("0,2")), [0, 2]);
    assert_eq!(numbers(frames("0-2:2")), [0, 2]);
    let range = |start, end| FrameChoice {
        start,
        end,
        ..FrameChoice::default()
    };
    assert_eq!(numbers(range(Some(1), None)), [1, 2]);
    assert_eq!(numbers(range(None, Some(1))), [0, 1]);
    assert_eq!(numbers(range(Some(1), Some(2))), [1, 2]);
    let shard = |text: &str| FrameChoice {
        shard: Some(text.parse::<Shard>().unwrap()),
        ..FrameChoice::default()
    };
    assert_eq!(numbers(shard("0/2")), [0, 2]);
    assert_eq!(numbers(shard("1/2")), [1]);
    // Frames it does not hold are errors naming them and what it holds.
    let message = |choice: FrameChoice| {
        choose(pvd.to_str().unwrap(), &choice)
            .unwrap_err()
            .to_string()
    };
    let m = message(frames("1-4"));
    assert!(
        m.contains(
            "no dataset for 2 of the 4 selected frames: 3, 4 (the collection holds frames 0-2)"
        ),
        "{m}"
    );
    let m = message(range(Some(-1), Some(3)));
    assert!(
        m.contains("frames -1, 3 of the range -1..=3 are not in the collection"),
        "{m}"
    );
    let m = message(range(Some(5), None));
    assert!(
        m.contains("no frame of the collection is in the range 5..="),
        "{m}"
    );
    let m = message(shard("3/4"));
    assert!(m.contains("shard 3/4 of 3 frames is empty"), "{m}");
}

#[test]
fn the_command_line_chooses_frames_of_a_collection() {
    let dir = tempfile::tempdir().unwrap();
    let pvd = fixture("run.pvd");
    let out = |name: &str| format!("{}/{name}/s_{{}}.ply", dir.path().display());
    let (code, _, stderr) = reconstruct(
        pvd.to_str().unwrap(),
        &out("a"),
        &["--frames", "0,2", "--no-radius-check"],
    );
    assert_eq!(code, Some(0), "{stderr}");
    assert_eq!(names_in(&dir.path().join("a")), ["s_0.ply", "s_2.ply"]);
    let (code, _, stderr) = reconstruct(
        pvd.to_str().unwrap(),
        &out("b"),
        &["--frames", "2-3", "--no-radius-check"],
    );
    assert_eq!(code, Some(1), "{stderr}");
    assert!(stderr.contains("run.pvd"), "{stderr}");
    assert!(
        stderr.contains("no dataset for 1 of the 2 selected frames: 3"),
        "{stderr}"
    );
    assert!(!dir.path().join("b").exists());
    // One output file for a collection is refused unless it holds a sequence.
    let single = dir.path().join("one.ply");
    let (code, _, stderr) = reconstruct(pvd.to_str().unwrap(), single.to_str().unwrap(), &[]);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("is a sequence collection"), "{stderr}");
    assert!(!single.exists());
}

/// The error of `collection_frames` on a collection of `body`.
fn refused(body: &str) -> (Error, String) {
    let dir = tempfile::tempdir().unwrap();
    let path = collection(dir.path(), body);
    let e = collection_frames(&path).unwrap_err();
    let message = e.to_string();
    assert!(message.contains("run.pvd"), "{message}");
    (e, message)
}

#[test]
fn broken_collections_are_errors_naming_the_file_and_the_entry() {
    let (e, m) = refused("");
    assert!(matches!(e, Error::Parse { .. }), "{e:?}");
    assert!(m.contains("an empty collection"), "{m}");
    let (_, m) = refused(&format!(
        "{}    <DataSet timestep=\"1\" part=\"0\"/>\n",
        entry("0", "0", "frame_0.vtu")
    ));
    assert!(m.contains("line 5: <DataSet> without a file"), "{m}");
    let (e, m) = refused(&format!(
        "{}{}",
        entry("0", "0", "frame_0.vtu"),
        entry("1", "0", "gone.vtu")
    ));
    assert!(
        matches!(&e, Error::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound),
        "{e:?}"
    );
    assert!(m.contains("line 5: the DataSet's file \"gone.vtu\""), "{m}");
    assert!(m.contains("does not exist"), "{m}");
    let (_, m) = refused(&format!(
        "{}{}{}",
        entry("0", "0", "frame_0.vtu"),
        entry("1", "0", "frame_1.vtu"),
        entry("1.0", "0", "frame_2.vtu")
    ));
    assert!(
        m.contains("line 6: duplicate timestep 1: \"frame_1.vtu\" (line 5) and \"frame_2.vtu\""),
        "{m}"
    );
    let (_, m) = refused(&format!(
        "{}{}",
        entry("0", "0", "frame_0.vtu"),
        entry("0", "1", "frame_1.vtu")
    ));
    assert!(
        m.contains("line 5: timestep 0 has more than one part"),
        "{m}"
    );
    assert!(m.contains("part \"1\""), "{m}");
    let (_, m) = refused(&format!(
        "{}    <DataSet file=\"frame_1.vtu\"/>\n",
        entry("0", "0", "frame_0.vtu")
    ));
    assert!(
        m.contains("line 5: <DataSet file=\"frame_1.vtu\"> has no timestep"),
        "{m}"
    );
    let (_, m) = refused(&entry("soon", "0", "frame_0.vtu"));
    assert!(
        m.contains("line 4: timestep \"soon\" is not a finite number"),
        "{m}"
    );
    // Not a collection: a dataset file, another XML file.
    let dir = tempfile::tempdir().unwrap();
    let grid = dir.path().join("grid.pvd");
    std::fs::copy(fixture("frame_0.vtu"), &grid).unwrap();
    let m = collection_frames(&grid).unwrap_err().to_string();
    assert!(m.contains("grid.pvd: line 2"), "{m}");
    assert!(
        m.contains("not a collection: VTKFile type \"UnstructuredGrid\""),
        "{m}"
    );
    std::fs::write(&grid, "<?xml version=\"1.0\"?>\n<html></html>\n").unwrap();
    let m = collection_frames(&grid).unwrap_err().to_string();
    assert!(m.contains("the first element is <html>"), "{m}");
    // Cut off after a whole entry (a collection still being written): an error, not the
    // entries so far taken for the whole sequence.
    let whole = collection(dir.path(), &entry("0", "0", "frame_0.vtu"));
    let text = std::fs::read_to_string(&whole).unwrap();
    let cut = &text[..text.find("  </Collection>").unwrap()];
    std::fs::write(&whole, cut).unwrap();
    let m = collection_frames(&whole).unwrap_err().to_string();
    assert!(
        m.contains("the file ends inside <Collection> (2 element(s) left open)"),
        "{m}"
    );
    assert!(m.contains("cut off"), "{m}");
    std::fs::write(&whole, &text[..text.find("</VTKFile>").unwrap()]).unwrap();
    let m = collection_frames(&whole).unwrap_err().to_string();
    assert!(m.contains("the file ends inside <VTKFile>"), "{m}");
    // A second root after the first: refused, whatever it is.
    for late in [
        "<VTKFile type=\"Collection\"><Collection/></VTKFile>",
        "<html/>",
    ] {
        std::fs::write(&whole, format!("{text}{late}\n")).unwrap();
        let m = collection_frames(&whole).unwrap_err().to_string();
        assert!(m.contains("line 7: <"), "{m}");
        assert!(m.contains("> after the end of the <VTKFile>"), "{m}");
    }
}

#[test]
fn collection_rules_order_and_duplicates() {
    let dir = tempfile::tempdir().unwrap();
    // Without timesteps: file order, no time.
    let path = collection(
        dir.path(),
        "    <DataSet file=\"frame_2.vtu\"/>\n    <DataSet file=\"frame_0.vtu\"/>\n",
    );
    let frames = collection_frames(&path).unwrap();
    let names: Vec<_> = frames
        .iter()
        .map(|f| f.input.file_name().unwrap().to_owned())
        .collect();
    assert_eq!(names, ["frame_2.vtu", "frame_0.vtu"]);
    assert!(frames.iter().all(|f| f.time.is_none()));
    // The same file listed twice for a time counts once; one part other than 0 is fine;
    // an absolute path is taken as it is; times sort numerically (10 after 9).
    let absolute = dir.path().join("frame_3.vtu");
    let body = format!(
        "{}{}{}{}",
        entry("10", "2", "frame_1.vtu"),
        entry("9", "2", "frame_0.vtu"),
        entry("9", "2", "frame_0.vtu"),
        entry("11", "2", absolute.to_str().unwrap()),
    );
    let path = collection(dir.path(), &body);
    let frames = collection_frames(&path).unwrap();
    let seen: Vec<(i64, Option<f64>, PathBuf)> = frames
        .into_iter()
        .map(|f| (f.number, f.time, f.input))
        .collect();
    assert_eq!(
        seen,
        [
            (0, Some(9.0), dir.path().join("frame_0.vtu")),
            (1, Some(10.0), dir.path().join("frame_1.vtu")),
            (2, Some(11.0), absolute),
        ]
    );
}
