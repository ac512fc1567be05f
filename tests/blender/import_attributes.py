"""Imports meniscus output with attributes into Blender (bpy as a Python module) and checks
that every vertex keeps its velocity and density.

    python tests/blender/import_attributes.py DIR

DIR holds attributes.glb, attributes.ply and attributes.json (written by
`cargo run --release --example attribute_fixture -- DIR`). The glTF check must pass: the
fluid and the merged spheres must each carry the point attributes `_VELOCITY` (FLOAT_VECTOR)
and `_DENSITY` (FLOAT) with the written values, vertex for vertex. The PLY check reports
whether Blender's PLY importer keeps the custom vertex properties; it fails only when it
keeps them with wrong values. Exits non-zero on any failure.
"""

import json
import sys
from pathlib import Path

import bpy
import numpy as np

failures = []


def check(ok, message):
    print(("ok   " if ok else "FAIL ") + message)
    if not ok:
        failures.append(message)


def reset():
    bpy.ops.wm.read_factory_settings(use_empty=True)


def attribute_array(mesh, name, width):
    attr = mesh.attributes[name]
    out = np.empty(len(attr.data) * width, dtype=np.float32)
    attr.data.foreach_get("vector" if width == 3 else "value", out)
    return attr, out


def check_mesh(label, mesh, expected, names, to_blender):
    """Compares a Blender mesh with the expected vertices and attribute values."""
    n = expected["vertices"]
    check(len(mesh.vertices) == n, f"{label}: {len(mesh.vertices)} vertices, expected {n}")
    if len(mesh.vertices) != n:
        return
    positions = np.empty(n * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", positions)
    want = to_blender(np.asarray(expected["positions"], dtype=np.float32))
    err = float(np.abs(positions.reshape(-1, 3) - want).max())
    check(err < 1e-6, f"{label}: vertex order and positions kept (max error {err:.2e})")
    for key, (name, width, data_type) in names.items():
        if name not in mesh.attributes:
            check(False, f"{label}: attribute {name!r} missing; Blender has {list(mesh.attributes.keys())}")
            continue
        attr, values = attribute_array(mesh, name, width)
        check(attr.domain == "POINT", f"{label}: {name} on domain {attr.domain}")
        check(attr.data_type == data_type, f"{label}: {name} of type {attr.data_type}")
        want = np.asarray(expected[key], dtype=np.float32)
        same = values.shape == want.shape and np.array_equal(values.view(np.uint32), want.view(np.uint32))
        check(same, f"{label}: {name} holds the written {key} values bit for bit ({values.size} floats)")


def gltf_to_blender(p):
    # glTF is +Y up, Blender +Z up: (x, y, z) -> (x, -z, y).
    return np.stack([p[:, 0], -p[:, 2], p[:, 1]], axis=1)


def main(folder):
    expected = json.loads((folder / "attributes.json").read_text())

    reset()
    bpy.ops.import_scene.gltf(filepath=str(folder / "attributes.glb"))
    objects = {o.name: o for o in bpy.context.scene.objects if o.type == "MESH"}
    print("glTF objects:", sorted(objects))
    for label in ["fluid", "isolated_particles"]:
        obj = objects.get(label)
        check(obj is not None, f"glTF: an object named {label!r}")
        if obj is None:
            continue
        print(f"glTF {label} attributes:", sorted(obj.data.attributes.keys()))
        names = {"velocity": ("_VELOCITY", 3, "FLOAT_VECTOR"), "density": ("_DENSITY", 1, "FLOAT")}
        check_mesh(f"glTF {label}", obj.data, expected[label], names, gltf_to_blender)

    reset()
    bpy.ops.wm.ply_import(filepath=str(folder / "attributes.ply"))
    objects = [o for o in bpy.context.scene.objects if o.type == "MESH"]
    check(len(objects) == 1, f"PLY: one mesh object ({len(objects)})")
    if objects:
        mesh = objects[0].data
        keys = sorted(mesh.attributes.keys())
        print("PLY attributes:", keys)
        kept = [k for k in keys if k.startswith("velocity") or k == "density"]
        if not kept:
            print("note PLY: Blender's PLY importer does not keep the custom vertex properties")
        else:
            print("note PLY: Blender keeps", kept)
            want = expected["merged"]
            velocity = np.asarray(want["velocity"], dtype=np.float32).reshape(-1, 3)
            columns = {"velocity_x": velocity[:, 0], "velocity_y": velocity[:, 1],
                       "velocity_z": velocity[:, 2], "density": np.asarray(want["density"], dtype=np.float32)}
            for k in kept:
                if k in columns:
                    _, values = attribute_array(mesh, k, 1)
                    same = np.array_equal(values.view(np.uint32), columns[k].view(np.uint32))
                    check(same, f"PLY: {k} holds the written values bit for bit")
    if failures:
        print(f"{len(failures)} check(s) failed")
        sys.exit(1)
    print("Blender import check passed")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
