"""Python's overhead over the CLI for the same work (issue 24's target: within 5 %).

Not run by CI. Needs the Python package in the active environment and the CLI built by
cargo (MENISCUS_BIN, else $CARGO_TARGET_DIR/release/meniscus, else target/release/...).

    python benches/python_overhead.py [--rounds 12] [--input FRAME] [--radius R]
        [--variant NAME=DIR ...]

Each round runs, alternately, in fresh processes:

* cli: `meniscus reconstruct FRAME -r R -o x.ply --stats s.json -q`. "work" is the frame's
  time without reading and writing (`seconds - read_seconds - write_seconds` of its
  --stats report), "process" the whole process's wall time.
* python: a fresh interpreter that loads the positions with numpy (not timed), then
  times `meniscus.reconstruct(positions, R)` ("first call", what the CLI's one frame
  compares with) and three more calls ("later calls", median).

The work is the same: both read the same positions, run the pipeline with the default
options and produce the same surface (the PLY bytes are compared once). `--variant
NAME=DIR` (repeatable) compares builds of the package: each round runs the Python step
once per variant, with DIR (holding a `meniscus/` package) first on PYTHONPATH.
"""

import argparse
import json
import os
import pathlib
import resource
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]

PYTHON_RUN = r"""
import json, resource, sys, time
import numpy as np
import meniscus
path, radius, ply = sys.argv[1], float(sys.argv[2]), sys.argv[3]
positions = np.fromfile(path, dtype="<f4").reshape(-1, 3)
times = []
for k in range(4):
    before = resource.getrusage(resource.RUSAGE_SELF)
    start = time.perf_counter()
    mesh = meniscus.reconstruct(positions, radius)
    times.append(time.perf_counter() - start)
    if k == 0:
        after = resource.getrusage(resource.RUSAGE_SELF)
        faults = after.ru_minflt - before.ru_minflt
        cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
        if ply:
            mesh.write(ply)
print(json.dumps([times, faults, cpu]))
"""


def cli_binary():
    if os.environ.get("MENISCUS_BIN"):
        return os.environ["MENISCUS_BIN"]
    target = os.environ.get("CARGO_TARGET_DIR", str(ROOT / "target"))
    return os.path.join(target, "release", "meniscus")


def run_cli(binary, frame, radius, tmp, ply_name):
    stats = os.path.join(tmp, "stats.json")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run([binary, "reconstruct", frame, "-r", str(radius), "-o", os.path.join(tmp, ply_name), "--stats", stats, "-q"], check=True)
    process = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    report = json.load(open(stats))["frames"][0]
    work = report["seconds"] - report["read_seconds"] - report["write_seconds"]
    faults = after.ru_minflt - before.ru_minflt
    cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    return work, process, faults, cpu


def run_python(frame, radius, ply, path):
    env = dict(os.environ)
    if path:
        env["PYTHONPATH"] = os.pathsep.join([path] + [p for p in [env.get("PYTHONPATH")] if p])
    out = subprocess.run([sys.executable, "-c", PYTHON_RUN, frame, str(radius), ply], check=True, capture_output=True, text=True, env=env)
    times, faults, cpu = json.loads(out.stdout)
    return times[0], statistics.median(times[1:]), faults, cpu


def summary(name, values):
    values = sorted(values)
    if name.endswith("faults"):
        return f"{name:<30} min {values[0]:8.0f}  median {statistics.median(values):8.0f}  max {values[-1]:8.0f}"
    return f"{name:<30} min {values[0]:8.3f}  median {statistics.median(values):8.3f}  max {values[-1]:8.3f} s"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=12)
    parser.add_argument("--input", default=str(ROOT / "datasets" / "dambreak_small" / "ParticleData_Fluid_25.xyz"))
    parser.add_argument("--radius", type=float, default=0.012)
    parser.add_argument("--variant", action="append", default=[], metavar="NAME=DIR")
    args = parser.parse_args()
    variants = [tuple(v.split("=", 1)) for v in args.variant] or [("python", "")]
    binary = cli_binary()
    columns = {"cli work": [], "cli process": [], "cli process cpu": [], "cli process minor faults": []}
    for name, _ in variants:
        for column in ("first call", "later calls", "first call cpu", "first call minor faults"):
            columns[f"{name} {column}"] = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.rounds):
            work, process, faults, cpu = run_cli(binary, args.input, args.radius, tmp, "cli.ply")
            line = [f"round {k + 1:2}: cli work {work:.3f} s (process {process:.3f} s, {faults} faults)"]
            for column, value in (("work", work), ("process", process), ("process cpu", cpu), ("process minor faults", faults)):
                columns[f"cli {column}"].append(value)
            for name, path in variants:
                ply = os.path.join(tmp, "py.ply") if k == 0 else ""
                first, later, faults, cpu = run_python(args.input, args.radius, ply, path)
                if k == 0 and pathlib.Path(tmp, "cli.ply").read_bytes() != pathlib.Path(ply).read_bytes():
                    sys.exit(f"{name}: the CLI and the package made different surfaces, not the same work")
                for column, value in (("first call", first), ("later calls", later), ("first call cpu", cpu), ("first call minor faults", faults)):
                    columns[f"{name} {column}"].append(value)
                line.append(f"{name} first call {first:.3f} s ({faults} faults), later calls {later:.3f} s")
            print(", ".join(line), flush=True)
    print()
    for name, values in columns.items():
        print(summary(name, values))
    cli = statistics.median(columns["cli work"])
    for name, _ in variants:
        for column in ("first call", "later calls"):
            ratio = statistics.median(columns[f"{name} {column}"]) / cli
            print(f"{name} {column} / cli work (medians): {ratio:.3f}")


if __name__ == "__main__":
    main()
