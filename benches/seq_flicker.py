#!/usr/bin/env python3
"""Flicker on consecutive frames (issue 51): meniscus's presets and splashsurf's smoothed
surface meshed on the same frames, then measured by the independent ruler seq_flicker.py
(not part of this repository: ../shared/eval/seq_flicker.py; its Python needs numpy,
scipy and trimesh). For each interior frame, points sampled on the surface get their
closest points on the frames before and after; N2 is the angle between the shading normal
and the mean of the neighbours' (second difference in time: noise that is not motion), D2
the second difference of the position along the normal. Two rows per tool: the normals
the files carry (what a renderer that reads them lights) and area-weighted normals
recomputed from the mesh (what a renderer that recomputes them lights).

    python3 benches/seq_flicker.py --ruler ../shared/eval/seq_flicker.py \
        --frames '../shared/data/splash_pool_seq60/ParticleData_Fluid_{}.bgeo' --start 36 --end 47 -r 0.01

splashsurf is taken from the PATH (`cargo install splashsurf --locked`); without it its rows
are left out. Not a test: a benchmark, figures in docs/quality.md ("Steady in motion").
"""
import argparse, json, os, shutil, subprocess, sys, tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CASES = {
    "meniscus steady (sequences' default)": ["--preset", "steady"],
    "meniscus still (one frame's default)": ["--preset", "still"],
}
SPLASHSURF = ["-l", "2.0", "-t", "0.6", "-c", "0.5", "--mesh-smoothing-weights=on",
              "--mesh-smoothing-iters=25", "--normals=on"]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ruler", required=True, help="path of seq_flicker.py")
    ap.add_argument("--python", default=sys.executable, help="python with the ruler's dependencies")
    ap.add_argument("--frames", required=True, help="particle files, {} for the frame number")
    ap.add_argument("--start", type=int, required=True)
    ap.add_argument("--end", type=int, required=True)
    ap.add_argument("-r", "--radius", type=float, required=True)
    ap.add_argument("--meniscus", default=os.path.join(ROOT, "target", "release", "meniscus"))
    args = ap.parse_args()
    frames = range(args.start, args.end + 1)
    work = tempfile.mkdtemp(prefix="seq_flicker_")
    runs = {}
    for name, extra in CASES.items():
        out = os.path.join(work, name.split()[1])
        os.makedirs(out)
        subprocess.run([args.meniscus, "reconstruct", args.frames, "-r", str(args.radius), "--start",
                        str(args.start), "--end", str(args.end), "-q", "-o",
                        os.path.join(out, "{}.ply")] + extra, check=True)
        runs[name] = [os.path.join(out, f"{k}.ply") for k in frames]
    splashsurf = shutil.which("splashsurf")
    if splashsurf:
        out = os.path.join(work, "splashsurf")
        os.makedirs(out)
        for k in frames:
            subprocess.run([splashsurf, "reconstruct", args.frames.replace("{}", str(k)), "-r",
                            str(args.radius), "-q", "-o", os.path.join(out, f"{k}.ply")] + SPLASHSURF,
                           check=True)
        runs["splashsurf smoothed (cube 0.5 r, 25 weighted iterations)"] = [
            os.path.join(out, f"{k}.ply") for k in frames]
    print(f"| {args.frames} {args.start}-{args.end} | normals | N2 mean | N2 p95 | D2 mean |")
    print("|---|---|---|---|---|")
    for name, meshes in runs.items():
        for flag, label in (("--file-normals", "written"), ("--shading", "recomputed")):
            j = json.loads(subprocess.run([args.python, args.ruler, str(args.radius)] + meshes + [flag],
                                          check=True, capture_output=True, text=True).stdout)
            print(f"| {name} | {label} | {j['n2_mean_deg']:.3f}° | {j['n2_p95_deg']:.3f}° | "
                  f"{j['d2_mean_r']:.4f} r |")
    shutil.rmtree(work)


if __name__ == "__main__":
    main()
