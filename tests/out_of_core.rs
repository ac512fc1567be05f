//! The out-of-core engine: decimation in tiles, the memory budget, the spill file, and
//! failures (unwritable temp dir, budget too small, truncated input, Ctrl-C) that leave
//! no output and no temporary file behind.

mod support;

use meniscus::mesh::{validate, InsideTest};
use meniscus::pipeline::{reconstruct_source, ReconstructOptions};
use meniscus::CancelToken;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};
use support::{dataset, dir_with_temp, in_pool, interrupt_once_spilled, meniscus, names_in, xyz};

#[test]
fn decimation_in_tiles_keeps_the_surface_closed_on_target_and_thread_independent() {
    // The last case cuts each tile's piece into regions (as large tiles are).
    for (rel, r, tile, regions) in [
        ("dambreak_small/ParticleData_Fluid_25.xyz", 0.012, 64, None),
        ("dambreak_small/ParticleData_Fluid_25.xyz", 0.012, 128, None),
        ("double_dambreak/ParticleData_Fluid_9.xyz", 0.025, 64, None),
        (
            "dambreak_small/ParticleData_Fluid_25.xyz",
            0.012,
            128,
            Some(4096),
        ),
    ] {
        let positions = xyz(rel);
        let whole = ReconstructOptions::new(r);
        let mut tiled = whole.clone();
        tiled.tiles.tile_size_cells = Some(tile);
        if let Some(regions) = regions {
            tiled.decimate.as_mut().unwrap().region_triangles = regions;
        }
        let (reference, _) =
            reconstruct_source(&positions, &whole, &|_| {}, &CancelToken::new()).unwrap();
        let (one, stats) = in_pool(1, || {
            reconstruct_source(&positions, &tiled, &|_| {}, &CancelToken::new()).unwrap()
        });
        let (two, _) = in_pool(2, || {
            reconstruct_source(&positions, &tiled, &|_| {}, &CancelToken::new()).unwrap()
        });

        assert!(stats.tiles.tiles >= 3, "{rel}: {:?}", stats.tiles);
        assert!(stats.tiles.spill_bytes >= 16 * positions.len() as u64);
        let d = stats.decimation.as_ref().expect("decimated in tiles");
        if regions.is_some() {
            assert!(d.regions > 2 * stats.tiles.tiles, "{rel}: {d:?}");
        }
        let fraction = whole.decimate.as_ref().unwrap().target_reduction.unwrap();
        let target =
            ((1.0 - fraction as f64) * stats.marching_cubes_triangles as f64).ceil() as usize;
        // A collapse removes two triangles: one below the target at most.
        assert!(
            d.triangles_after + 1 >= target && d.triangles_after <= target + target / 50,
            "{rel}: {} triangles after decimation, target {target}",
            d.triangles_after
        );
        let report = validate(&one.fluid);
        assert!(report.is_closed_manifold(), "{rel}: {report:?}");
        assert!(
            one.fluid.positions == two.fluid.positions
                && one.fluid.triangles == two.fluid.triangles,
            "{rel}: output depends on the thread count"
        );
        // The same surface as the untiled run, up to the decimation's choices.
        let (v_tiled, v_whole) = (one.fluid.signed_volume(), reference.fluid.signed_volume());
        assert!(
            (v_tiled - v_whole).abs() < 0.01 * v_whole,
            "{rel}: volume {v_tiled} vs untiled {v_whole}"
        );
        assert_eq!(one.spheres.centers, reference.spheres.centers, "{rel}");
        let inside = InsideTest::new(&one.fluid, 4.0 * r);
        let outside = positions
            .iter()
            .filter(|p| !one.spheres.centers.contains(p) && !inside.contains(**p))
            .count();
        let inside_reference = InsideTest::new(&reference.fluid, 4.0 * r);
        let outside_reference = positions
            .iter()
            .filter(|p| !reference.spheres.centers.contains(p) && !inside_reference.contains(**p))
            .count();
        assert_eq!(
            outside, outside_reference,
            "{rel}: particles outside the tiled surface"
        );
    }
}

