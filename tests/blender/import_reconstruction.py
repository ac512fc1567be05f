"""Imports a real reconstruction with velocity into Blender (bpy as a Python module), as a
user would for motion blur, and checks the velocity on the fluid mesh against the PLY
that meniscus wrote for the same run.

    python tests/blender/import_reconstruction.py SURFACE.glb SURFACE.ply

The GLB's fluid object must carry a point attribute `_VELOCITY` (FLOAT_VECTOR) with one
value per vertex, equal bit for bit to the `velocity_x/_y/_z` columns of the PLY's first
vertices (the PLY lists the fluid's vertices first, then the spheres'), and the velocity
must be a real field: finite, not all zero. Exits non-zero on any failure.
"""

import sys

import bpy
import numpy as np


def read_ply(path):
    """Vertex columns of a binary little-endian PLY of float vertex properties."""
    data = open(path, "rb").read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    vertices, names, in_vertex = 0, [], False
    for line in header:
        words = line.split()
        if words[:2] == ["element", "vertex"]:
            vertices, in_vertex = int(words[2]), True
        elif words[:1] == ["element"]:
            in_vertex = False
        elif words[:1] == ["property"] and in_vertex:
            assert words[1] == "float", line
            names.append(words[2])
    table = np.frombuffer(data, dtype="<f4", count=vertices * len(names), offset=end)
    table = table.reshape(vertices, len(names))
    return {name: table[:, k] for k, name in enumerate(names)}


def main(glb, ply):
    failures = []

    def check(ok, message):
        print(("ok   " if ok else "FAIL ") + message)
        if not ok:
            failures.append(message)

    columns = read_ply(ply)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=glb)
    objects = {o.name: o for o in bpy.context.scene.objects if o.type == "MESH"}
    fluid = objects.get("fluid")
    check(fluid is not None, f"an object named 'fluid' ({sorted(objects)})")
    if fluid is not None:
        mesh = fluid.data
        n = len(mesh.vertices)
        print(f"fluid: {n} vertices, attributes {sorted(mesh.attributes.keys())}")
        attr = mesh.attributes.get("_VELOCITY")
        check(attr is not None, "the fluid carries _VELOCITY")
        if attr is not None:
            check(attr.domain == "POINT" and attr.data_type == "FLOAT_VECTOR",
                  f"_VELOCITY is a point vector ({attr.domain}, {attr.data_type})")
            values = np.empty(len(attr.data) * 3, dtype=np.float32)
            attr.data.foreach_get("vector", values)
            values = values.reshape(-1, 3)
            check(len(values) == n, f"one velocity per vertex ({len(values)} for {n})")
            want = np.stack([columns[f"velocity_{a}"][:n] for a in "xyz"], axis=1)
            # glTF is +Y up; the importer turns vectors of custom attributes as it turns
            # positions only for known semantics, so compare both conventions.
            same = np.array_equal(values.view(np.uint32), want.view(np.uint32))
            turned = np.stack([want[:, 0], -want[:, 2], want[:, 1]], axis=1)
            same_turned = np.array_equal(values.view(np.uint32), turned.view(np.uint32))
            check(same or same_turned, "the velocities equal the PLY's bit for bit")
            if same_turned and not same:
                print("note: Blender turned _VELOCITY to its +Z-up axes, as it does positions")
            elif same:
                print("note: Blender keeps _VELOCITY in glTF's +Y-up axes (positions are turned)")
            speed = np.linalg.norm(values, axis=1)
            check(bool(np.isfinite(values).all()) and float(speed.max()) > 0.1,
                  f"a finite, moving velocity field (max speed {speed.max():.3f})")
    if failures:
        print(f"{len(failures)} check(s) failed")
        sys.exit(1)
    print("Blender import of a reconstruction with velocity passed")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
