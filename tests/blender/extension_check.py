"""The Blender extension as a user meets it, in Blender 5.0.1 (bpy as a Python module):

    python tests/blender/extension_check.py ZIP WORK DAMBREAK_PATTERN VELOCITY_PATTERN

* the zip built by blender/build.sh installs and enables with
  ``bpy.ops.extensions.package_install_files`` (its bundled meniscus wheel with it);
* the panel's settings: picking the dam-break frames (a ``{}`` pattern) shows the
  estimated radius; a radius 10x too small is refused with the estimate in the message;
* ``bpy.ops.meniscus.bake()`` bakes the frames to a ``.mseq``; the archive equals the
  CLI's (``WORK/cli.mseq``, written by the caller with the same settings) byte for byte;
* the archive plays back as one animated object: at each frame its faces plus the
  droplets' sphere faces equal the CLI's PLY of that frame (``WORK/cli_{}.ply``), and the
  scene's range is the archive's;
* a bake on its own thread leaves the main thread free (it runs on while the bake
  works) and stops when cancelled, the archive keeping the frames done;
* the velocity sequence baked and played: ``velocity`` on the fluid and on the droplets'
  point cloud, and a small Cycles render of the droplets with motion blur differs from
  the same render without it on the droplets' pixels.

Exits non-zero on any failure.
"""

import os
import sys
import tempfile
import time
from pathlib import Path

import bpy
import numpy as np
from mathutils import Vector

failures = []


def check(ok, message):
    print(("ok   " if ok else "FAIL ") + message, flush=True)
    if not ok:
        failures.append(message)
    return ok


def ply_faces(path):
    with open(path, "rb") as f:
        head = f.read(4096).split(b"end_header")[0].decode("ascii")
    return next(int(line.split()[2]) for line in head.splitlines() if line.startswith("element face"))


