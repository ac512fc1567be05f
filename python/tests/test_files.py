import numpy as np
import pytest

import meniscus
from conftest import DATA, RADIUS, run_cli

VTK = DATA / "ParticleData_Fluid_25.vtk"


def test_read_particles_xyz(frame25):
    positions, attributes = meniscus.read_particles(str(DATA / "ParticleData_Fluid_25.xyz"))
    assert positions.dtype == np.float32
    assert np.array_equal(positions, frame25)
    assert attributes == {}


def test_attributes_round_trip_through_reconstruct(tmp_path):
    positions, attributes = meniscus.read_particles(VTK)
    # The names the library exports pick the attribute the CLI's default selection takes
    # (the bytes compared below).
    velocity_key = next(k for k in attributes if k.lower() in meniscus.VELOCITY_NAMES)
    velocity = attributes[velocity_key]
    assert velocity.shape == (len(positions), 3)
    mesh = meniscus.reconstruct(positions, RADIUS, attributes={velocity_key: velocity})
    carried = mesh.attributes[velocity_key]
    assert carried.shape == (len(mesh.vertices), 3)
    assert np.isfinite(carried).all()
    # Kernel-weighted means of particle velocities stay within their range.
    lo, hi = velocity.min(axis=0), velocity.max(axis=0)
    assert (carried >= lo - 1e-4).all() and (carried <= hi + 1e-4).all()
    # The same bytes as the CLI, which carries the velocity by default.
    cli = tmp_path / "b.ply"
    run_cli("reconstruct", VTK, "--particle-radius", RADIUS, "-o", cli, "--quiet")
    mesh.write(tmp_path / "a.ply")
    assert (tmp_path / "a.ply").read_bytes() == cli.read_bytes()
    run_cli("reconstruct", VTK, "--particle-radius", RADIUS, "-o", tmp_path / "b.glb", "--quiet")
    mesh.write(tmp_path / "a.glb")
    assert (tmp_path / "a.glb").read_bytes() == (tmp_path / "b.glb").read_bytes()


def test_missing_file_is_an_os_error(tmp_path):
    with pytest.raises(OSError) as e:
        meniscus.read_particles(tmp_path / "missing.xyz")
    assert isinstance(e.value, FileNotFoundError)
    with pytest.raises(OSError):
        meniscus.reconstruct_file(str(tmp_path / "missing.vtk"), str(tmp_path / "o.ply"), RADIUS)


def test_junk_file_is_a_format_error(tmp_path):
    junk = tmp_path / "junk.vtk"
    junk.write_bytes(b"this is not a VTK file\n\x00\x01garbage" * 10)
    with pytest.raises(meniscus.FormatError):
        meniscus.read_particles(junk)
    with pytest.raises(meniscus.FormatError):
        meniscus.read_particles(tmp_path / "particles.unknown")


def test_reconstruct_file_equals_cli(tmp_path, cli_ply):
    out = tmp_path / "f.ply"
    reports = meniscus.reconstruct_file(str(DATA / "ParticleData_Fluid_25.xyz"), str(out), RADIUS)
    assert len(reports) == 1 and reports[0]["status"] == "done"
    assert out.read_bytes() == cli_ply.read_bytes()
    with pytest.raises(ValueError, match="particle_radius"):
        meniscus.reconstruct_file(str(DATA / "ParticleData_Fluid_25.xyz"), str(out), -1.0)


def test_reconstruct_file_archive_equals_cli(tmp_path):
    # The default error bound is 0.01 r with r as written (0.012, not the f32's
    # 0.0120000001...): the same bound as the CLI's, so the archives are the same bytes
    # and the ones of several writers merge.
    pattern = str(DATA / "ParticleData_Fluid_{}.xyz")
    run_cli("reconstruct", pattern, "--particle-radius", RADIUS, "-o", tmp_path / "cli.mseq", "--quiet")
    reports = meniscus.reconstruct_file(pattern, str(tmp_path / "py.mseq"), RADIUS)
    assert [r["status"] for r in reports] == ["done"] * len(reports) and len(reports) > 1
    assert (tmp_path / "py.mseq").read_bytes() == (tmp_path / "cli.mseq").read_bytes()


