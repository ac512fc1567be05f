"""Reads the stages of `examples/usd_fixture.rs` back with Pixar's USD (`pip install
usd-core`) and checks them against `usd_expected.json`.

    python tests/usd/check_stages.py OUT_DIR

For every stage: it opens without an error, Pixar's compliance check reports no error
(`UsdUtils.ComplianceChecker` where the installed usd-core has it, up to 25.x; the
`UsdValidation` validators that replace it otherwise), the layer metadata
(`startTimeCode`/`endTimeCode`, `timeCodesPerSecond`, `framesPerSecond`, `upAxis`,
`metersPerUnit`, `defaultPrim`) is right, and every time-sampled property of the fluid
mesh and of the sphere instancer has a sample at exactly the frame numbers. At every frame:
every face is a triangle, the indices are in range and equal the mesh's, points and
normals equal the mesh's, `velocities` has the points' length and equals the velocity
attribute, each other attribute is a `primvars:NAME` of its components (1-4 as
float..float4, more as float[] with elementSize) with vertex interpolation and the same
values, the extent is the points' bounding box; the isolated particles are a Points prim
(`check_points`: centres, widths 2 r_i, extent, velocity and density) by default, or with
the instancer option a PointInstancer of the icosphere with the centres as positions,
their velocity and density, their scales and each instance's size where a frame has them
(`check_scales`); either is absent from a stage without isolated particles. Floats must be equal to the bit (f32). Exits non-zero on the
first failure.
"""

import json
import re
import struct
import sys
from pathlib import Path

from pxr import Gf, Sdf, Tf, Usd, UsdGeom

try:
    from pxr import UsdUtils
except ImportError:  # pragma: no cover - every usd-core has UsdUtils
    UsdUtils = None


def f32(x):
    """`x` rounded to float32, as the files store it."""
    return struct.unpack("<f", struct.pack("<f", x))[0]


def flat(values):
    """A Vt array (of scalars or vectors) as a flat list of Python floats/ints."""
    out = []
    for v in values:
        if hasattr(v, "__len__"):
            out.extend(v)
        else:
            out.append(v)
    return out


def expect(condition, message):
    if not condition:
        raise AssertionError(message)


def same_floats(actual, expected, what):
    expected = [f32(x) for x in expected]
    actual = flat(actual)
    expect(len(actual) == len(expected), f"{what}: {len(actual)} floats, expected {len(expected)}")
    for i, (a, e) in enumerate(zip(actual, expected)):
        if a != e:
            raise AssertionError(f"{what}: value {i} is {a!r}, expected {e!r}")


def identifier(name):
    out = re.sub(r"[^A-Za-z0-9]", "_", name)
    return "_" + out if not out or out[0].isdigit() else out


def compliance_errors(path):
    """Errors (and failed checks) of Pixar's compliance check of `path`."""
    if UsdUtils is not None and hasattr(UsdUtils, "ComplianceChecker"):
        checker = UsdUtils.ComplianceChecker(assetLevelChecks=True)
        checker.CheckCompliance(str(path))
        for w in checker.GetWarnings():
            print(f"  compliance warning: {w}")
        return list(checker.GetErrors()) + list(checker.GetFailedChecks()), "UsdUtils.ComplianceChecker"
    from pxr import UsdValidation

    registry = UsdValidation.ValidationRegistry()
    context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    stage = Usd.Stage.Open(str(path))
    errors = []
    for e in context.Validate(stage):
        if e.GetType() == UsdValidation.ValidationErrorType.Error:
            errors.append(f"{e.GetName()}: {e.GetMessage()}")
        else:
            print(f"  validation {e.GetType()}: {e.GetName()}: {e.GetMessage()}")
    return errors, "UsdValidation (all validators)"


