"""USD stages from Python: ``Mesh.write("f.usdc")`` and ``reconstruct_file(pattern,
"shot.usdc")``, read back with Pixar's library (``usd-core``; skipped without it)."""

import numpy as np
import pytest

import meniscus
from conftest import DATA, RADIUS, ROOT, run_cli

Usd = pytest.importorskip("pxr.Usd")
UsdGeom = pytest.importorskip("pxr.UsdGeom")

VTK = DATA / "ParticleData_Fluid_25.vtk"
SEQUENCE = ROOT / "datasets" / "double_dambreak"


def fluid(stage):
    return UsdGeom.Mesh(stage.GetPrimAtPath("/Surface/Fluid"))


def test_a_mesh_writes_a_one_frame_stage(tmp_path):
    positions, attributes = meniscus.read_particles(VTK)
    mesh = meniscus.reconstruct(positions, RADIUS, attributes=attributes, isolated_spheres=None)
    path = tmp_path / "f.usdc"
    assert mesh.write(path, frame=25) == path.stat().st_size
    stage = Usd.Stage.Open(str(path))
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (25, 25)
    assert UsdGeom.GetStageUpAxis(stage) == "Y"
    surface = fluid(stage)
    points = np.array(surface.GetPointsAttr().Get(25), dtype=np.float32)
    assert np.array_equal(points, mesh.vertices)
    indices = np.array(surface.GetFaceVertexIndicesAttr().Get(25)).reshape(-1, 3)
    assert np.array_equal(indices, mesh.triangles)
    (name,) = attributes
    velocities = np.array(surface.GetVelocitiesAttr().Get(25), dtype=np.float32)
    assert np.array_equal(velocities, mesh.attributes[name])
    # A text stage, by extension, holds the same points.
    mesh.write(tmp_path / "f.usda", frame=25)
    text = Usd.Stage.Open(str(tmp_path / "f.usda"))
    assert np.array_equal(np.array(fluid(text).GetPointsAttr().Get(25), dtype=np.float32), points)


def test_reconstruct_file_writes_the_cli_stage(tmp_path):
    pattern = str(SEQUENCE / "ParticleData_Fluid_{}.xyz")
    out = tmp_path / "shot.usdc"
    reports = meniscus.reconstruct_file(
        pattern, str(out), 0.025, frames=[1, 6, 9], fps=10, up_axis="Z", meters_per_unit=0.5
    )
    assert [r["frame"] for r in reports] == [1, 6, 9]
    cli = tmp_path / "cli.usdc"
    run_cli(
        "reconstruct", pattern, "-r", 0.025, "--frames", "1,6,9", "--fps", 10,
        "--up-axis", "Z", "--meters-per-unit", 0.5, "-o", cli, "--quiet",
    )
    assert out.read_bytes() == cli.read_bytes()
    stage = Usd.Stage.Open(str(out))
    assert stage.GetTimeCodesPerSecond() == 10
    assert UsdGeom.GetStageUpAxis(stage) == "Z"
    assert UsdGeom.GetStageMetersPerUnit(stage) == 0.5
    assert fluid(stage).GetPointsAttr().GetTimeSamples() == [1, 6, 9]
    with pytest.raises(ValueError, match="up_axis"):
        meniscus.reconstruct_file(pattern, str(out), 0.025, up_axis="X")