#[test]
fn a_tiled_cli_run_leaves_no_temporary_file() {
    let (dir, temp) = dir_with_temp();
    let out = dir.path().join("s.ply");
    let status = meniscus()
        .args(["reconstruct"])
        .arg(dataset("dambreak_small/ParticleData_Fluid_25.xyz"))
        .args(["-r", "0.012", "--tile-size", "64", "-q", "--temp-dir"])
        .arg(&temp)
        .arg("-o")
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success());
    assert!(out.exists());
    assert!(names_in(&temp).is_empty(), "{:?}", names_in(&temp));
}

/// Runs the CLI expecting a failure; returns its stderr after checking that neither the
/// output nor anything in `temp` was left behind.
fn fails_cleanly(args: &[&str], input: &Path, temp: &Path, out: &Path) -> String {
    let result = meniscus()
        .arg("reconstruct")
        .arg(input)
        .args(args)
        .arg("--temp-dir")
        .arg(temp)
        .arg("-o")
        .arg(out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&result.stderr).into_owned();
    assert!(!result.status.success(), "{args:?} succeeded");
    assert!(!out.exists(), "{args:?} left {}", out.display());
    if temp.is_dir() {
        assert!(
            names_in(temp).is_empty(),
            "{args:?} left {:?}",
            names_in(temp)
        );
    }
    let siblings = names_in(out.parent().unwrap());
    assert!(
        siblings
            .iter()
            .all(|n| !n.starts_with('.') && !n.contains("tmp")),
        "{args:?} left {siblings:?}"
    );
    err
}

#[test]
fn an_unwritable_temp_dir_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let blocker = dir.path().join("not-a-dir");
    std::fs::write(&blocker, b"x").unwrap();
    let out_dir = dir.path().join("out");
    std::fs::create_dir(&out_dir).unwrap();
    let err = fails_cleanly(
        &["-r", "0.012", "--tile-size", "64", "-q"],
        &dataset("dambreak_small/ParticleData_Fluid_25.xyz"),
        &blocker.join("spill"),
        &out_dir.join("s.ply"),
    );
    assert!(
        err.contains("spill file") && err.contains("not-a-dir"),
        "{err}"
    );
}

#[test]
fn a_budget_too_small_for_one_tile_fails_before_any_work() {
    let (dir, temp) = dir_with_temp();
    let out_dir = dir.path().join("out");
    std::fs::create_dir(&out_dir).unwrap();
    let input = dataset("dambreak_small/ParticleData_Fluid_25.xyz");
    let out = out_dir.join("s.ply");
    let clock = Instant::now();
    let err = fails_cleanly(
        &["-r", "0.012", "--memory-budget", "2MiB", "-q"],
        &input,
        &temp,
        &out,
    );
    assert!(err.contains("memory budget of 2 MiB is too small"), "{err}");
    assert!(clock.elapsed() < Duration::from_secs(5));
    // An explicit tile size that does not fit is refused the same way.
    let err = fails_cleanly(
        &[
            "-r",
            "0.012",
            "--memory-budget",
            "70MiB",
            "--tile-size",
            "4096",
            "-q",
        ],
        &input,
        &temp,
        &out,
    );
    assert!(err.contains("tiles of 4096 cells need"), "{err}");
    // Nonsense sizes are rejected by name.
    let err = fails_cleanly(
        &["-r", "0.012", "--memory-budget", "2 parsecs"],
        &input,
        &temp,
        &out,
    );
    assert!(err.contains("--memory-budget"), "{err}");
}

#[test]
fn truncated_inputs_fail_cleanly_in_a_tiled_run() {
    let (dir, temp) = dir_with_temp();
    let out_dir = dir.path().join("out");
    std::fs::create_dir(&out_dir).unwrap();
    let args = ["-r", "0.012", "--tile-size", "64", "-q"];

    // Raw positions cut mid-record.
    let bytes = std::fs::read(dataset("dambreak_small/ParticleData_Fluid_25.xyz")).unwrap();
    let cut = dir.path().join("cut.xyz");
    std::fs::write(&cut, &bytes[..bytes.len() / 2 + 5]).unwrap();
    let err = fails_cleanly(&args, &cut, &temp, &out_dir.join("a.ply"));
    assert!(
        err.contains("cut.xyz") && err.contains("not a multiple of 12"),
        "{err}"
    );

    // A gzip BGEO stream cut in the middle of the particle data.
    let bgeo = std::fs::read(dataset("dambreak_small/ParticleData_Fluid_25.bgeo")).unwrap();
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    std::io::Write::write_all(&mut gz, &bgeo).unwrap();
    let gz = gz.finish().unwrap();
    let cut = dir.path().join("cut.bgeo.gz");
    std::fs::write(&cut, &gz[..gz.len() / 2]).unwrap();
    let err = fails_cleanly(&args, &cut, &temp, &out_dir.join("b.ply"));
    assert!(err.contains("cut.bgeo.gz"), "{err}");
}

