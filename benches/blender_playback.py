"""Playback benchmark of the Blender extension (a benchmark, not a test): the time to
decode an archived frame and to swap it into the scene's objects, per frame, as the
extension's frame-change handler does it.

    bash blender/build.sh
    target/bpy-venv/bin/python benches/blender_playback.py ZIP ARCHIVE.mseq [ROUNDS]

Every frame of the archive is shown ROUNDS times (default 3) in turn (so each show
decodes: the handler skips a frame already shown); printed per frame: triangles,
droplets, decode seconds, swap seconds (median over the rounds). Goal: decode + swap
<= 0.1 s for a 1 M-triangle frame, so scrubbing feels live.
"""

import os
import statistics
import sys
import tempfile
import time

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="meniscus-bench-"))

import bpy  # noqa: E402


def main(zip_path, archive, rounds=3):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default", enable_on_install=True)
    scene_mod = sys.modules[next(m for m in sys.modules if m.endswith(".meniscus.scene"))]
    context = bpy.context
    fluid = scene_mod.load_archive(context, archive)
    drops = next(c for c in fluid.children)
    player = scene_mod.player(bpy.path.abspath(archive))
    times = {f: ([], []) for f in player.frames}
    sizes = {}
    for _ in range(rounds):
        for f in player.frames:
            start = time.perf_counter()
            (v, t, a, e), (c, r, d) = player.decode(f)
            decoded = time.perf_counter()
            scene_mod.set_fluid(fluid.data, v, t, a, e)
            scene_mod.set_droplets(drops.data, c, r, d)
            swapped = time.perf_counter()
            times[f][0].append(decoded - start)
            times[f][1].append(swapped - decoded)
            sizes[f] = (len(t), len(c))
    print(f"{archive}: {len(player.frames)} frame(s), median of {rounds} rounds")
    print("frame  triangles  droplets  decode_s  swap_s  total_s")
    for f in player.frames:
        dec, swap = statistics.median(times[f][0]), statistics.median(times[f][1])
        print(f"{f:5d}  {sizes[f][0]:9d}  {sizes[f][1]:8d}  {dec:8.3f}  {swap:6.3f}  {dec + swap:7.3f}")


if __name__ == "__main__":
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    main(args[0], args[1], int(args[2]) if len(args) > 2 else 3)
