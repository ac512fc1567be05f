"""reconstruct_file's frame choice, keep_going and progress: the CLI's --frames, --shard,
--keep-going and --json-progress, compared with the CLI itself."""

import json
import shutil
import subprocess

import pytest

import meniscus
from conftest import DATA, RADIUS, ROOT, cli_command, run_cli

PATTERN = str(DATA / "ParticleData_Fluid_{}.xyz")
FRAMES = [1, 9, 17, 25, 31, 45]  # the shipped .xyz frames


def numbers(reports):
    return [r["frame"] for r in reports]


def test_frames_and_shards_take_what_the_cli_takes(tmp_path):
    assert numbers(meniscus.reconstruct_file(PATTERN, str(tmp_path / "a.mseq"), RADIUS, frames="1-20:8,45")) == [1, 9, 17, 45]
    # A list of numbers is the same selection.
    assert numbers(meniscus.reconstruct_file(PATTERN, str(tmp_path / "b.mseq"), RADIUS, frames=[45, 9, 1])) == [1, 9, 45]
    assert numbers(meniscus.reconstruct_file(PATTERN, str(tmp_path / "c.mseq"), RADIUS, start=17)) == [17, 25, 31, 45]
    # Shards are round-robin; (i, n) and "i/n" are the same shard; the shards' union is
    # every frame once.
    parts = []
    for i in range(4):
        shard = (i, 4) if i % 2 else f"{i}/4"
        reports = meniscus.reconstruct_file(PATTERN, str(tmp_path / f"part_{i}.mseq"), RADIUS, shard=shard)
        assert numbers(reports) == FRAMES[i::4]
        parts.append(tmp_path / f"part_{i}.mseq")
    # Merged, the shards' archives are the CLI's archive of the whole sequence.
    run_cli("reconstruct", PATTERN, "--particle-radius", RADIUS, "-o", tmp_path / "cli.mseq", "--quiet")
    stats = meniscus.merge_archives(parts, tmp_path / "all.mseq")
    assert stats == {"inputs": 4, "frames": len(FRAMES), "bytes": (tmp_path / "all.mseq").stat().st_size}
    assert (tmp_path / "all.mseq").read_bytes() == (tmp_path / "cli.mseq").read_bytes()
    # A merge that cannot be done is refused: the same frame twice.
    with pytest.raises(meniscus.FormatError, match="25"):
        meniscus.merge_archives([tmp_path / "all.mseq", parts[3]], tmp_path / "twice.mseq")


def test_bad_frame_choices_name_the_option(tmp_path):
    out = str(tmp_path / "o.mseq")
    with pytest.raises(ValueError, match="invalid frames: .*reversed"):
        meniscus.reconstruct_file(PATTERN, out, RADIUS, frames="9-1")
    with pytest.raises(ValueError, match="invalid frames: takes the place of start/end"):
        meniscus.reconstruct_file(PATTERN, out, RADIUS, frames="1", start=1)
    with pytest.raises(ValueError, match="invalid shard: .*does not exist"):
        meniscus.reconstruct_file(PATTERN, out, RADIUS, shard=(4, 4))
    with pytest.raises(ValueError, match="invalid shard: .*empty"):
        meniscus.reconstruct_file(PATTERN, out, RADIUS, shard="6/7")
    with pytest.raises(TypeError, match="invalid shard"):
        meniscus.reconstruct_file(PATTERN, out, RADIUS, shard=0.5)
    with pytest.raises(OSError, match="no file for 1 of the 2 selected frames: 2"):
        meniscus.reconstruct_file(PATTERN, out, RADIUS, frames="1,2")
    with pytest.raises(ValueError, match="invalid frames: .*single file"):
        meniscus.reconstruct_file(str(DATA / "ParticleData_Fluid_1.xyz"), out, RADIUS, frames="1")
    # A CLI flag the caller did not use is never named.
    for kwargs in ({"frames": "1", "start": 1}, {"frames": "x"}, {"shard": "1"}):
        with pytest.raises(ValueError) as e:
            meniscus.reconstruct_file(PATTERN, out, RADIUS, **kwargs)
        assert "--" not in str(e.value), e.value
    assert not (tmp_path / "o.mseq").exists()


def broken_sequence(tmp_path):
    """Frames 1, 5 (truncated: not whole x, y, z triples) and 9."""
    for n in (1, 9):
        shutil.copy(DATA / f"ParticleData_Fluid_{n}.xyz", tmp_path / f"f_{n}.xyz")
    (tmp_path / "f_5.xyz").write_bytes((DATA / "ParticleData_Fluid_1.xyz").read_bytes()[:100])
    return str(tmp_path / "f_{}.xyz")