#[test]
fn ctrl_c_stops_a_tiled_run_and_removes_its_files() {
    let (dir, temp) = dir_with_temp();
    let out = dir.path().join("s.ply");
    // One-block tiles: hundreds of tiles, several seconds of work.
    let mut child = meniscus()
        .arg("reconstruct")
        .arg(dataset("dambreak_small/ParticleData_Fluid_25.xyz"))
        .args(["-r", "0.012", "--tile-size", "8", "-q", "--temp-dir"])
        .arg(&temp)
        .arg("-o")
        .arg(&out)
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until the spill file exists, then interrupt.
    interrupt_once_spilled(&mut child, &temp);
    let result = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&result.stderr);
    assert!(!result.status.success());
    assert!(err.contains("interrupted"), "{err}");
    assert!(!out.exists());
    assert!(names_in(&temp).is_empty(), "{:?}", names_in(&temp));
}

#[test]
fn marching_cubes_files_are_byte_identical_for_any_tiling_and_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let input = dataset("dambreak_small/ParticleData_Fluid_25.xyz");
    let mut files = Vec::new();
    for (tile, threads) in [
        (None, "2"),
        (Some("16"), "1"),
        (Some("64"), "2"),
        (Some("100000"), "1"),
    ] {
        let out = dir
            .path()
            .join(format!("s_{}_{threads}.ply", tile.unwrap_or("none")));
        let mut command = meniscus();
        command
            .arg("reconstruct")
            .arg(&input)
            .args(["-r", "0.012", "--decimate", "off", "--subdivide", "0", "-q"])
            .args(["--threads", threads])
            .arg("-o")
            .arg(&out);
        if let Some(t) = tile {
            command.args(["--tile-size", t]);
        }
        assert!(command.status().unwrap().success());
        files.push((tile, std::fs::read(&out).unwrap()));
    }
    for (tile, bytes) in &files[1..] {
        assert!(
            bytes == &files[0].1,
            "tile {tile:?}: output differs from the untiled run"
        );
    }
}

#[test]
fn bgeo_vtk_and_ply_are_streamed_and_mesh_like_their_xyz() {
    // The shipped BGEO and VTK (and a PLY written from them) hold the same positions as
    // the .xyz of the frame: streamed into a temporary .xyz and mapped, they must give the
    // same file, tiled or not, and leave no temporary file behind.
    let (dir, temp) = dir_with_temp();
    // The frame as binary PLY too.
    let ply = dir.path().join("frame25.ply");
    let particles = meniscus::io::particles::read_particles(
        &dataset("dambreak_small/ParticleData_Fluid_25.vtk"),
        None,
    )
    .unwrap();
    meniscus::io::particles::write_particles(
        &ply,
        &particles,
        meniscus::io::particles::ParticleFormat::Ply,
    )
    .unwrap();
    for tiles in [None, Some("64")] {
        let mut outputs = Vec::new();
        for input in [
            dataset("dambreak_small/ParticleData_Fluid_25.bgeo"),
            dataset("dambreak_small/ParticleData_Fluid_25.vtk"),
            ply.clone(),
            dataset("dambreak_small/ParticleData_Fluid_25.xyz"),
        ] {
            let name = input.file_name().unwrap().to_string_lossy().into_owned();
            let out = dir.path().join(format!("{name}.out.ply"));
            let mut cmd = meniscus();
            cmd.arg("reconstruct")
                .arg(&input)
                .args(["-r", "0.012", "-q", "--temp-dir"])
                .arg(&temp)
                .arg("-o")
                .arg(&out);
            if let Some(t) = tiles {
                cmd.args(["--tile-size", t]);
            }
            let result = cmd.output().unwrap();
            assert!(
                result.status.success(),
                "{}",
                String::from_utf8_lossy(&result.stderr)
            );
            outputs.push(std::fs::read(&out).unwrap());
        }
        assert!(
            outputs[0] == outputs[1],
            "tiles {tiles:?}: bgeo and xyz differ"
        );
        assert!(names_in(&temp).is_empty(), "left {:?}", names_in(&temp));
    }
}