def check_metadata(stage, spec):
    numbers = [f["frame"] for f in spec["frames"]]
    layer = stage.GetRootLayer()
    if not numbers:
        expect(not layer.HasStartTimeCode() and not layer.HasEndTimeCode(), "a time range without frames")
        numbers = [0]
    expect(stage.GetStartTimeCode() == min(numbers), f"startTimeCode {stage.GetStartTimeCode()}")
    expect(stage.GetEndTimeCode() == max(numbers), f"endTimeCode {stage.GetEndTimeCode()}")
    expect(layer.HasStartTimeCode() == layer.HasEndTimeCode() == bool(spec["frames"]), "time range authored")
    expect(stage.GetTimeCodesPerSecond() == spec["fps"], f"timeCodesPerSecond {stage.GetTimeCodesPerSecond()}")
    expect(stage.GetFramesPerSecond() == spec["fps"], f"framesPerSecond {stage.GetFramesPerSecond()}")
    expect(UsdGeom.GetStageUpAxis(stage) == spec["up_axis"], f"upAxis {UsdGeom.GetStageUpAxis(stage)}")
    expect(stage.HasAuthoredMetadata("metersPerUnit"), "metersPerUnit authored")
    expect(UsdGeom.GetStageMetersPerUnit(stage) == spec["meters_per_unit"], "metersPerUnit")
    expect(stage.GetDefaultPrim().GetPath() == Sdf.Path("/Surface"), "defaultPrim /Surface")


def check_samples(attribute, numbers):
    samples = attribute.GetTimeSamples()
    expect(samples == [float(n) for n in numbers], f"{attribute.GetPath()}: samples at {samples}, frames {numbers}")


def check_primvars(prim, attributes, t, items, what):
    api = UsdGeom.PrimvarsAPI(prim)
    for a in attributes:
        if a["name"] == "velocity" and a["components"] == 3:
            velocities = prim.GetAttribute("velocities").Get(t)
            expect(len(velocities) == items, f"{what}: {len(velocities)} velocities for {items} items at {t}")
            same_floats(velocities, a["values"], f"{what} velocities at {t}")
            continue
        primvar = api.GetPrimvar(identifier(a["name"]))
        expect(primvar, f"{what}: no primvars:{identifier(a['name'])}")
        expect(primvar.GetInterpolation() == UsdGeom.Tokens.vertex, f"{what}: {a['name']} interpolation")
        c = a["components"]
        type_name = {1: "float[]", 2: "float2[]", 3: "float3[]", 4: "float4[]"}.get(c, "float[]")
        expect(str(primvar.GetTypeName()) == type_name, f"{what}: {a['name']} is {primvar.GetTypeName()}")
        expect(primvar.GetElementSize() == (c if c > 4 else 1), f"{what}: {a['name']} elementSize")
        same_floats(primvar.Get(t), a["values"], f"{what} primvar {a['name']} at {t}")


def check_extent(attribute, points, t, pad=((0, 0, 0), (0, 0, 0))):
    extent = flat(attribute.Get(t))
    if not points:
        expect(extent == [0.0] * 6, f"{attribute.GetPath()} at {t}: {extent}")
        return
    # The corners are summed in f32, as the writer sums them.
    lo = [f32(min(f32(p[k]) for p in points) + pad[0][k]) for k in range(3)]
    hi = [f32(max(f32(p[k]) for p in points) + pad[1][k]) for k in range(3)]
    same_floats(extent, [*lo, *hi], f"{attribute.GetPath()} at {t}")


def check_fluid(stage, spec):
    numbers = [f["frame"] for f in spec["frames"]]
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Surface/Fluid"))
    expect(mesh, "/Surface/Fluid is a Mesh")
    expect(mesh.GetSubdivisionSchemeAttr().Get() == "none", "subdivisionScheme none")
    prim = mesh.GetPrim()
    for attribute in prim.GetAttributes():
        if attribute.GetName() != "subdivisionScheme" and attribute.HasAuthoredValue():
            check_samples(attribute, numbers)
    for f in spec["frames"]:
        t, fluid = float(f["frame"]), f["fluid"]
        counts = mesh.GetFaceVertexCountsAttr().Get(t)
        indices = list(mesh.GetFaceVertexIndicesAttr().Get(t))
        points = mesh.GetPointsAttr().Get(t)
        expect(all(c == 3 for c in counts), f"frame {t}: a face that is not a triangle")
        expect(len(counts) * 3 == len(indices), f"frame {t}: counts and indices disagree")
        expect(all(0 <= i < len(points) for i in indices), f"frame {t}: an index out of range")
        expect(indices == fluid["indices"], f"frame {t}: indices differ")
        valid, why = UsdGeom.Mesh.ValidateTopology(indices, counts, len(points))
        expect(valid, f"frame {t}: {why}")
        same_floats(points, flat(fluid["points"]), f"frame {t} points")
        if fluid["normals"]:
            same_floats(mesh.GetNormalsAttr().Get(t), flat(fluid["normals"]), f"frame {t} normals")
            expect(mesh.GetNormalsInterpolation() == UsdGeom.Tokens.vertex, "normals interpolation")
        else:
            expect(not mesh.GetNormalsAttr().HasAuthoredValue(), "normals on a mesh without them")
        check_primvars(prim, fluid["attributes"], t, len(points), "fluid")
        check_extent(mesh.GetExtentAttr(), fluid["points"], t)


