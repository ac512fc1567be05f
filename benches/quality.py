#!/usr/bin/env python3
"""Surface-quality table of docs/quality.md: every shipped frame and analytic case, and
generated violent splashes, reconstructed with each kernel and measured with the
independent ruler meshq.py (not part of this repository; its venv needs numpy, scipy,
trimesh).

    python3 benches/quality.py --meshq ../shared/eval/meshq.py --python /path/to/venv/bin/python \
        [--binary target/release/meniscus] [--runs default isotropic paper] [--out table.md]

Runs: `default` (the defaults: anisotropic kernels), `isotropic` (`--kernel isotropic`, the
other defaults), `paper` (`--paper`: the pipeline of Akinci et al. 2013 exactly).

With `--multiscale ../shared/eval/multiscale_bump.py` a *dimples* column is added: the 90th
percentile, over the flattest three quarters of the surface (gently curved parts included),
of the mean angle between the surface normals and the best-fitting plane in a 3 r ball
(issue 36: what a render of gently curved water shows, which the flat bumpiness misses).

Splash frames are made with `examples/tile_scene` (`cargo build --release --example
tile_scene`). Times are the CLI's own stage total (one run; for comparisons only within
one table).
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = os.path.join(ROOT, "datasets")

RUNS = {"default": [], "isotropic": ["--kernel", "isotropic"], "paper": ["--paper"]}

ANALYTIC = {
    "sphere": ["--sphere", "0,0,0,0.5"],
    "box": ["--box=-0.5,-0.3,-0.2,0.5,0.3,0.2"],
    "droplets": [],
    "sheet": [],
}


def cases(tmp, tile_scene):
    for k in (1, 9, 17, 25, 31, 45):
        yield f"dambreak {k}", os.path.join(DATA, "dambreak_small", f"ParticleData_Fluid_{k}.xyz"), 0.012, []
    for k in (1, 6, 9, 13, 20):
        yield f"double dambreak {k}", os.path.join(DATA, "double_dambreak", f"ParticleData_Fluid_{k}.xyz"), 0.025, []
    for name, ref in ANALYTIC.items():
        yield name, os.path.join(DATA, "analytic", f"{name}.xyz"), 0.025, ref
    for src, copies, r, name in (
        ("dambreak_small/ParticleData_Fluid_25.xyz", 4, 0.012, "splash of dambreak 25 ×4"),
        ("dambreak_small/ParticleData_Fluid_45.xyz", 4, 0.012, "splash of dambreak 45 ×4"),
        ("double_dambreak/ParticleData_Fluid_9.xyz", 1, 0.025, "splash of double dambreak 9"),
    ):
        out = os.path.join(tmp, name.replace(" ", "_").replace("×", "x") + ".xyz")
        subprocess.run([tile_scene, os.path.join(DATA, src), str(copies), out, "splash"],
                       check=True, stdout=subprocess.DEVNULL)
        yield name, out, r, []


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--meshq", required=True)
    ap.add_argument("--python", default=sys.executable, help="python with meshq's dependencies")
    ap.add_argument("--binary", default=os.path.join(ROOT, "target", "release", "meniscus"))
    ap.add_argument("--tile-scene", default=os.path.join(ROOT, "target", "release", "examples", "tile_scene"))
    ap.add_argument("--runs", nargs="+", default=list(RUNS), choices=list(RUNS))
    ap.add_argument("--multiscale", help="the ruler multiscale_bump.py: adds the dimples column (issue 36)")
    ap.add_argument("--out")
    args = ap.parse_args()
    dimples = ["dimples [°] |", "---|"] if args.multiscale else ["", ""]
    rows = ["| case | run | triangles | flat bumpiness [r] | " + dimples[0] + " normal error [°] | volume | mean \\|d − r\\| [r] | depth bias [r] | centres outside | time [ms] |",
            "|---|---|---|---|" + dimples[1] + "---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        for name, path, r, ref in cases(tmp, args.tile_scene):
            for run in args.runs:
                mesh = os.path.join(tmp, "m.ply")
                stats = os.path.join(tmp, "s.json")
                subprocess.run([args.binary, "reconstruct", path, "-r", str(r), "-o", mesh, "--quiet",
                                *RUNS[run], "--stats", stats], check=True)
                q = json.loads(subprocess.run([args.python, args.meshq, mesh, "--particles", path, "-r", str(r),
                                               "--json", *ref], check=True, capture_output=True, text=True).stdout)
                rec = json.load(open(stats))["frames"][0]["reconstruction"]
                ms = 1e3 * sum(s["seconds"] for s in rec["stages"])
                p = q["particles"]
                refq = q.get("reference") or {}
                nerr = f"{refq['normal_error']['mean_deg']:.2f}" if refq else "–"
                vol = f"{100 * refq['volume']['rel_error']:+.2f} %" if refq else "–"
                dimple = ""
                if args.multiscale:
                    m = json.loads(subprocess.run([args.python, args.multiscale, mesh, str(r), "3"], check=True,
                                                  capture_output=True, text=True).stdout.splitlines()[-1])
                    dimple = f" {m['3r']['normal_dev_q75_p90_deg']:.2f} |"
                row = (f"| {name} | {run} | {q['size']['triangles']} | "
                       f"{q['smoothness']['bumpiness']['flat_bumpiness_median_r']:.4f} |{dimple} {nerr} | {vol} | "
                       f"{p['surface_abs_dev_mean_r']:.3f} | {p['surface_depth_bias_r']:+.3f} | "
                       f"{p['outside_count']} | {ms:.0f} |")
                rows.append(row)
                print(row, flush=True)
    if args.out:
        with open(args.out, "w") as f:
            f.write("\n".join(rows) + "\n")


if __name__ == "__main__":
    main()
