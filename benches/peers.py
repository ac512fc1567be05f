#!/usr/bin/env python3
"""meniscus against splashsurf, alternating in one run: the speed goals of the README's
performance table are ratios of wall times measured this way (never absolute seconds:
this VM's speed drifts within the hour).

    python3 benches/peers.py [--rounds 3] [--cases frame25,splash168k,splash4m,splash4m-1GiB,calm4m]

Two more cases, run only when named, give the floor of the default pipeline's time:
`frame25-raw` and `splash4m-raw` time meniscus's raw anisotropic surface (no decimation,
smoothing, containment or subdivision) against the same splashsurf runs.

Each round runs every case's meniscus command and its splashsurf command back to back
(meniscus first on odd rounds, splashsurf first on even ones), each under
`/usr/bin/time -v` for the wall time and the peak RSS. Per case it prints the ratio
meniscus / splashsurf as median and range over the rounds, and both tools' median wall
time and peak memory.

The scenes are built from the shipped frames with `examples/tile_scene` into a temporary
directory (4M scenes: 96 copies of dam break frame 25, calm or thrown apart as a violent
splash; the 168k splash: 4 copies). splashsurf is installed with
`cargo install splashsurf --locked` when it is not on the PATH.

The comparisons (the issue's, splashsurf 0.14, smoothing length 2 r, surface threshold
0.6): meniscus's default surface against splashsurf's raw surface with cubes of 1 r on
the 4M scenes, and against splashsurf's smoothed surface (cubes of 0.5 r, 25 iterations
of feature-weighted smoothing, normals) on the small frames.
"""
import argparse
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FRAME = os.path.join(ROOT, "datasets", "dambreak_small", "ParticleData_Fluid_25.xyz")
RADIUS = "0.012"
SPLASHSURF_RAW = ["-l", "2.0", "-t", "0.6", "-c", "1.0"]
# meniscus without post-processing.
RAW = ["--decimate", "off", "--smooth", "0", "--subdivide", "0", "--keep-inside", "off"]
SPLASHSURF_SMOOTHED = ["-l", "2.0", "-t", "0.6", "-c", "0.5", "--mesh-smoothing-weights=on",
                       "--mesh-smoothing-iters=25", "--normals=on"]

# name: (scene (copies, splash) or None for frame 25, meniscus extra args, splashsurf args)
CASES = {
    "frame25": (None, [], SPLASHSURF_SMOOTHED),
    "splash168k": ((4, True), [], SPLASHSURF_SMOOTHED),
    "splash4m": ((96, True), [], SPLASHSURF_RAW),
    "splash4m-1GiB": ((96, True), ["--memory-budget", "1GiB"], SPLASHSURF_RAW),
    "calm4m": ((96, False), [], SPLASHSURF_RAW),
    # The floor: meniscus's raw anisotropic surface (kernels, field, marching cubes, no
    # post-processing) against the same peer runs. The default pipeline cannot be faster.
    "frame25-raw": (None, RAW, SPLASHSURF_SMOOTHED),
    "splash4m-raw": ((96, True), RAW, SPLASHSURF_RAW),
}
# Cases run without --cases (the floor cases are asked for by name).
DEFAULT_CASES = [case for case in CASES if not case.endswith("-raw")]


def splashsurf_binary():
    found = shutil.which("splashsurf")
    if found:
        return found
    print("installing splashsurf (cargo install splashsurf --locked)", file=sys.stderr)
    subprocess.run(["cargo", "install", "splashsurf", "--locked"], check=True)
    return shutil.which("splashsurf") or os.path.expanduser("~/.cargo/bin/splashsurf")


def scene(work, spec):
    if spec is None:
        return FRAME
    copies, splash = spec
    path = os.path.join(work, f"scene_{copies}{'_splash' if splash else ''}.xyz")
    if not os.path.exists(path):
        tile_scene = os.path.join(ROOT, "target", "release", "examples", "tile_scene")
        subprocess.run([tile_scene, FRAME, str(copies), path] + (["splash"] if splash else []),
                       check=True, stdout=subprocess.DEVNULL)
    return path


def timed(command, work):
    """Wall seconds and peak RSS (MiB) of one run; raises when it fails."""
    report = os.path.join(work, "time.txt")
    with open(report, "w") as err:
        done = subprocess.run(["/usr/bin/time", "-v"] + command, stdout=subprocess.DEVNULL,
                              stderr=err)
    text = open(report).read()
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} failed:\n{text[-2000:]}")
    clock = re.search(r"Elapsed \(wall clock\) time.*: (\S+)", text).group(1)
    seconds = 0.0
    for part in clock.split(":"):
        seconds = seconds * 60 + float(part)
    rss = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", text).group(1)) / 1024
    return seconds, rss


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--cases", default=",".join(DEFAULT_CASES))
    ap.add_argument("--binary", default=os.path.join(ROOT, "target", "release", "meniscus"))
    args = ap.parse_args()
    cases = args.cases.split(",")
    unknown = [c for c in cases if c not in CASES]
    if unknown:
        sys.exit(f"unknown case(s) {unknown}; known: {', '.join(CASES)}")
    subprocess.run(["cargo", "build", "--release", "--quiet", "--example", "tile_scene"],
                   cwd=ROOT, check=True)
    if args.binary == os.path.join(ROOT, "target", "release", "meniscus"):
        subprocess.run(["cargo", "build", "--release", "--quiet"], cwd=ROOT, check=True)
    splashsurf = splashsurf_binary()
    with tempfile.TemporaryDirectory(prefix="meniscus-peers.") as work:
        results = {c: {"meniscus": [], "splashsurf": []} for c in cases}
        for round_ in range(args.rounds):
            for case in cases:
                spec, extra, peer = CASES[case]
                source = scene(work, spec)
                runs = {
                    "meniscus": [args.binary, "reconstruct", source, "-r", RADIUS, "-q",
                                 "-o", os.path.join(work, "meniscus.ply")] + extra,
                    "splashsurf": [splashsurf, "reconstruct", source, "-r", RADIUS, "-q",
                                   "-o", os.path.join(work, "splashsurf.ply")] + peer,
                }
                order = ["meniscus", "splashsurf"] if round_ % 2 == 0 else ["splashsurf", "meniscus"]
                for tool in order:
                    results[case][tool].append(timed(runs[tool], work))
                m, s = results[case]["meniscus"][-1], results[case]["splashsurf"][-1]
                print(f"round {round_ + 1} {case}: meniscus {m[0]:.2f} s {m[1]:.0f} MiB, "
                      f"splashsurf {s[0]:.2f} s {s[1]:.0f} MiB, ratio {m[0] / s[0]:.3f}",
                      file=sys.stderr, flush=True)
    print(f"load before the table: {os.getloadavg()[0]:.1f} (1-minute average, 2 cores)")
    print("| case | ratio (median, range) | meniscus | splashsurf |")
    print("|---|---|---|---|")
    for case in cases:
        m, s = results[case]["meniscus"], results[case]["splashsurf"]
        ratios = [a[0] / b[0] for a, b in zip(m, s)]
        med = lambda runs, k: statistics.median(r[k] for r in runs)
        print(f"| {case} | {statistics.median(ratios):.3f} ({min(ratios):.3f}–{max(ratios):.3f}) "
              f"| {med(m, 0):.2f} s, {med(m, 1):.0f} MiB | {med(s, 0):.2f} s, {med(s, 1):.0f} MiB |")


if __name__ == "__main__":
    main()
