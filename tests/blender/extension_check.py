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
* live mode on the same frames (plus a broken frame file and the gaps between frames):
  a wrong radius is refused as the bake refuses it; at each frame the live fluid's faces
  plus the droplets' sphere faces equal the CLI's PLY of that frame with the viewport
  preset (``WORK/cli_preview_{}.ply``), the radius is the estimate; a frame without a
  file (in a gap, before the first, after the last) holds the file playback would hold
  (the faces of its frame's PLY, nothing meshed again) and the panel names it; a frame
  whose file fails to read (and the gap after it) clears the fluid and is reported,
  nothing raised; going back to a meshed frame is a cache hit (no meshing); a file
  written after Live is found once a look for files is due; a small Cycles
  render meshes with the render preset (the render's evaluated fluid has the faces of
  the CLI's steady PLY, ``WORK/cli_{}.ply``) and the viewport preset is back after it;
  the handler runs on after the blend file is saved and opened again; Stop Live removes
  the live objects and frame changes mesh nothing more;
* the velocity sequence baked and played: ``velocity`` on the fluid and on the droplets'
  point cloud, and a small Cycles render of the droplets with motion blur differs from
  the same render without it on the droplets' pixels.

Exits non-zero on any failure.
"""

import os
import sys
import tempfile
import time
import types
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

    live(work, dambreak, frames)
    scene = bpy.context.scene
    settings = scene.meniscus
    scene_mod = sys.modules[next(m for m in sys.modules if m.endswith(".meniscus.scene"))]

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

    # Live on the same sequence: velocity on its fluid and droplets, as in playback.
    bpy.ops.meniscus.live_start()
    (live_fluid,) = scene_mod.live_objects(scene)
    attr = live_fluid.data.attributes.get("velocity")
    live_points, live_velocity, _ = droplet_points(live_fluid)
    check(attr is not None and attr.data_type == "FLOAT_VECTOR" and attr.domain == "POINT" and len(live_points) > 0
          and live_velocity is not None and np.abs(live_velocity).max() > 0,
          f"live frame {scene.frame_current}: 'velocity' on the live fluid and on its {len(live_points)} droplets")
    bpy.ops.meniscus.live_stop()

    if len(points) and world is not None:
        render_blur(scene, fluid, points, world)


class Layout:
    """Stands for the panel's layout: records the labels and operators drawn."""

    def __init__(self, texts):
        self.texts, self.alert = texts, False

    def box(self):
        return self

    def row(self):
        return self

    def label(self, text="", icon="NONE"):
        self.texts.append(text)

    def operator(self, idname, **_):
        self.texts.append(idname)

    def prop(self, *_, **__):
        pass

    def progress(self, **_):
        pass


def panel_texts():
    """What the panel's draw shows (labels and operators), drawn into a ``Layout``."""
    ui = sys.modules[next(m for m in sys.modules if m.endswith(".meniscus.ui"))]
    texts = []
    ui.MENISCUS_PT_panel.draw(types.SimpleNamespace(layout=Layout(texts)), bpy.context)
    return texts


def live_faces(fluid):
    points, _, _ = droplet_points(fluid)
    return len(fluid.data.polygons) + 320 * len(points), len(fluid.data.polygons), len(points)


def live(work, dambreak, frames):
    """Live mode over the dam-break frames (see the module's docstring)."""
    scene_mod = sys.modules[next(m for m in sys.modules if m.endswith(".meniscus.scene"))]
    scene = bpy.context.scene
    settings = scene.meniscus
    for o in list(scene.objects):
        bpy.data.objects.remove(o)
    # The same frames in a folder of their own, with a frame whose file is broken.
    folder = work / "live"
    folder.mkdir()
    for f in frames:
        (folder / f"f_{f}.xyz").write_bytes(Path(dambreak.replace("{}", str(f))).read_bytes())
    broken = frames[0] + 2
    (folder / f"f_{broken}.xyz").write_bytes(b"not particles")
    settings.source = str(folder / "f_{}.xyz")
    settings.live_viewport_preset, settings.live_render_preset = "PREVIEW", "STEADY"
    report = scene_mod.live_report

    settings.radius = settings.estimated_radius / 30
    scene.frame_set(frames[0])
    try:
        bpy.ops.meniscus.live_start()
        check(False, "live: a radius 30x too small fails the Live operator")
    except RuntimeError:
        pass
    check("is refused" in settings.live_status and "tick Force radius" in settings.live_status
          and settings.live_status.startswith(str(folder / f"f_{frames[0]}.xyz")),
          f"live: a radius 30x too small is refused as the bake refuses it: {settings.live_status!r}")
    check(not scene_mod.live_objects(scene), "live: and no live object is made")
    check(settings.live_status in panel_texts() and "meniscus.live_start" in panel_texts(),
          "live: the panel shows the refusal under its Live button")
    settings.radius = 0.0

    bpy.ops.meniscus.live_start()
    fluids = scene_mod.live_objects(scene)
    check(len(fluids) == 1 and fluids[0].type == "MESH" and settings.live_status == "",
          f"live: Live makes one fluid object ({[o.name for o in fluids]})")
    fluid = fluids[0]
    (mesher,) = scene_mod._meshers.values()
    check(mesher.stats["meshed"] == 1 and mesher.stats["hits"] == 1,
          f"live: the first frame is meshed once (the radius check) and shown from the cache ({mesher.stats})")
    check(mesher.radius == np.float32(settings.estimated_radius),
          f"live: the radius {mesher.radius:.6f} is the panel's estimate {settings.estimated_radius:.6f}")
    check((scene.frame_start, scene.frame_end) == (frames[0], frames[-1]),
          f"live: the scene range {scene.frame_start}-{scene.frame_end} is the sequence's")
    for f in frames:
        scene.frame_set(f)
        faces, fl, drops = live_faces(fluid)
        want = ply_faces(str(work / f"cli_preview_{f}.ply"))
        check(faces == want and report["frame"] == f and report["preset"] == "PREVIEW" and report["error"] is None,
              f"live frame {f} (viewport preset {report['preset']}): {fl} faces + {drops} droplets = {faces}, "
              f"the CLI's PLY with that preset {want}")
        if f == frames[1]:
            check(len(fluid.data.edges) > 0 and not fluid.data.copy().validate(),
                  f"live frame {f}: the swapped-in mesh (with the library's edges) is valid as it is")

    # Frames without a file hold the file before them (the first before the sequence), as
    # playback holds an archive's frames, and the panel says which: after the last
    # (the fluid kept as it is), before the first (from the cache), in a gap.
    for f, held in ((frames[-1] + 1, frames[-1]), (frames[0] - 1, frames[0]), (frames[0] + 1, frames[0])):
        meshed = mesher.stats["meshed"]
        scene.frame_set(f)
        faces, fl, drops = live_faces(fluid)
        want = ply_faces(str(work / f"cli_preview_{held}.ply"))
        label = f"frame {f}: no file, shows frame {held} (Preview): {fl} triangles, {drops} droplets, "
        shown = [t for t in panel_texts() if t.startswith("frame ")]
        check(faces == want and report["frame"] == f and report.get("held") == held and report["error"] is None
              and mesher.stats["meshed"] == meshed and any(t.startswith(label) for t in shown),
              f"live frame {f} (no file) holds frame {held}: {fl} faces + {drops} droplets = {faces}, the CLI's "
              f"PLY of frame {held} {want}, nothing meshed ({mesher.stats['meshed'] - meshed}); the panel: {shown}")

    # A file that exists but is broken is an error, not a gap: its frame and the gap after
    # it are reported, the fluid cleared, nothing raised.
    for f, where in ((broken, f"frame {broken}: "), (broken + 1, f"frame {broken + 1} (no file; frame {broken} held): ")):
        try:
            scene.frame_set(f)
            raised = None
        except Exception as e:  # the handler must not let it out
            raised = e
        faces, fl, drops = live_faces(fluid)
        error = report["error"] or ""
        check(raised is None and error.startswith(where) and f"f_{broken}.xyz" in error and faces == 0
              and error in panel_texts(),
              f"live frame {f}: reported in the panel ({error!r}), the fluid cleared ({fl} faces, "
              f"{drops} droplets), nothing raised ({raised!r})")

    # Back to a meshed frame: from the cache.
    meshed, hits = mesher.stats["meshed"], mesher.stats["hits"]
    scene.frame_set(frames[0])
    faces, _, _ = live_faces(fluid)
    check(mesher.stats["hits"] == hits + 1 and mesher.stats["meshed"] == meshed and report["cached"]
          and faces == ply_faces(str(work / f"cli_preview_{frames[0]}.ply")),
          f"live: back to frame {frames[0]}, a cache hit ({mesher.stats['hits'] - hits} hit, "
          f"{mesher.stats['meshed'] - meshed} meshed; {mesher.stats['cached_frames']} frames, "
          f"{mesher.stats['cached_bytes'] / 2**20:.1f} MiB cached), {faces} faces")

    # A file written after Live was pressed: found when a frame without a known file
    # looks for the files again, at most once in rescan_seconds.
    late = frames[-1] + 4
    (folder / f"f_{late}.xyz").write_bytes(Path(dambreak.replace("{}", str(frames[1]))).read_bytes())
    mesher.rescan_seconds = 3600.0  # no look due
    scene.frame_set(late)
    faces, _, _ = live_faces(fluid)
    check(report.get("held") == frames[-1] and faces == ply_faces(str(work / f"cli_preview_{frames[-1]}.ply")),
          f"live: frame {late}, its file written after Live, holds frame {report.get('held')} while no look is "
          f"due ({faces} faces)")
    mesher.rescan_seconds = 0.5
    time.sleep(0.5)
    meshed = mesher.stats["meshed"]
    scene.frame_set(late)
    faces, _, _ = live_faces(fluid)
    check(report["frame"] == late and report.get("held") is None and report["error"] is None
          and mesher.stats["meshed"] == meshed + 1
          and faces == ply_faces(str(work / f"cli_preview_{frames[1]}.ply")),
          f"live: frame {late} meshes its new file (a copy of frame {frames[1]}: {faces} faces) once a look is due")

    # A render meshes with the render preset; the viewport preset comes back after it.
    f = frames[1]
    scene.frame_set(f)
    seen = []

    def on_post(scene_, depsgraph):  # the render's evaluated fluid
        if depsgraph is not None and depsgraph.mode == "RENDER":
            evaluated = fluid.evaluated_get(depsgraph)
            points = [i for i in depsgraph.object_instances if i.object.type == "POINTCLOUD"]
            seen.append((len(evaluated.data.polygons), sum(len(i.object.data.points) for i in points),
                         report["preset"]))

    bpy.app.handlers.frame_change_post.append(on_post)
    camera = bpy.data.objects.new("Live camera", bpy.data.cameras.new("Live camera"))
    scene.collection.objects.link(camera)
    camera.location, camera.rotation_euler = (0.3, -3.0, 0.3), (1.5707963, 0.0, 0.0)
    scene.camera = camera
    scene.render.engine = "CYCLES"
    scene.cycles.samples, scene.cycles.device = 1, "CPU"
    scene.render.resolution_x, scene.render.resolution_y = 16, 16
    with tempfile.TemporaryDirectory() as out:
        scene.render.filepath = os.path.join(out, "live.png")
        bpy.ops.render.render(write_still=True)
    bpy.app.handlers.frame_change_post.remove(on_post)
    want = ply_faces(str(work / f"cli_{f}.ply"))
    rendered = [fl + 320 * drops for fl, drops, _ in seen]
    check(bool(seen) and all(r == want and p == "STEADY" for r, (_, _, p) in zip(rendered, seen)),
          f"live: the render of frame {f} meshed with the render preset: its evaluated fluid {seen} "
          f"makes {rendered} faces, the CLI's steady PLY {want}")
    faces, _, _ = live_faces(fluid)
    check(not scene_mod.rendering() and report["preset"] == "PREVIEW" and report["cached"]
          and faces == ply_faces(str(work / f"cli_preview_{f}.ply")),
          f"live: after the render the viewport preset is back, from the cache ({faces} faces)")
    scene.camera = None
    bpy.data.objects.remove(camera)

    # The handler survives saving and opening the file again.
    blend = str(work / "live.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    bpy.ops.wm.open_mainfile(filepath=blend)
    scene = bpy.context.scene
    fluid = scene_mod.live_objects(scene)[0]
    f = frames[2]
    scene.frame_set(f)
    faces, _, _ = live_faces(fluid)
    check(report["frame"] == f and faces == ply_faces(str(work / f"cli_preview_{f}.ply")),
          f"live: after the file is opened again, frame {f} is meshed ({faces} faces)")

    # Stop Live: the objects go, frame changes mesh nothing.
    check("meniscus.live_stop" in panel_texts(), "live: the panel offers Stop Live while live")
    bpy.ops.meniscus.live_stop()
    scene.frame_set(frames[0])
    check(not scene_mod.live_objects(scene) and not scene_mod._meshers and report["frame"] is None
          and not any(o.name.endswith("live") for o in bpy.data.objects),
          "live: Stop Live removes the live objects; a frame change meshes nothing")


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
    print("the Blender extension bakes, plays back, meshes live and blurs")