#[test]
fn a_tiled_run_streaming_attributes_writes_the_file_of_the_parsed_path() {
    // The shipped VTK frame carries `velocity`: streamed with its payload into temporary
    // files, it must give the very bytes of the same frame parsed into memory. The parsed
    // path is forced with a copy whose title line is longer than the section scan follows.
    use meniscus::attributes::AttributeSelection;
    use meniscus::io::particles::{ParticleFormat, SpooledParticles};
    let (dir, temp) = dir_with_temp();
    let vtk = dataset("dambreak_small/ParticleData_Fluid_25.vtk");
    let bytes = std::fs::read(&vtk).unwrap();
    let first_line = bytes.iter().position(|&b| b == b'\n').unwrap() + 1;
    let second_line = first_line
        + bytes[first_line..]
            .iter()
            .position(|&b| b == b'\n')
            .unwrap();
    let mut unstreamable = bytes[..first_line].to_vec();
    unstreamable.extend(std::iter::repeat_n(b't', 5000));
    unstreamable.extend_from_slice(&bytes[second_line..]);
    let parsed_input = dir.path().join("long_title.vtk");
    std::fs::write(&parsed_input, &unstreamable).unwrap();
    let cancel = CancelToken::new();
    let velocity = AttributeSelection::Velocity;
    let streamed =
        SpooledParticles::from_file(&vtk, ParticleFormat::Vtk, &velocity, Some(&temp), &cancel)
            .unwrap()
            .expect("the shipped frame streams");
    assert_eq!(
        meniscus::io::particles::ParticleSource::attribute_layout(&streamed)[0].name,
        "velocity"
    );
    drop(streamed);
    assert!(SpooledParticles::from_file(
        &parsed_input,
        ParticleFormat::Vtk,
        &velocity,
        Some(&temp),
        &cancel
    )
    .unwrap()
    .is_none());
    assert!(names_in(&temp).is_empty(), "left {:?}", names_in(&temp));

    let mut outputs = Vec::new();
    for (input, attributes) in [(&vtk, "velocity"), (&parsed_input, "velocity")] {
        let out = dir
            .path()
            .join(format!("{}_{attributes}.ply", outputs.len()));
        let stats = dir.path().join(format!("{}.json", outputs.len()));
        let result = meniscus()
            .arg("reconstruct")
            .arg(input)
            .args(["-r", "0.012", "--tile-size", "64", "-q", "--attributes"])
            .arg(attributes)
            .arg("--stats")
            .arg(&stats)
            .arg("--temp-dir")
            .arg(&temp)
            .arg("-o")
            .arg(&out)
            .output()
            .unwrap();
        assert!(
            result.status.success(),
            "{}",
            String::from_utf8_lossy(&result.stderr)
        );
        let stats: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
        let tiles = &stats["frames"][0]["reconstruction"]["tiles"];
        assert!(tiles["tiles"].as_u64().unwrap() > 1, "not tiled: {tiles}");
        assert!(
            tiles["spill_bytes"].as_u64().unwrap() > 0,
            "not spilled: {tiles}"
        );
        assert!(names_in(&temp).is_empty(), "left {:?}", names_in(&temp));
        outputs.push(std::fs::read(&out).unwrap());
    }
    assert!(
        outputs[0] == outputs[1],
        "streamed and parsed outputs differ"
    );

    // The mesh writers do not write vertex attributes yet: compare the surfaces, whose
    // vertices and spheres carry the velocity, through the library, tiled.
    let mut options = ReconstructOptions::new(0.012);
    options.tiles.tile_size_cells = Some(64);
    options.tiles.temp_dir = Some(temp.clone());
    let streamed =
        SpooledParticles::from_file(&vtk, ParticleFormat::Vtk, &velocity, Some(&temp), &cancel)
            .unwrap()
            .unwrap();
    let (from_stream, stats) = reconstruct_source(streamed, &options, &|_| {}, &cancel).unwrap();
    assert!(stats.tiles.tiles > 1);
    let parsed = meniscus::io::particles::read_particles(&vtk, None)
        .unwrap()
        .select(&vtk, &velocity)
        .unwrap();
    let (from_parse, _) = reconstruct_source(parsed, &options, &|_| {}, &cancel).unwrap();
    assert_eq!(from_stream.fluid.attributes.len(), 1);
    assert_eq!(from_stream.fluid.attributes[0].name, "velocity");
    assert_eq!(
        from_stream.fluid.attributes[0].len(),
        from_stream.fluid.positions.len()
    );
    assert!(
        from_stream == from_parse,
        "streamed and parsed surfaces differ"
    );
    assert!(names_in(&temp).is_empty(), "left {:?}", names_in(&temp));
}

