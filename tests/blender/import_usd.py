"""Imports a meniscus USD stage of a 3-frame sequence with a gap (frames 1, 2, 4; Y up)
into Blender (bpy as a Python module) as a user would, and checks it against the PLYs
meniscus wrote for the same frames with the same options:

    python tests/blender/import_usd.py SHOT.usdc PLY_PATTERN

* `bpy.ops.wm.usd_import` gives an object `Fluid` with a Mesh Sequence Cache modifier,
  and the scene's frame range is the sequence's (1 to 4);
* at the middle frame (2) the evaluated mesh has that frame's faces and vertices (the
  PLY's), and a `velocity` point attribute (FLOAT_VECTOR) equal bit for bit to the PLY's
  `velocity_x/_y/_z`; the fixture's velocity points mostly up the stage's +Y, which the
  imported object's transform turns into Blender's +Z;
* a Cycles render with motion blur (a few pixels, one sample) runs without an error.

The stage and the PLYs are written without isolated spheres (`--isolated-spheres off`),
so that the PLY holds the fluid mesh alone. Exits non-zero on any failure.
"""

import sys
import tempfile
from pathlib import Path

import bpy
import numpy as np
from mathutils import Vector

MIDDLE = 2


def read_ply(path):
    """Face count and vertex columns of a binary little-endian meniscus PLY (float
    vertex properties, then the faces)."""
    data = Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    vertices, faces, names, in_vertex = 0, 0, [], False
    for line in data[:end].decode("ascii").splitlines():
        words = line.split()
        if words[:2] == ["element", "vertex"]:
            vertices, in_vertex = int(words[2]), True
        elif words[:2] == ["element", "face"]:
            faces, in_vertex = int(words[2]), False
        elif words[:1] == ["property"] and in_vertex:
            assert words[1] == "float", line
            names.append(words[2])
    table = np.frombuffer(data, dtype="<f4", count=vertices * len(names), offset=end)
    table = table.reshape(vertices, len(names))
    return faces, {name: table[:, k] for k, name in enumerate(names)}


def main(stage, ply_pattern):
    failures = []

    def check(ok, message):
        print(("ok   " if ok else "FAIL ") + message)
        if not ok:
            failures.append(message)

    faces, columns = read_ply(ply_pattern.replace("{}", str(MIDDLE)))
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.usd_import(filepath=stage)
    scene = bpy.context.scene
    check((scene.frame_start, scene.frame_end) == (1, 4),
          f"frame range {scene.frame_start}-{scene.frame_end} is the sequence's, 1-4")
    fluid = scene.objects.get("Fluid")
    check(fluid is not None and fluid.type == "MESH", "a mesh object 'Fluid'")
    if fluid is None:
        return failures
    modifiers = [m.type for m in fluid.modifiers]
    check("MESH_SEQUENCE_CACHE" in modifiers, f"a Mesh Sequence Cache ({modifiers})")
    scene.frame_set(MIDDLE)
    evaluated = fluid.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = evaluated.to_mesh()
    n = len(mesh.vertices)
    check(len(mesh.polygons) == faces, f"frame {MIDDLE}: {len(mesh.polygons)} faces, the PLY {faces}")
    check(n == len(columns["x"]), f"frame {MIDDLE}: {n} vertices, the PLY {len(columns['x'])}")
    attr = mesh.attributes.get("velocity")
    check(attr is not None and attr.domain == "POINT" and attr.data_type == "FLOAT_VECTOR",
          "a 'velocity' point attribute of vectors")
    if attr is not None and n == len(columns["x"]):
        values = np.empty(3 * n, dtype=np.float32)
        attr.data.foreach_get("vector", values)
        values = values.reshape(n, 3)
        ply = np.stack([columns[f"velocity_{c}"] for c in "xyz"], axis=1)
        check(np.array_equal(values.view(np.uint32), ply.view(np.uint32)),
              "velocity equals the PLY's, bit for bit")
        up = fluid.matrix_world.to_3x3() @ Vector(values.mean(axis=0).tolist())
        check(up.z > 1.5 and abs(up.x) < 0.5 and abs(up.y) < 0.5,
              f"the mean velocity points up Blender's +Z ({tuple(round(c, 3) for c in up)})")
    evaluated.to_mesh_clear()
    render_with_motion_blur(scene, check)
    return failures


def render_with_motion_blur(scene, check):
    """A tiny Cycles render of the middle frame with motion blur on."""
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(camera)
    camera.location = (0.0, -6.0, 2.0)
    camera.rotation_euler = (1.25, 0.0, 0.0)
    scene.camera = camera
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 1
    scene.cycles.device = "CPU"
    scene.render.use_motion_blur = True
    scene.render.resolution_x, scene.render.resolution_y = 32, 24
    with tempfile.TemporaryDirectory() as out:
        scene.render.filepath = str(Path(out) / "frame.png")
        try:
            bpy.ops.render.render(write_still=True)
            check(Path(scene.render.filepath).exists(), "a Cycles render with motion blur")
        except RuntimeError as e:
            check(False, f"a Cycles render with motion blur: {e}")


if __name__ == "__main__":
    failed = main(sys.argv[-2], sys.argv[-1])
    if failed:
        print(f"{len(failed)} check(s) failed")
        sys.exit(1)
    print("Blender imports the USD stage")
