import subprocess
import warnings

import numpy as np
import pytest

import meniscus
from conftest import DATA, RADIUS, ROOT, cli_command


@pytest.mark.parametrize("radius", [0.0, -1.0, float("nan")])
def test_bad_radius_is_a_value_error_naming_it(frame25, radius):
    with pytest.raises(ValueError, match="particle_radius"):
        meniscus.reconstruct(frame25, radius)


def test_bad_shapes_and_options(frame25):
    with pytest.raises(ValueError, match="positions"):
        meniscus.reconstruct(np.zeros((5, 2), dtype=np.float32), RADIUS)
    with pytest.raises(ValueError, match="positions"):
        meniscus.reconstruct([[0, 0, 0]], RADIUS)
    with pytest.raises(ValueError, match="decimate"):
        meniscus.reconstruct(frame25, RADIUS, decimate=1.5)
    with pytest.raises(ValueError, match="threads"):
        meniscus.reconstruct(frame25, RADIUS, threads=0)
    with pytest.raises(ValueError, match="attributes"):
        meniscus.reconstruct(frame25, RADIUS, attributes={"v": np.zeros(3)})


def test_non_finite_position_is_a_value_error():
    p = np.zeros((10, 3), dtype=np.float32)
    p[3, 1] = np.nan
    with pytest.raises(ValueError):
        meniscus.reconstruct(p, RADIUS)


def test_format_error_is_a_value_error():
    assert issubclass(meniscus.FormatError, ValueError)


def test_write_to_missing_directory_is_an_os_error(frame25, tmp_path):
    mesh = meniscus.reconstruct(frame25, RADIUS)
    with pytest.raises(OSError):
        mesh.write(tmp_path / "no" / "such" / "dir" / "m.ply")
    with pytest.raises(ValueError):
        mesh.write(tmp_path / "m.unknown")


def test_ctrl_c_interrupts_a_run(frame25):
    import os
    import signal
    import threading
    import time

    big = np.concatenate([frame25 + np.float32(dx) for dx in (0.0, 1.0, 2.0, 3.0, 4.0, 5.0)])
    # Ctrl-C as a terminal delivers it, to Python's own handler: a shell that starts a
    # job in the background (`cmd &`, as CI scripts may) starts it with SIGINT ignored,
    # and Python then keeps it ignored, so no KeyboardInterrupt could come.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(0.1, lambda: os.kill(os.getpid(), signal.SIGINT))
    try:
        start = time.perf_counter()
        timer.start()
        with pytest.raises(KeyboardInterrupt):
            meniscus.reconstruct(big, RADIUS, subdivide=2)
        timer.join()
    finally:
        signal.signal(signal.SIGINT, previous)
    elapsed = time.perf_counter() - start
    full = time.perf_counter()
    meniscus.reconstruct(big, RADIUS, subdivide=2)
    full = time.perf_counter() - full
    print(f"interrupted after {elapsed:.2f} s; a whole run takes {full:.2f} s")
    assert elapsed < full


def test_the_radius_is_estimated_and_checked(frame25):
    # Frame 25 of the small dam break: r = 0.012.
    r = meniscus.estimate_radius(frame25)
    assert abs(r / RADIUS - 1) < 0.1
    estimated = meniscus.reconstruct(frame25)
    given = meniscus.reconstruct(frame25, r)
    assert np.array_equal(estimated.triangles, given.triangles)
    assert np.array_equal(estimated.vertices, given.vertices)
    with pytest.raises(ValueError, match="the particles' spacing implies") as refused:
        meniscus.reconstruct(frame25, 100 * RADIUS)
    assert "one blob" in str(refused.value)
    with pytest.warns(UserWarning, match="radius_check=False silences this"):
        meniscus.reconstruct(frame25, 3 * RADIUS)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        meniscus.reconstruct(frame25, 6 * RADIUS, radius_check=False)


def test_a_radius_that_isolates_most_particles_is_refused_with_the_keyword(tmp_path):
    # The case, r at 0.1x the spacing's radius: the library's message (as the
    # CLI's), naming the keyword that forces it and no CLI flag; nothing is written.
    frame = str(DATA / "ParticleData_Fluid_25.xyz")
    out = tmp_path / "fluid.glb"
    for r, what in [(0.0012, "100% of the fluid's particles would have no neighbour"),
                    (0.0048, "of the fluid's particles would have no neighbour")]:
        with pytest.raises(ValueError) as refused:
            meniscus.reconstruct_file(frame, str(out), r)
        message = str(refused.value)
        for part in [f"a particle radius of {r} is refused", "the 0.0119", what,
                     "give about 0.0119", f"or radius_check=False to run with {r} anyway"]:
            assert part in message, (part, message)
        assert "--no-radius-check" not in message
        assert not out.exists()
        # The same words as the CLI's, but for the way to force it.
        run = subprocess.run(cli_command("reconstruct", frame, "-r", str(r), "-o", str(out)),
                             cwd=ROOT, capture_output=True, text=True)
        assert run.returncode == 2
        assert run.stderr.strip() == "error: " + message.replace("radius_check=False", "--no-radius-check")


def test_the_radius_attribute_gives_r_and_is_checked(frame25):
    n = len(frame25)
    uniform = {"pscale": np.full(n, RADIUS, dtype=np.float32)}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        by_attribute = meniscus.reconstruct(frame25, attributes=uniform)
    # pscale by default; r is its median, and the mesh is the plain run's.
    plain = meniscus.reconstruct(frame25, RADIUS, radius_check=False)
    assert np.array_equal(by_attribute.vertices, plain.vertices)
    assert np.array_equal(by_attribute.triangles, plain.triangles)
    bad = np.full(n, RADIUS, dtype=np.float32)
    bad[7] = -1.0
    with pytest.raises(ValueError, match='radius attribute "size", particle 7: radius -1.0'):
        meniscus.reconstruct(frame25, attributes={"size": bad}, radius_attribute="size")
    # Ignored with "none"; a given radius far from the median is refused.
    meniscus.reconstruct(frame25, RADIUS, attributes={"pscale": bad}, radius_attribute="none")
    with pytest.raises(ValueError, match="median of the particles' radius attribute \"pscale\""):
        meniscus.reconstruct(frame25, 100 * RADIUS, attributes=uniform)
    # Each particle meshed with its own radius: radii of 1.5 r reach farther and the
    # surface encloses more, with r (the lattice) still the given one.
    larger = np.full(n, 1.5 * RADIUS, dtype=np.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sized = meniscus.reconstruct(frame25, RADIUS, attributes={"pscale": larger})
    def volume(mesh):
        v = mesh.vertices.astype(np.float64)[mesh.triangles.astype(np.int64)]
        return np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0

    assert volume(sized) > 1.05 * volume(plain)
