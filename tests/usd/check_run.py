"""Reads a stage written by `meniscus reconstruct` with Pixar's USD (`pip install
usd-core`) and checks it against the binary PLYs the same run options wrote for the same
frames:

    python tests/usd/check_run.py SHOT.usdc PLY_PATTERN FRAME...

The stage opens without an error and Pixar's compliance check reports none
(`UsdUtils.ComplianceChecker` up to usd-core 25.x, the `UsdValidation` validators after);
its time range is the first and last frame; every time-sampled property of the fluid mesh
has a sample at exactly FRAME...; at every frame each face is a triangle, the indices are
in range, `velocities` has the points' length, and points and velocities equal the PLY's
first vertices (the PLY lists the fluid's vertices, then the spheres'), bit for bit; the
triangles of the fluid plus every sphere instance are the PLY's. Exits non-zero on the
first failure.
"""

import struct
import sys
from pathlib import Path

from pxr import Usd, UsdGeom

from check_stages import compliance_errors, expect


def read_ply(path):
    """(face count, vertex columns) of a binary little-endian meniscus PLY."""
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
            expect(words[1] == "float", f"{path}: {line}")
            names.append(words[2])
    width = len(names)
    floats = struct.unpack_from(f"<{vertices * width}f", data, end)
    columns = {name: floats[k::width] for k, name in enumerate(names)}
    return faces, columns


def check_frame(stage, frame, ply):
    faces, columns = read_ply(ply)
    fluid = UsdGeom.Mesh(stage.GetPrimAtPath("/Surface/Fluid"))
    points = fluid.GetPointsAttr().Get(frame)
    counts = fluid.GetFaceVertexCountsAttr().Get(frame)
    indices = fluid.GetFaceVertexIndicesAttr().Get(frame)
    velocities = fluid.GetVelocitiesAttr().Get(frame)
    n = len(points)
    expect(all(c == 3 for c in counts), f"frame {frame}: every face a triangle")
    expect(len(indices) == 3 * len(counts), f"frame {frame}: three indices per face")
    expect(all(0 <= i < n for i in indices), f"frame {frame}: indices in range")
    expect(len(velocities) == n, f"frame {frame}: {len(velocities)} velocities, {n} points")
    for k, axis in enumerate("xyz"):
        expect([p[k] for p in points] == list(columns[axis][:n]), f"frame {frame}: points {axis}")
        expect([v[k] for v in velocities] == list(columns[f"velocity_{axis}"][:n]),
               f"frame {frame}: velocity {axis} equals the PLY's")
    triangles = len(counts)
    spheres = stage.GetPrimAtPath("/Surface/Spheres")
    if spheres.IsValid():
        instancer = UsdGeom.PointInstancer(spheres)
        instances = len(instancer.GetPositionsAttr().Get(frame) or [])
        target = instancer.GetPrototypesRel().GetTargets()[0]
        prototype = UsdGeom.Mesh(stage.GetPrimAtPath(target))
        triangles += instances * len(prototype.GetFaceVertexCountsAttr().Get())
    expect(triangles == faces, f"frame {frame}: {triangles} triangles, the PLY {faces}")
    return len(counts)


def main(path, ply_pattern, frames):
    stage = Usd.Stage.Open(path)
    expect(stage is not None, f"{path} opens")
    errors, checker = compliance_errors(path)
    expect(not errors, f"{path}: {checker} errors {errors}")
    expect((stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (frames[0], frames[-1]),
           f"time range {stage.GetStartTimeCode()}-{stage.GetEndTimeCode()}")
    fluid = stage.GetPrimAtPath("/Surface/Fluid")
    for attribute in fluid.GetAttributes():
        if attribute.GetNumTimeSamples():
            expect(attribute.GetTimeSamples() == frames,
                   f"{attribute.GetName()}: samples at {attribute.GetTimeSamples()}")
    for frame in frames:
        triangles = check_frame(stage, frame, ply_pattern.replace("{}", str(frame)))
        print(f"ok   {path} frame {frame}: {triangles} fluid triangles as the PLY's")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], [int(f) for f in sys.argv[3:]])
