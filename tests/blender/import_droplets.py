"""Imports a meniscus USD stage whose isolated particles are a point cloud (the default,
`/Surface/Droplets`) into Blender (bpy as a Python module) as a user would, and checks that
the droplets arrive ready for motion blur:

    python tests/blender/import_droplets.py SHOT.usdc RADIUS

* `bpy.ops.wm.usd_import` gives an object `Droplets` of type POINTCLOUD beside the fluid;
* at the frame of the sequence with the most droplets, the evaluated point cloud has a
  `velocity` point attribute (FLOAT_VECTOR, not all zero) and a `radius` attribute equal
  to RADIUS (the run's particle radius: the stage's widths are 2 r);
* a small Cycles render of the droplets alone (the fluid hidden) with motion blur differs
  from the same render without it on the droplets' pixels (the issue this replaces: the
  point instancer's velocities were dropped, and both renders were the same).

Exits non-zero on any failure.
"""

import sys
import tempfile
from pathlib import Path

import bpy
import numpy as np
from mathutils import Vector


def evaluated_points(obj):
    """(positions, velocity, radius) arrays of the evaluated point cloud at this frame."""
    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    cloud = evaluated.data
    n = len(cloud.points)
    out = []
    for name, width in (("position", 3), ("velocity", 3), ("radius", 1)):
        attr = cloud.attributes.get(name)
        if attr is None or n == 0:
            out.append(None)
            continue
        values = np.empty(width * n, dtype=np.float32)
        attr.data.foreach_get("vector" if width == 3 else "value", values)
        out.append(values.reshape(n, width) if width == 3 else values)
    return n, out


def render(scene, blur, path):
    scene.render.use_motion_blur = blur
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(str(path))
    pixels = np.array(image.pixels[:], dtype=np.float32).reshape(-1, 4)
    bpy.data.images.remove(image)
    return pixels


def main(stage, radius):
    failures = []

    def check(ok, message):
        print(("ok   " if ok else "FAIL ") + message)
        if not ok:
            failures.append(message)

    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.usd_import(filepath=stage)
    scene = bpy.context.scene
    droplets = scene.objects.get("Droplets")
    check(droplets is not None and droplets.type == "POINTCLOUD",
          f"a point cloud object 'Droplets' ({droplets and droplets.type})")
    if droplets is None or droplets.type != "POINTCLOUD":
        return failures
    best, best_frame = 0, scene.frame_start
    for frame in range(scene.frame_start, scene.frame_end + 1):
        scene.frame_set(frame)
        n, _ = evaluated_points(droplets)
        if n > best:
            best, best_frame = n, frame
    check(best > 0, f"droplets at frame {best_frame}: {best}")
    if best == 0:
        return failures
    scene.frame_set(best_frame)
    n, (positions, velocity, radii) = evaluated_points(droplets)
    check(velocity is not None and np.abs(velocity).max() > 0,
          f"frame {best_frame}: a non-zero 'velocity' on the droplets")
    check(radii is not None and np.allclose(radii, radius, rtol=1e-5),
          f"frame {best_frame}: 'radius' {radii[:3] if radii is not None else None} is the run's r = {radius}")
    # The droplets alone, framed by a camera looking at their bounding box.
    fluid = scene.objects.get("Fluid")
    if fluid is not None:
        fluid.hide_render = True
    world = droplets.matrix_world
    points = [world @ Vector(p.tolist()) for p in positions]
    lo = Vector([min(p[k] for p in points) for k in range(3)])
    hi = Vector([max(p[k] for p in points) for k in range(3)])
    centre, size = (lo + hi) / 2, max((hi - lo).length, 10 * radius)
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
    with tempfile.TemporaryDirectory() as out:
        still = render(scene, False, Path(out) / "still.png")
        blurred = render(scene, True, Path(out) / "blur.png")
    covered = (still[:, 3] > 0.01) | (blurred[:, 3] > 0.01)
    changed = np.abs(still - blurred).max(axis=1) > 0.05
    check(covered.sum() > 0, f"the droplets cover {covered.sum()} pixels")
    moved = int((changed & covered).sum())
    check(moved >= max(5, covered.sum() // 10),
          f"motion blur changes {moved} of the droplets' {covered.sum()} pixels")
    return failures


if __name__ == "__main__":
    failed = main(sys.argv[-2], float(sys.argv[-1]))
    if failed:
        print(f"{len(failed)} check(s) failed")
        sys.exit(1)
    print("Blender imports the droplets as a point cloud with velocity")