def check_scales(instancer, s, t, pad, template):
    """Spheres of their own sizes: `scales` (s, s, s) per instance, each instance's
    transform (Pixar's `ComputeInstanceTransformsAtTime`) putting every prototype vertex at
    its scaled distance from the centre, the extent holding every sphere at its size; a
    frame without scales has none (an empty array when another frame has them)."""
    scales = instancer.GetScalesAttr()
    if not s["scales"]:
        expect(not scales.HasAuthoredValue() or len(scales.Get(t)) == 0, f"frame {t}: scales without sizes")
        return
    same_floats(scales.Get(t), [x for k in s["scales"] for x in (k, k, k)], f"frame {t} scales")
    transforms = instancer.ComputeInstanceTransformsAtTime(Usd.TimeCode(t), Usd.TimeCode(t))
    expect(len(transforms) == len(s["centers"]), f"frame {t}: {len(transforms)} instance transforms")
    radius = max(sum(c * c for c in p) ** 0.5 for p in template["points"])
    for k, (m, c) in enumerate(zip(transforms, s["centers"])):
        for p in template["points"]:
            q = m.Transform(Gf.Vec3d(*p))
            d = sum((q[i] - c[i]) ** 2 for i in range(3)) ** 0.5
            want = sum(x * x for x in p) ** 0.5 * s["scales"][k]
            expect(abs(d - want) < 1e-5 * max(1.0, radius), f"frame {t} sphere {k}: a vertex at {d}, expected {want}")
    # Every centre moved by the prototype's corners times its scale, summed in f32.
    lo = [f32(min(f32(c[i]) + f32(pad[0][i] * k) for c, k in zip(s["centers"], s["scales"]))) for i in range(3)]
    hi = [f32(max(f32(c[i]) + f32(pad[1][i] * k) for c, k in zip(s["centers"], s["scales"]))) for i in range(3)]
    same_floats(instancer.GetExtentAttr().Get(t), [*lo, *hi], f"frame {t} sphere extent")


def check_points(stage, spec):
    """The isolated particles as a `UsdGeomPoints` prim, `/Surface/Droplets`: the centres
    as points, widths 2 r_i (the template's radius, the mean distance of its vertices, times the scale, doubled), the extent
    holding every point at its width, the velocity as `velocities`, the other attributes
    as primvars; no instancer."""
    numbers = [f["frame"] for f in spec["frames"]]
    expect(not stage.GetPrimAtPath("/Surface/Spheres"), "an instancer in a stage of points")
    prim = stage.GetPrimAtPath("/Surface/Droplets")
    if not any(f["spheres"]["centers"] for f in spec["frames"]):
        expect(not prim, "droplets in a stage without isolated particles")
        return
    points = UsdGeom.Points(prim)
    expect(points, "/Surface/Droplets is a Points prim")
    expect(points.GetWidthsInterpolation() == UsdGeom.Tokens.vertex, "widths interpolation")
    for attribute in prim.GetAttributes():
        if attribute.HasAuthoredValue():
            check_samples(attribute, numbers)
    for f in spec["frames"]:
        t, s = float(f["frame"]), f["spheres"]
        n = len(s["centers"])
        same_floats(points.GetPointsAttr().Get(t), flat(s["centers"]), f"frame {t} droplet points")
        widths = list(points.GetWidthsAttr().Get(t))
        expect(len(widths) == n, f"frame {t}: {len(widths)} widths for {n} droplets")
        if not n:
            expect(len(points.GetVelocitiesAttr().Get(t)) == 0, f"frame {t}: velocities without droplets")
            continue
        pts = s["template"]["points"]
        radius = f32(sum(sum(f32(c) * f32(c) for c in p) ** 0.5 for p in pts) / len(pts))
        scales = s["scales"] or [1.0] * n
        for k, (w, scale) in enumerate(zip(widths, scales)):
            want = 2 * radius * scale
            expect(abs(w - want) <= 1e-6 * want, f"frame {t} droplet {k}: width {w}, expected {want}")
        lo = [min(c[i] - w / 2 for c, w in zip(s["centers"], widths)) for i in range(3)]
        hi = [max(c[i] + w / 2 for c, w in zip(s["centers"], widths)) for i in range(3)]
        extent = flat(points.GetExtentAttr().Get(t))
        for got, want in zip(extent, [*lo, *hi]):
            expect(abs(got - want) <= 1e-6 * max(1.0, abs(want)), f"frame {t}: droplet extent {extent}, expected {lo} {hi}")
        # What a renderer computes for the prim must hold every droplet too.
        bound = UsdGeom.Points.ComputeExtent(points.GetPointsAttr().Get(t), points.GetWidthsAttr().Get(t))
        expect(bound is not None and all(abs(a - b) <= 1e-6 * max(1.0, abs(b)) for a, b in zip(flat(bound), extent)),
               f"frame {t}: extent {extent}, Pixar computes {bound}")
        check_primvars(prim, s["attributes"], t, n, "droplets")