def test_keep_going_and_progress_as_the_cli(tmp_path):
    pattern = broken_sequence(tmp_path)
    lines = []
    reports = meniscus.reconstruct_file(pattern, str(tmp_path / "py.mseq"), RADIUS, keep_going=True, progress=lines.append)
    assert [(r["frame"], r["status"]) for r in reports] == [(1, "done"), (5, "failed"), (9, "done")]
    assert "multiple of 12" in reports[1]["error"]
    assert meniscus.Archive(tmp_path / "py.mseq").frames == [1, 9]
    # The callback got each frame as it finished, as the CLI's --json-progress line.
    cli = subprocess.run(
        cli_command("reconstruct", pattern, "-r", RADIUS, "-o", tmp_path / "cli.mseq", "--keep-going", "--json-progress", "-q"),
        cwd=ROOT, capture_output=True, text=True,
    )
    assert cli.returncode == 1, cli.stderr
    cli_lines = [json.loads(line) for line in cli.stdout.splitlines()]
    assert len(lines) == len(cli_lines) == 3
    for mine, theirs, report in zip(lines, cli_lines, reports):
        assert mine.keys() == theirs.keys()
        for key in ("frame", "status", "triangles", "error"):
            assert mine.get(key) == theirs.get(key), key
        assert mine["frame"] == report["frame"] and mine["seconds"] == report["seconds"]
        if report["status"] == "done":
            r = report["reconstruction"]
            assert mine["triangles"] == r["fluid_triangles"] + r["sphere_triangles"] > 0
    assert (tmp_path / "py.mseq").read_bytes() == (tmp_path / "cli.mseq").read_bytes()


def test_without_keep_going_the_first_failure_stops_the_run(tmp_path):
    pattern = broken_sequence(tmp_path)
    with pytest.raises(meniscus.FormatError, match="multiple of 12"):
        meniscus.reconstruct_file(pattern, str(tmp_path / "o.mseq"), RADIUS)
    # The frame before it is kept (the archive is finished with its index).
    archive = meniscus.Archive(tmp_path / "o.mseq")
    assert archive.frames == [1] and archive.verify()["clean"]
    # A re-run that skips what is held and goes on past the broken frame completes it.
    reports = meniscus.reconstruct_file(pattern, str(tmp_path / "o.mseq"), RADIUS, skip_existing=True, keep_going=True)
    assert [r["status"] for r in reports] == ["skipped", "failed", "done"]
    assert archive.frames == [1, 9]


def test_an_exception_in_progress_stops_the_run_and_is_raised(tmp_path):
    seen = []

    def progress(line):
        seen.append(line["frame"])
        raise LookupError("the farm manager went away")

    with pytest.raises(LookupError, match="went away"):
        meniscus.reconstruct_file(PATTERN, str(tmp_path / "o.mseq"), RADIUS, progress=progress)
    assert seen == [1]
    assert meniscus.Archive(tmp_path / "o.mseq").frames == [1]


def test_a_pvd_collection_is_a_sequence_like_its_pattern(tmp_path):
    pvd = ROOT / "tests" / "data" / "pvd"
    reports = meniscus.reconstruct_file(str(pvd / "run.pvd"), str(tmp_path / "pvd.mseq"), 0.025, radius_check=False, frames="0,2")
    assert [(r["frame"], r["time"]) for r in reports] == [(0, 0.0), (2, 0.1)]
    meniscus.reconstruct_file(str(pvd / "frame_{}.vtu"), str(tmp_path / "pattern.mseq"), 0.025, radius_check=False, frames="0,2")
    assert (tmp_path / "pvd.mseq").read_bytes() == (tmp_path / "pattern.mseq").read_bytes()
    with pytest.raises(OSError, match="no dataset for 1 of the 1 selected frames: 3"):
        meniscus.reconstruct_file(str(pvd / "run.pvd"), str(tmp_path / "o.mseq"), 0.025, frames="3")


def test_a_sequence_takes_the_steady_preset_and_one_file_the_still(tmp_path):
    one = str(DATA / "ParticleData_Fluid_25.xyz")
    meniscus.reconstruct_file(PATTERN, str(tmp_path / "seq_{}.ply"), RADIUS, frames=[25])
    meniscus.reconstruct_file(one, str(tmp_path / "steady.ply"), RADIUS, preset="steady")
    meniscus.reconstruct_file(one, str(tmp_path / "one.ply"), RADIUS)
    meniscus.reconstruct_file(PATTERN, str(tmp_path / "still_{}.ply"), RADIUS, frames=[25], preset="still")
    sequence = (tmp_path / "seq_25.ply").read_bytes()
    # One frame chosen of a pattern is still a sequence's frame (a farm task's).
    assert sequence == (tmp_path / "steady.ply").read_bytes()
    assert sequence != (tmp_path / "one.ply").read_bytes()
    assert (tmp_path / "still_25.ply").read_bytes() == (tmp_path / "one.ply").read_bytes()
    with pytest.raises(ValueError, match='invalid preset: .*"smooth"'):
        meniscus.reconstruct_file(PATTERN, str(tmp_path / "x_{}.ply"), RADIUS, preset="smooth")
    assert not list(tmp_path.glob("x_*"))
