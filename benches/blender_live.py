"""Live meshing benchmark of the Blender extension (a benchmark, not a test): the time
from a frame change to the frame's surface in the scene, per preset, as the extension's
frame-change handler does it in live mode: read the frame's particle file, mesh it
(``meniscus.reconstruct``), swap it into the fluid and droplets objects; and the same
from the cache (scrubbing back to a frame meshed before).

    bash blender/build.sh
    target/bpy-venv/bin/python benches/blender_live.py ZIP PATTERN [ROUNDS] [PRESETS]

PATTERN is a ``{}`` particle sequence (e.g. the shipped
``datasets/dambreak_small/ParticleData_Fluid_{}.xyz``); every frame is meshed ROUNDS
times (default 3) per preset, the cache emptied before each; PRESETS defaults to
``PREVIEW,STEADY`` (the live defaults for the viewport and for renders). Printed per
preset and frame: triangles, droplets, the meshing's seconds (read + reconstruct +
edges), the whole show's seconds (meshing + swap), and a cache hit's seconds (medians).
"""

import os
import statistics
import sys
import tempfile
import time

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="meniscus-bench-"))

import bpy  # noqa: E402


def main(zip_path, pattern, rounds=3, presets="PREVIEW,STEADY"):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default", enable_on_install=True)
    scene_mod = sys.modules[next(m for m in sys.modules if m.endswith(".meniscus.scene"))]
    scene = bpy.context.scene
    scene.meniscus.source = pattern
    fluid = scene_mod.start_live(bpy.context, pattern)
    (mesher,) = scene_mod._meshers.values()
    report = scene_mod.live_report
    print(f"{pattern}: {len(mesher.sequence.frames)} frame(s), radius {mesher.radius:.5g}, "
          f"median of {rounds} rounds; {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}")
    print("preset   frame  triangles  droplets  mesh_s  show_s  cached_s")
    for preset in presets.split(","):
        scene.meniscus.live_viewport_preset = preset
        for f in mesher.sequence.frames:
            mesh, show, hit = [], [], []
            for _ in range(rounds):
                mesher.clear()
                fluid.pop("meniscus_live_shown", None)
                start = time.perf_counter()
                scene_mod.show_live(scene, fluid, frame=f)
                show.append(time.perf_counter() - start)
                assert report["error"] is None and not report["cached"], report
                mesh.append(report["mesh_seconds"])
                fluid.pop("meniscus_live_shown", None)
                start = time.perf_counter()
                scene_mod.show_live(scene, fluid, frame=f)
                hit.append(time.perf_counter() - start)
                assert report["cached"], report
            print(f"{preset:8s} {f:5d}  {report['triangles']:9d}  {report['droplets']:8d}  "
                  f"{statistics.median(mesh):6.3f}  {statistics.median(show):6.3f}  {statistics.median(hit):8.4f}")
    print(f"load average after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    main(args[0], args[1], int(args[2]) if len(args) > 2 else 3, args[3] if len(args) > 3 else "PREVIEW,STEADY")