/// The PID of a process that has exited (and that no process has taken since).
#[cfg(target_os = "linux")]
fn dead_pid() -> u32 {
    loop {
        let mut child = Command::new("true").spawn().unwrap();
        let pid = child.id();
        child.wait().unwrap();
        if !Path::new("/proc").join(pid.to_string()).exists() {
            return pid;
        }
    }
}

#[cfg(target_os = "linux")]
#[test]
fn a_run_removes_what_killed_runs_left_and_keeps_what_live_ones_hold() {
    let dir = tempfile::tempdir().unwrap();
    let temp = dir.path().join("temp");
    let outputs = dir.path().join("out");
    std::fs::create_dir(&temp).unwrap();
    std::fs::create_dir(&outputs).unwrap();
    let dead = dead_pid();
    let mut live = Command::new("sleep").arg("60").spawn().unwrap();
    let alive = live.id();
    let spill = temp.join(format!("meniscus-spill-{dead}-aB3xYz"));
    std::fs::create_dir(&spill).unwrap();
    std::fs::write(spill.join("particles.bin"), [0u8; 64]).unwrap();
    let gone_temp = [
        format!("meniscus-input-{dead}-aB3xYz.xyz"),
        format!("meniscus-payload-{dead}-Qw12er.f32"),
    ];
    let kept_temp = [
        format!("meniscus-input-{alive}-aB3xYz.xyz"),
        format!("meniscus-spill-{alive}-aB3xYz"),
        format!("meniscus-input-{dead}-aB3.xyz"),
        format!("meniscus-input-{dead}-aB3xYz.xyz.keep"),
        "meniscus-input-aB3xYz.xyz".to_string(),
        "notes.txt".to_string(),
    ];
    for name in gone_temp.iter().chain(&kept_temp) {
        std::fs::write(temp.join(name), b"x").unwrap();
    }
    let out = outputs.join("s.ply");
    let gone_out = format!(".s.ply.tmp-{dead}-0");
    let kept_out = [
        format!(".s.ply.tmp-{alive}-3"),
        format!(".other.ply.tmp-{dead}-0"),
        format!("s.ply.tmp-{dead}-0"),
    ];
    for name in std::iter::once(&gone_out).chain(&kept_out) {
        std::fs::write(outputs.join(name), b"x").unwrap();
    }
    let status = meniscus()
        .args(["reconstruct"])
        .arg(dataset("dambreak_small/ParticleData_Fluid_25.xyz"))
        .args(["-r", "0.012", "-q", "--temp-dir"])
        .arg(&temp)
        .arg("-o")
        .arg(&out)
        .status()
        .unwrap();
    live.kill().unwrap();
    live.wait().unwrap();
    assert!(status.success());
    let mut kept: Vec<String> = kept_temp.to_vec();
    kept.sort();
    assert_eq!(names_in(&temp), kept);
    let mut kept: Vec<String> = kept_out.to_vec();
    kept.push("s.ply".into());
    kept.sort();
    assert_eq!(names_in(&outputs), kept);
}
