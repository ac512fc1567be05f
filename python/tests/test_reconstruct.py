import numpy as np
import pytest

import meniscus
from conftest import DATA, RADIUS, run_cli


def ply_counts(path):
    counts = {}
    with open(path, "rb") as f:
        for line in f:
            if line.startswith(b"element"):
                _, name, n = line.split()
                counts[name.decode()] = int(n)
            if line.strip() == b"end_header":
                return counts


def test_numpy_in_mesh_out_equals_cli(frame25, cli_ply, tmp_path):
    mesh = meniscus.reconstruct(frame25, RADIUS)
    counts = ply_counts(cli_ply)
    assert mesh.vertices.shape == (counts["vertex"], 3)
    assert mesh.triangles.shape == (counts["face"], 3)
    assert mesh.vertices.dtype == np.float32
    assert mesh.triangles.dtype == np.uint32
    assert mesh.normals.shape == mesh.vertices.shape
    assert mesh.triangles.max() < len(mesh.vertices)
    out = tmp_path / "a.ply"
    mesh.write(str(out))
    assert out.read_bytes() == cli_ply.read_bytes()


def test_float64_and_strided_give_the_same_mesh(frame25):
    a = meniscus.reconstruct(frame25, RADIUS, decimate=None, subdivide=0)
    b = meniscus.reconstruct(frame25.astype(np.float64), RADIUS, decimate=None, subdivide=0)
    wide = np.zeros((len(frame25), 4), dtype=np.float32)
    wide[:, :3] = frame25
    c = meniscus.reconstruct(wide[:, :3], RADIUS, decimate=None, subdivide=0)
    for m in (b, c):
        assert np.array_equal(a.vertices, m.vertices)
        assert np.array_equal(a.triangles, m.triangles)


def test_stats_is_the_stage_table(frame25):
    mesh = meniscus.reconstruct(frame25, RADIUS)
    stats = mesh.stats
    assert stats["particles"] == len(frame25)
    stages = [s["stage"] for s in stats["stages"]]
    assert stages and all(s["seconds"] >= 0 for s in stats["stages"])
    assert stats["fluid_triangles"] + stats["sphere_triangles"] == len(mesh.triangles)


def test_options_off_and_spheres(frame25):
    raw = meniscus.reconstruct(frame25, RADIUS, decimate=None, subdivide=0, isolated_spheres=None)
    assert raw.stats["isolated_particles"] == 0
    assert raw.stats["decimation"] is None
    assert len(raw.triangles) > 0


def test_sphere_centers_and_scales(frame25):
    mesh = meniscus.reconstruct(frame25, RADIUS)
    centers = mesh.sphere_centers
    count = len(centers)
    assert centers.shape == (count, 3)
    assert mesh.stats["sphere_triangles"] == count * 320  # level-2 icospheres
    # Each centre is an input particle.
    particles = {tuple(p) for p in np.asarray(frame25, dtype=np.float32)}
    assert all(tuple(c) in particles for c in centers)
    # One radius for every particle: every sphere at scale 1.
    np.testing.assert_array_equal(mesh.sphere_scales, np.ones(count, dtype=np.float32))


def test_attributes_from_arrays(frame25):
    n = len(frame25)
    velocity = np.tile(np.array([1.0, -2.0, 0.5]), (n, 1))
    density = np.full(n, 1000.0)
    mesh = meniscus.reconstruct(frame25, RADIUS, attributes={"velocity": velocity, "density": density})
    assert mesh.attributes["velocity"].shape == (len(mesh.vertices), 3)
    assert mesh.attributes["density"].shape == (len(mesh.vertices),)
    # A constant attribute comes out exactly (to f32 rounding).
    np.testing.assert_allclose(mesh.attributes["velocity"], np.tile([1.0, -2.0, 0.5], (len(mesh.vertices), 1)), rtol=1e-5)
    np.testing.assert_allclose(mesh.attributes["density"], 1000.0, rtol=1e-5)


@pytest.mark.parametrize("ext", ["ply", "obj", "glb", "gltf", "vtk"])
def test_write_formats(frame25, tmp_path, ext):
    mesh = meniscus.reconstruct(frame25, RADIUS)
    out = tmp_path / f"m.{ext}"
    assert mesh.write(out) == out.stat().st_size > 0


