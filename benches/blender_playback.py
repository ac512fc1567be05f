"""Playback benchmark of the Blender extension (a benchmark, not a test): the time to
decode an archived frame and to swap it into the scene's objects, per frame, as the
extension's frame-change handler does it (``ArchivePlayer.decode``, then
``scene.swap``), step by step.

    bash blender/build.sh
    target/bpy-venv/bin/python benches/blender_playback.py ZIP ARCHIVE.mseq [ROUNDS]

Every frame of the archive is shown ROUNDS times (default 5) in turn (so each show
decodes). Printed per frame: triangles, droplets, then the median wall time and the
median CPU time of the process (``time.process_time``: all its threads, which other
jobs on the machine do not inflate as they do wall time) of each step: ``decode``
(``Archive[n]``: read, zstd, Loop subdivision of the stored control mesh, normals),
``arrays`` (``Mesh.fluid()`` and the droplets' arrays), ``edges``
(``Mesh.fluid_edges()``), ``swap`` (``set_fluid`` and ``set_droplets``) and the total;
and the load average. Goal: decode + swap <= 0.1 s for a 1 M-triangle frame, so
scrubbing feels live.
"""

import os
import statistics
import sys
import tempfile
import time

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="meniscus-bench-"))

import bpy  # noqa: E402

STEPS = ("decode", "arrays", "edges", "swap", "total")


def main(zip_path, archive, rounds=5):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default", enable_on_install=True)
    scene_mod = sys.modules[next(m for m in sys.modules if m.endswith(".meniscus.scene"))]
    fluid = scene_mod.load_archive(bpy.context, archive)
    drops = next(c for c in fluid.children)
    player = scene_mod.player(bpy.path.abspath(archive))
    times = {f: {s: [] for s in STEPS} for f in player.frames}
    sizes = {}
    for _ in range(rounds):
        for f in player.frames:
            marks = [(time.perf_counter(), time.process_time())]
            mesh = player.archive[f]
            marks.append((time.perf_counter(), time.process_time()))
            vertices, triangles, _normals, attributes = mesh.fluid()
            centres, radii = mesh.sphere_centers, mesh.sphere_scales * mesh.sphere_radius
            drop_attributes = mesh.sphere_attributes
            marks.append((time.perf_counter(), time.process_time()))
            edges = mesh.fluid_edges()
            marks.append((time.perf_counter(), time.process_time()))
            scene_mod.set_fluid(fluid.data, vertices, triangles, attributes, edges)
            scene_mod.set_droplets(drops.data, centres, radii, drop_attributes)
            marks.append((time.perf_counter(), time.process_time()))
            for s, (a, b) in zip(STEPS, zip(marks, marks[1:])):
                times[f][s].append((b[0] - a[0], b[1] - a[1]))
            times[f]["total"].append((marks[-1][0] - marks[0][0], marks[-1][1] - marks[0][1]))
            sizes[f] = (len(triangles), len(centres))
            del mesh, vertices, triangles, attributes, edges
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"{archive}: {len(player.frames)} frame(s), median of {rounds} rounds, wall / CPU ms, load average {load}")
    print("frame  triangles  droplets" + "".join(f"  {s:>13s}" for s in STEPS))
    for f in player.frames:
        cells = []
        for s in STEPS:
            wall = statistics.median(w for w, _ in times[f][s])
            cpu = statistics.median(c for _, c in times[f][s])
            cells.append(f"{1e3 * wall:6.1f} /{1e3 * cpu:5.1f}")
        print(f"{f:5d}  {sizes[f][0]:9d}  {sizes[f][1]:8d}  " + "  ".join(cells))


if __name__ == "__main__":
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    main(args[0], args[1], int(args[2]) if len(args) > 2 else 5)