def check_spheres(stage, spec):
    if spec.get("droplets", "points") == "points":
        check_points(stage, spec)
        return
    numbers = [f["frame"] for f in spec["frames"]]
    expect(not stage.GetPrimAtPath("/Surface/Droplets"), "droplets in a stage of instances")
    prim = stage.GetPrimAtPath("/Surface/Spheres")
    if not any(f["spheres"]["centers"] for f in spec["frames"]):
        expect(not prim, "a sphere instancer in a stage without spheres")
        return
    instancer = UsdGeom.PointInstancer(prim)
    expect(instancer, "/Surface/Spheres is a PointInstancer")
    targets = instancer.GetPrototypesRel().GetTargets()
    expect(targets == [Sdf.Path("/Surface/Spheres/Prototypes/Sphere")], f"prototypes {targets}")
    template = next(f["spheres"]["template"] for f in spec["frames"] if f["spheres"]["centers"])
    sphere = UsdGeom.Mesh(stage.GetPrimAtPath(targets[0]))
    same_floats(sphere.GetPointsAttr().Get(), flat(template["points"]), "prototype points")
    expect(list(sphere.GetFaceVertexIndicesAttr().Get()) == template["indices"], "prototype indices")
    expect(all(c == 3 for c in sphere.GetFaceVertexCountsAttr().Get()), "prototype triangles")
    expect(UsdGeom.Mesh(sphere).GetSubdivisionSchemeAttr().Get() == "none", "prototype subdivisionScheme")
    pts = template["points"]
    pad = ([min(f32(p[k]) for p in pts) for k in range(3)], [max(f32(p[k]) for p in pts) for k in range(3)])
    for attribute in prim.GetAttributes():
        if attribute.HasAuthoredValue():
            check_samples(attribute, numbers)
    for f in spec["frames"]:
        t, s = float(f["frame"]), f["spheres"]
        n = len(s["centers"])
        same_floats(instancer.GetPositionsAttr().Get(t), flat(s["centers"]), f"frame {t} sphere positions")
        expect(list(instancer.GetProtoIndicesAttr().Get(t)) == [0] * n, f"frame {t}: protoIndices")
        check_scales(instancer, s, t, pad, template)
        if n:
            check_primvars(prim, s["attributes"], t, n, "spheres")
            if not s["scales"]:
                check_extent(instancer.GetExtentAttr(), s["centers"], t, pad)
        else:
            expect(len(instancer.GetVelocitiesAttr().Get(t)) == 0, f"frame {t}: velocities without spheres")


def check_stage(directory, spec):
    path = Path(directory) / spec["file"]
    mark = Tf.Error.Mark()
    stage = Usd.Stage.Open(str(path))
    expect(stage is not None and mark.IsClean(), f"{path}: does not open cleanly")
    errors, checker = compliance_errors(path)
    expect(not errors, f"{path}: {checker}: {errors}")
    check_metadata(stage, spec)
    check_fluid(stage, spec)
    check_spheres(stage, spec)
    frames = [f["frame"] for f in spec["frames"]]
    print(f"{path.name}: ok ({checker}: no errors; frames {frames})")


def main():
    if len(sys.argv) != 2:
        sys.exit("usage: check_stages.py OUT_DIR (written by examples/usd_fixture.rs)")
    directory = sys.argv[1]
    spec = json.loads((Path(directory) / "usd_expected.json").read_text())
    print(f"usd-core {'.'.join(map(str, Usd.GetVersion()))}")
    for stage in spec["stages"]:
        check_stage(directory, stage)
    print(f"{len(spec['stages'])} passed, 0 failed")


if __name__ == "__main__":
    main()