def area(mesh):
    a, b, c = (mesh.vertices[mesh.triangles[:, k]].astype(np.float64) for k in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()


def test_archive_append_read_verify(frame25, tmp_path):
    path = tmp_path / "run.mseq"
    archive = meniscus.Archive(path)
    assert len(archive) == 0 and archive.frames == []
    meshes = {}
    for number, name in ((25, "ParticleData_Fluid_25.xyz"), (31, "ParticleData_Fluid_31.xyz")):
        positions, attributes = meniscus.read_particles(DATA / name)
        meshes[number] = meniscus.reconstruct(positions, RADIUS)
        assert archive.append(number, meshes[number]) > 0
    assert len(archive) == 2 and archive.frames == [25, 31] and 31 in archive
    for number, mesh in meshes.items():
        back = archive[number]
        assert back.triangles.shape == mesh.triangles.shape
        assert back.vertices.shape == mesh.vertices.shape
        # The archive orders vertices its own way; the geometry is kept to the default
        # bound, 0.01 r per coordinate.
        bound = 0.01 * RADIUS * 1.001
        assert np.abs(back.vertices.min(axis=0) - mesh.vertices.min(axis=0)).max() <= bound
        assert np.abs(back.vertices.max(axis=0) - mesh.vertices.max(axis=0)).max() <= bound
        assert area(back) == pytest.approx(area(mesh), rel=1e-3)
    report = archive.verify()
    assert report["clean"] and report["good"] == [25, 31]
    with pytest.raises(FileExistsError):
        archive.append(25, meshes[25])
    with pytest.raises(KeyError, match=r"frame 7: .*it holds 2 frame\(s\): 25, 31"):
        archive[7]
    # A frame read back is appended with the archive's bound; a new archive needs one.
    archive.append(40, archive[25])
    assert archive.frames == [25, 31, 40] and archive.verify()["clean"]
    with pytest.raises(ValueError, match="error_bound"):
        meniscus.Archive(tmp_path / "other.mseq").append(1, archive[25])
    other = meniscus.Archive(tmp_path / "other.mseq", error_bound=1e-4)
    other.append(1, archive[25])
    assert other.frames == [1] and other.verify()["clean"]


def test_archive_append_of_a_control_mesh_is_the_cli_archive(tmp_path):
    # The CLI's .mseq stores each frame's control mesh (before Loop subdivision) and the
    # number of steps the reader runs: reconstructed with defer_subdivision=True (the
    # control mesh, its particles kept inside the surface it becomes) and appended with
    # subdivide=1, a frame is the CLI's, byte for byte, one append at a time.
    # (A sequence takes the steady preset, which does not subdivide: the still one here.)
    run_cli("reconstruct", str(DATA / "ParticleData_Fluid_{}.xyz"), "--particle-radius", RADIUS,
            "--frames", "1,9,25", "--preset", "still", "-o", tmp_path / "cli.mseq", "--quiet")
    archive = meniscus.Archive(tmp_path / "py.mseq")
    for number in (1, 9, 25):
        positions, _ = meniscus.read_particles(DATA / f"ParticleData_Fluid_{number}.xyz")
        control = meniscus.reconstruct(positions, RADIUS, defer_subdivision=True)
        archive.append(number, control, subdivide=1)
    assert (tmp_path / "py.mseq").read_bytes() == (tmp_path / "cli.mseq").read_bytes()
    # Read back, a frame is the subdivided surface (4x the control mesh's triangles).
    assert archive[25].triangle_count - control.stats["sphere_triangles"] == 4 * control.stats["fluid_triangles"]
    # A mesh subdivided already is not subdivided again.
    with pytest.raises(ValueError, match="subdivided already"):
        archive.append(31, meniscus.reconstruct(positions, RADIUS), subdivide=1)
    # Stored as given (the default), a subdivided mesh keeps all its triangles: the same
    # surface when read back, in a larger file.
    whole = meniscus.Archive(tmp_path / "whole.mseq")
    whole.append(25, meniscus.reconstruct(positions, RADIUS))
    single = meniscus.Archive(tmp_path / "control.mseq")
    single.append(25, control, subdivide=1)
    assert whole[25].triangle_count == single[25].triangle_count
    assert (tmp_path / "whole.mseq").stat().st_size > 2 * (tmp_path / "control.mseq").stat().st_size