@pytest.mark.parametrize(
    "options, flags",
    [
        # The concavity thresholds are the isotropic field's.
        ({"kernel": "isotropic", "t_low": 0.3, "t_high": 3.0}, ["--kernel", "isotropic", "--t-low", "0.3", "--t-high", "3.0"]),
        ({"decimate": "adaptive"}, ["--decimate", "adaptive"]),
        ({"decimate": 0.5, "decimate_error": 0.05}, ["--decimate", "0.5", "--decimate-error", "0.05"]),
        ({"particle_coverage": 0.0, "iso_offset": 0.1}, ["--particle-coverage", "0", "--iso-offset", "0.1"]),
        ({"kernel": "isotropic"}, ["--kernel", "isotropic"]),
        ({"max_stretch": 2.0}, ["--max-stretch", "2"]),
        (meniscus.PAPER, ["--paper"]),
        ({"preset": "paper"}, ["--paper"]),
        (meniscus.STEADY, ["--preset", "steady"]),
        ({"preset": "steady"}, ["--preset", "steady"]),
        # A setting given beside a preset wins.
        ({"preset": "steady", "cell_size": 1.0, "normal_smoothing": 0}, ["--preset", "steady", "-c", "1", "--normal-smoothing", "0"]),
        ({"smooth_method": "laplacian", "smooth_max_inward": 0.2}, ["--smooth-method", "laplacian", "--smooth-max-inward", "0.2"]),
        ({"preset": "steady", "smooth_feature_angle": None}, ["--preset", "steady", "--smooth-feature-angle", "off"]),
        # The bound holds decimation back at 0.9 on this frame: off is seen.
        ({"decimate": 0.9, "decimate_error": None}, ["--decimate", "0.9", "--decimate-error", "off"]),
        ({"decimate": None, "subdivide": 2, "isolated_spheres": None}, ["--decimate", "off", "--subdivide", "2", "--isolated-spheres", "off"]),
        # Containment moves the isotropic surface of this frame (and not the default one).
        ({"kernel": "isotropic", "keep_inside": None}, ["--kernel", "isotropic", "--keep-inside", "off"]),
        ({"keep_inside": 0.5}, ["--keep-inside", "0.5"]),
        ({"smooth": 0}, ["--smooth", "0"]),
        ({"smooth": 3}, ["--smooth", "3"]),
        ({"tile_size": 16, "memory_budget": "1GiB", "temp_dir": "TMP"}, ["--tile-size", "16", "--memory-budget", "1GiB", "--temp-dir", "TMP"]),
    ],
)
def test_options_are_the_cli_flags(frame25, cli_ply, tmp_path, options, flags):
    spill = tmp_path / "spill"
    spill.mkdir()
    options = {k: (str(spill) if v == "TMP" else v) for k, v in options.items()}
    flags = [str(spill) if f == "TMP" else f for f in flags]
    cli = tmp_path / "cli.ply"
    run_cli("reconstruct", DATA / "ParticleData_Fluid_25.xyz", "--particle-radius", RADIUS, "-o", cli, "--quiet", *flags)
    # The flags change the surface (so a keyword that was ignored would show) ...
    assert cli.read_bytes() != cli_ply.read_bytes()
    # ... and the keywords change it the same way.
    meniscus.reconstruct(frame25, RADIUS, **options).write(tmp_path / "py.ply")
    assert (tmp_path / "py.ply").read_bytes() == cli.read_bytes()
    assert list(spill.iterdir()) == []


def test_unknown_and_mistyped_options_are_refused(frame25):
    with pytest.raises(TypeError, match="unexpected keyword argument 'decimation'"):
        meniscus.reconstruct(frame25, RADIUS, decimation=0.5)
    with pytest.raises(TypeError, match="unexpected keyword argument 'fps'"):
        meniscus.reconstruct(frame25, RADIUS, fps=24)
    with pytest.raises(TypeError, match="invalid cell_size"):
        meniscus.reconstruct(frame25, RADIUS, cell_size="fine")
    with pytest.raises(ValueError, match="invalid decimate: .*adaptive"):
        meniscus.reconstruct(frame25, RADIUS, decimate="most")
    with pytest.raises(ValueError, match="invalid decimate_error"):
        meniscus.reconstruct(frame25, RADIUS, decimate_error=-1.0)
    with pytest.raises(ValueError, match="invalid t_low/t_high"):
        meniscus.reconstruct(frame25, RADIUS, t_low=3.0, t_high=1.0)
