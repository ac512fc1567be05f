"""Reads a stage written by `meniscus reconstruct` with Pixar's USD (`pip install
usd-core`) and checks it against the binary PLYs the same run options wrote for the same
frames:

    python tests/usd/check_run.py SHOT.usdc PLY_PATTERN FRAME...

The stage opens without an error and Pixar's compliance check reports none
(`UsdUtils.ComplianceChecker` up to usd-core 25.x, the `UsdValidation` validators after);
its time range is the first and last frame; every time-sampled property of the fluid mesh
has a sample at exactly FRAME...; at every frame each face is a triangle, the indices are
in range, `velocities` has the points' length, and points and velocities equal the PLY's
first vertices (the PLY lists the fluid's vertices, then the spheres'), bit for bit; with
an instancer, the triangles of the fluid plus every sphere instance are the PLY's; with
droplets as points (the default), each point is the centre of one of the PLY's spheres,
its width the sphere's diameter and its velocity the sphere's (`check_droplets`). Exits non-zero on the
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


def check_droplets(points, frame, faces, columns, first):
    """The droplets (a Points prim) against the PLY's spheres, which follow the fluid's
    `first` vertices: as many spheres as points, each of the same number of vertices and
    `faces` / points triangles, centred (the mean of its vertices) on its point, as wide
    as its point's width (twice its farthest vertex), with the point's velocity."""
    centers = points.GetPointsAttr().Get(frame) or []
    widths = points.GetWidthsAttr().Get(frame) or []
    velocities = points.GetVelocitiesAttr().Get(frame) or []
    d = len(centers)
    expect(len(widths) == d and len(velocities) == d, f"frame {frame}: {d} droplets, {len(widths)} widths, {len(velocities)} velocities")
    rest = len(columns["x"]) - first
    if d == 0:
        expect(rest == 0 and faces == 0, f"frame {frame}: sphere vertices without droplets")
        return
    expect(rest % d == 0 and faces % d == 0, f"frame {frame}: {rest} sphere vertices, {faces} faces for {d} droplets")
    per = rest // d
    for k in range(d):
        block = range(first + k * per, first + (k + 1) * per)
        mean = [sum(columns[a][i] for i in block) / per for a in "xyz"]
        reach = max(sum((columns[a][i] - mean[j]) ** 2 for j, a in enumerate("xyz")) ** 0.5 for i in block)
        tolerance = 1e-4 * max(widths[k], 1e-6) + 1e-6 * max(abs(c) for c in centers[k])
        expect(all(abs(mean[j] - centers[k][j]) <= tolerance for j in range(3)),
               f"frame {frame} droplet {k}: at {centers[k]}, its sphere centred at {mean}")
        expect(abs(2 * reach - widths[k]) <= 1e-4 * widths[k] + 2 * tolerance,
               f"frame {frame} droplet {k}: width {widths[k]}, its sphere {2 * reach} wide")
        for j, a in enumerate("xyz"):
            expect(velocities[k][j] == columns[f"velocity_{a}"][block[0]],
                   f"frame {frame} droplet {k}: velocity {a} is the PLY sphere's")


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
    droplets = stage.GetPrimAtPath("/Surface/Droplets")
    if droplets.IsValid():
        expect(not spheres.IsValid(), "both droplets and spheres")
        check_droplets(UsdGeom.Points(droplets), frame, faces - triangles, columns, n)
        return len(counts)
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
