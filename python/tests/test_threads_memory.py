import json
import os
import subprocess
import sys
import threading
import time

import pytest

import meniscus
from conftest import DATA, RADIUS

REPEATS = 4


def reconstruct_n(positions):
    for _ in range(REPEATS):
        meniscus.reconstruct(positions, RADIUS, threads=1)


def timed(target, threads):
    workers = [threading.Thread(target=target, args=(POSITIONS[0],)) for _ in range(threads)]
    start = time.perf_counter()
    for t in workers:
        t.start()
    for t in workers:
        t.join()
    return time.perf_counter() - start


POSITIONS = []


def test_gil_is_released_two_threads_run_at_once(frame25):
    # One worker thread each: two Python threads then run on two cores exactly when the
    # GIL is released during the work. On a machine whose other load leaves less than two
    # cores, the ratio cannot be met; the test then skips (the next test still checks
    # that the GIL is free during the work, whatever the load).
    POSITIONS[:] = [frame25]
    meniscus.reconstruct(frame25, RADIUS, threads=1)  # warm up
    tries = []
    for _ in range(3):
        one = timed(reconstruct_n, 1)
        two = timed(reconstruct_n, 2)
        tries.append((one, two))
        print(f"one thread {one:.3f} s, two threads {two:.3f} s, ratio {two / one:.2f}")
        if two < 1.6 * one:
            return
    load = os.getloadavg()[0]
    if load > (os.cpu_count() or 1):
        pytest.skip(f"machine busy (load {load:.1f} on {os.cpu_count()} cores): {tries}")
    raise AssertionError(f"two threads took >= 1.6 x one thread's time: {tries}")


def test_python_threads_run_during_reconstruction(frame25):
    # A Python thread counting in a loop needs the GIL: it counts on while the work runs
    # only if the GIL is released (held, it would count nothing).
    def count(seconds=None, stop=None, out=None):
        n = 0
        end = time.perf_counter() + seconds if seconds else None
        while (end and time.perf_counter() < end) or (stop and not stop.is_set()):
            n += 1
        if out is not None:
            out.append(n)
        return n

    alone = count(seconds=0.5) / 0.5
    stop, out = threading.Event(), []
    counter = threading.Thread(target=count, kwargs={"stop": stop, "out": out})
    counter.start()
    start = time.perf_counter()
    reconstruct_n(frame25)
    elapsed = time.perf_counter() - start
    stop.set()
    counter.join()
    during = out[0] / elapsed
    print(f"counting alone {alone:.0f}/s, during reconstruction {during:.0f}/s")
    assert during > 0.2 * alone, (alone, during)


CALLS_SCRIPT = r"""
import json, sys
import numpy as np
import meniscus

def peak_kib():
    # This process's own peak (VmHWM): ru_maxrss would start at the forking pytest's.
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM:"):
            return int(line.split()[1])

positions = np.fromfile(sys.argv[1], dtype="<f4").reshape(-1, 3)
calls, radius = int(sys.argv[2]), float(sys.argv[3])
peaks = {}
for k in range(1, calls + 1):
    mesh = meniscus.reconstruct(positions, radius)
    mesh.vertices, mesh.triangles, mesh.attributes, mesh.stats
    if k in (1, 2, 10, 50, 100, calls):
        peaks[k] = peak_kib()
# What the caller's mesh holds (merged as the getters hand it out: a little more than the
# spheres' instances take), alive while the next call works.
mesh_kib = sum(a.nbytes for a in (mesh.vertices, mesh.triangles, mesh.normals)) // 1024
print(json.dumps({"peaks": peaks, "mesh_kib": mesh_kib}))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/status")
def test_memory_does_not_grow_over_repeated_calls():
    # Issue 24: 200 calls on frame 25 in one process leave the peak RSS within 10 % of
    # the first call's, beyond the caller's own previous mesh. A fresh interpreter, since
    # the peak of this one holds the other tests'. The loop is a caller's: each mesh is
    # used and stays alive while the next call works, so from the second call on the peak
    # holds that mesh too (2.9 MiB of arrays, 5 % of the first peak), which the caller
    # keeps, not the package: it is taken off before the comparison. With glibc's
    # defaults the peak grew by about 50 %, most of it at the second call and the rest
    # within about 50 calls; with the package's settings, 7-11 % with the mesh, 2-6 %
    # without (the first call's peak is one sample: later calls' own peaks spread over
    # about 4 % with the heap's layout, even on one thread).
    calls = 200
    out = subprocess.run(
        [sys.executable, "-c", CALLS_SCRIPT, str(DATA / "ParticleData_Fluid_25.xyz"), str(calls), str(RADIUS)],
        check=True, capture_output=True, text=True,
    ).stdout
    result = json.loads(out)
    peaks = {int(k): v for k, v in result["peaks"].items()}
    first, grown, mesh = peaks[1], peaks[calls], result["mesh_kib"]
    print(f"peak RSS after the first call {first} KiB, after {calls} calls {grown} KiB "
          f"(+{100 * (grown - first) / first:.1f} %, +{100 * (grown - mesh - first) / first:.1f} % "
          f"beyond the caller's {mesh} KiB mesh); {peaks}")
    assert grown - mesh <= 1.10 * first, (peaks, mesh)