def droplet_points(fluid):
    """The droplets' evaluated point cloud (positions, velocity or None)."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    for instance in depsgraph.object_instances:
        data = instance.object.data
        if instance.object.type == "POINTCLOUD" and instance.object.original.parent == fluid:
            n = len(data.points)
            pos = np.empty(3 * n, dtype=np.float32)
            data.attributes["position"].data.foreach_get("vector", pos)
            vel = data.attributes.get("velocity")
            v = None
            if vel is not None:
                v = np.empty(3 * n, dtype=np.float32)
                vel.data.foreach_get("vector", v)
                v = v.reshape(n, 3)
            return pos.reshape(n, 3), v, instance.matrix_world.copy()
    return np.zeros((0, 3), np.float32), None, None


def main(zip_path, work, dambreak, velocity_pattern):
    work = Path(work)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    result = bpy.ops.extensions.package_install_files(
        filepath=zip_path, repo="user_default", enable_on_install=True)
    check(result == {"FINISHED"}, f"the extension zip installs and enables ({result})")
    check(hasattr(bpy.ops.meniscus, "bake") and hasattr(bpy.types.Scene, "meniscus"),
          "its operators and settings are registered")
    import meniscus  # the bundled wheel

    check(hasattr(meniscus, "reconstruct_file"), f"the bundled wheel imports ({meniscus.__file__})")
    scene = bpy.context.scene
    settings = scene.meniscus

    # Radius: estimated on picking the sequence; a wrong one refused.
    settings.source = dambreak
    check(abs(settings.estimated_radius - 0.012) < 0.002,
          f"the estimated radius {settings.estimated_radius:.5f} is the dam break's (0.012)")
    settings.output = str(work / "wrong.mseq")
    settings.radius = settings.estimated_radius / 30
    try:
        bpy.ops.meniscus.bake()
        check(False, "a radius 30x too small fails the bake operator")
    except RuntimeError as e:
        print(f"     (the operator reported: {e})")
    estimate = str(np.float32(settings.estimated_radius))
    check("is refused" in settings.status and estimate in settings.status
          and "tick Force radius to run with" in settings.status and "radius_check" not in settings.status,
          f"a radius 30x too small is refused with the library's message, naming the estimate {estimate} "
          f"and the Force radius box: {settings.status!r}")
    check(not (work / "wrong.mseq").exists(), "and nothing is written")
    settings.radius = 0.0

    # Bake through the operator; the archive is the CLI's.
    settings.output = str(work / "ext.mseq")
    bpy.ops.meniscus.bake()
    check((work / "ext.mseq").read_bytes() == (work / "cli.mseq").read_bytes(),
          f"the baked archive equals the CLI's byte for byte ({settings.status})")
    fluid = next((o for o in scene.objects if o.get("meniscus_archive") and o["meniscus_archive"] != "droplets"), None)
    check(fluid is not None and fluid.type == "MESH", "the bake loads the archive as a mesh object")
    archive = meniscus.Archive(str(work / "ext.mseq"))
    frames = sorted(archive.frames)
    check((scene.frame_start, scene.frame_end) == (frames[0], frames[-1]),
          f"the scene range {scene.frame_start}-{scene.frame_end} is the archive's {frames[0]}-{frames[-1]}")
    for f in frames:
        scene.frame_set(f)
        mesh = fluid.data
        points, _, _ = droplet_points(fluid)
        template = 320  # the CLI's icosphere level 2
        faces = len(mesh.polygons) + template * len(points)
        want = ply_faces(str(work / f"cli_{f}.ply"))
        check(faces == want, f"frame {f}: {len(mesh.polygons)} faces + {len(points)} droplets = {faces}, the CLI's PLY {want}")
        if f == frames[0]:
            check(len(mesh.edges) > 0 and not mesh.copy().validate(),
                  f"frame {f}: the swapped-in mesh (with the library's {len(mesh.edges)} edges) is valid as it is")
    # Between two baked frames the last one before is held.
    if len(frames) > 1 and frames[1] - frames[0] > 1:
        scene.frame_set(frames[0] + 1)
        check(fluid["meniscus_frame"] == frames[0], f"frame {frames[0] + 1} shows frame {frames[0]}")

    # A bake on its own thread: the main thread runs on; cancel keeps the frames done.
    core = sys.modules[next(m for m in sys.modules if m.endswith(".meniscus.core"))]
    seq = core.resolve_sequence(dambreak)
    job = core.BakeJob(seq, str(work / "cancel.mseq"))
    job.start()
    ticks, start = 0, time.monotonic()
    while job.done == 0 and time.monotonic() - start < 120:
        time.sleep(0.01)
        ticks += 1
    job.cancel()
    job.join(300)
    check(ticks > 3, f"the main thread ran {ticks} times while the first frame baked")
    check(job.finished and job.cancelled and job.error is None, f"the bake stopped on cancel ({job.error})")
    held = len(meniscus.Archive(str(work / "cancel.mseq")).frames)
    check(1 <= held < len(seq.frames), f"the cancelled cache keeps its {held} finished frame(s) of {len(seq.frames)}")

    # Velocity and motion blur, on a sequence with velocity.
    for o in list(scene.objects):
        bpy.data.objects.remove(o)
    settings.source = velocity_pattern
    settings.output = str(work / "velocity.mseq")
    bpy.ops.meniscus.bake()
    fluid = next(o for o in scene.objects if o.get("meniscus_archive") and o["meniscus_archive"] != "droplets")
    best, best_frame = -1, scene.frame_start
    for f in range(scene.frame_start, scene.frame_end + 1):
        scene.frame_set(f)
        n = len(droplet_points(fluid)[0])
        if n > best:
            best, best_frame = n, f
    scene.frame_set(best_frame)
    attr = fluid.data.attributes.get("velocity")
    check(attr is not None and attr.data_type == "FLOAT_VECTOR" and attr.domain == "POINT",
          "a 'velocity' point attribute on the fluid")
    if attr is not None:
        v = np.empty(3 * len(fluid.data.vertices), dtype=np.float32)
        attr.data.foreach_get("vector", v)
        up = fluid.matrix_world.to_3x3() @ Vector(v.reshape(-1, 3).mean(axis=0).tolist())
        check(up.z > 1.0, f"the fluid's mean velocity points up Blender's +Z ({tuple(round(c, 2) for c in up)})")
    points, velocity, world = droplet_points(fluid)
    check(len(points) > 0, f"frame {best_frame}: {len(points)} droplets as a point cloud")
    check(velocity is not None and np.abs(velocity).max() > 0, "a non-zero 'velocity' on the droplets")
    if len(points) and world is not None:
        render_blur(scene, fluid, points, world)


def render_blur(scene, fluid, points, world):
    fluid.hide_render = True
    pts = [world @ Vector(p.tolist()) for p in points]
    lo = Vector([min(p[k] for p in pts) for k in range(3)])
    hi = Vector([max(p[k] for p in pts) for k in range(3)])
    centre, size = (lo + hi) / 2, max((hi - lo).length, 0.5)
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(camera)
    camera.location = centre + Vector((0.0, -2.0 * size, 0.0))
    camera.rotation_euler = (1.5707963, 0.0, 0.0)
    scene.camera = camera
    light = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    scene.collection.objects.link(light)
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 4
    scene.cycles.device = "CPU"
    scene.render.resolution_x, scene.render.resolution_y = 96, 96
    scene.render.film_transparent = True
    images = []
    with tempfile.TemporaryDirectory() as out:
        for blur in (False, True):
            scene.render.use_motion_blur = blur
            scene.render.filepath = os.path.join(out, f"blur{int(blur)}.png")
            bpy.ops.render.render(write_still=True)
            image = bpy.data.images.load(scene.render.filepath)
            images.append(np.array(image.pixels[:], dtype=np.float32).reshape(-1, 4))
            bpy.data.images.remove(image)
    still, blurred = images
    covered = (still[:, 3] > 0.01) | (blurred[:, 3] > 0.01)
    moved = int((covered & (np.abs(still - blurred).max(axis=1) > 0.05)).sum())
    check(covered.sum() > 0, f"the droplets cover {covered.sum()} pixels")
    check(moved >= max(5, covered.sum() // 10), f"motion blur changes {moved} of the droplets' {covered.sum()} pixels")


if __name__ == "__main__":
    main(*sys.argv[-4:])
    if failures:
        print(f"{len(failures)} check(s) failed")
        sys.exit(1)
    print("the Blender extension bakes, plays back and blurs")
