"""A 12-frame sequence through a Dask LocalCluster against the CLI in one process.

Not run by CI. Needs the Python package and dask[distributed] in the active environment,
and the CLI and the `tile_scene` example built by cargo in the same target directory:

    cargo build --release --bin meniscus --example tile_scene
    python benches/dask_sequence.py [--rounds 3] [--workers 2] [--shards 4] [--dir DIR]

The sequence: `tile_scene` makes frame 25 × 8 (335 296 particles, the copies side by side
in x and z); frame k of 12 is that scene moved by k · 0.05 r in x with every particle
jittered by up to 0.1 r (seeded by k), so each frame is its own reconstruction. Each
round runs, alternately:

* cli: `meniscus reconstruct 'seq_{}.xyz' -r 0.012 -o cli.mseq -q` under
  `/usr/bin/time -v` (one process, all cores);
* dask: a fresh `LocalCluster(n_workers, threads_per_worker=1, processes=True)`; each of
  `--shards` tasks runs `meniscus.reconstruct_file(..., shard=(i, n), threads=cores //
  workers)` into its own archive and reports its worker's peak RSS (getrusage, the
  worker process's own peak since it started); then `merge_archives`. The merged archive
  must equal the CLI's byte for byte (the same work).
* dask, glibc malloc: the same with Dask's `MALLOC_TRIM_THRESHOLD_=65536` (which Dask sets
  in its workers to return freed memory early: `distributed.nanny.pre-spawn-environ`)
  unset, so the workers' allocator is glibc's default, as in the CLI before its tuning.

Reported: frames/s (12 / wall time of the frames; the cluster's start and the merge
timed apart) and peak RSS: the CLI process's, each worker's before the tasks (Python,
Dask and the package loaded) and after them.
"""

import argparse
import os
import pathlib
import re
import resource
import shutil
import statistics
import subprocess
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
RADIUS = 0.012
FRAMES = 12


def target_dir():
    return pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))


def generate(directory):
    """Frames seq_1.xyz ... seq_12.xyz (raw little-endian float32)."""
    scene = directory / "scene8.xyz"
    if not scene.exists():
        tile_scene = target_dir() / "release" / "examples" / "tile_scene"
        subprocess.run([str(tile_scene), str(ROOT / "datasets/dambreak_small/ParticleData_Fluid_25.xyz"), "8", str(scene)], check=True)
    base = np.fromfile(scene, dtype="<f4").reshape(-1, 3)
    for k in range(1, FRAMES + 1):
        path = directory / f"seq_{k}.xyz"
        if path.exists():
            continue
        rng = np.random.default_rng(k)
        frame = base + np.float32(k * 0.05 * RADIUS) * np.array([1, 0, 0], dtype=np.float32)
        frame += rng.uniform(-0.1 * RADIUS, 0.1 * RADIUS, size=frame.shape).astype(np.float32)
        frame.astype("<f4").tofile(path)
    return len(base)


def run_cli(directory):
    out = directory / "cli.mseq"
    out.unlink(missing_ok=True)
    binary = os.environ.get("MENISCUS_BIN") or str(target_dir() / "release" / "meniscus")
    start = time.perf_counter()
    done = subprocess.run(
        ["/usr/bin/time", "-v", binary, "reconstruct", str(directory / "seq_{}.xyz"), "-r", str(RADIUS), "-o", str(out), "-q"],
        check=True, capture_output=True, text=True,
    )
    wall = time.perf_counter() - start
    peak_kib = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", done.stderr).group(1))
    return wall, peak_kib / 1024


def peak_rss_mib():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def reconstruct_shard(index, count, pattern, parts, threads):
    import meniscus

    archive = os.path.join(parts, f"part_{index}.mseq")
    reports = meniscus.reconstruct_file(pattern, archive, RADIUS, shard=(index, count), threads=threads)
    return archive, os.getpid(), len(reports), peak_rss_mib()


def run_dask(directory, workers, shards, dask_trim):
    import dask
    from dask.distributed import Client, LocalCluster

    import meniscus

    parts = directory / "parts"
    shutil.rmtree(parts, ignore_errors=True)
    parts.mkdir()
    threads = max(1, (os.cpu_count() or 1) // workers)
    start = time.perf_counter()
    environ = {} if dask_trim else {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}
    with dask.config.set(environ), LocalCluster(
        n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster, Client(cluster) as client:
        # Load the package in every worker before the clock starts, as a running cluster has.
        client.run(lambda: __import__("meniscus") and None)
        before = client.run(peak_rss_mib)
        started = time.perf_counter() - start
        start = time.perf_counter()
        futures = client.map(reconstruct_shard, range(shards), count=shards, pattern=str(directory / "seq_{}.xyz"), parts=str(parts), threads=threads)
        results = client.gather(futures)
        wall = time.perf_counter() - start
        after = client.run(peak_rss_mib)
    start = time.perf_counter()
    merged = directory / "dask.mseq"
    merged.unlink(missing_ok=True)
    meniscus.merge_archives([r[0] for r in results], merged)
    merge = time.perf_counter() - start
    same = merged.read_bytes() == (directory / "cli.mseq").read_bytes()
    frames_per_worker = {}
    for _, pid, frames, _ in results:
        frames_per_worker[pid] = frames_per_worker.get(pid, 0) + frames
    return wall, started, merge, sorted(before.values()), sorted(after.values()), same, sorted(frames_per_worker.values()), threads


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--shards", type=int, default=4)
    parser.add_argument("--dir", default="/tmp/meniscus-dask-sequence", help="where the frames are generated (kept for later runs)")
    args = parser.parse_args()
    directory = pathlib.Path(args.dir)
    directory.mkdir(parents=True, exist_ok=True)
    particles = generate(directory)
    print(f"{FRAMES} frames of {particles} particles in {directory}")
    fps = {"cli": [], "dask": [], "dask, glibc malloc": []}
    for k in range(args.rounds):
        wall, peak = run_cli(directory)
        fps["cli"].append(FRAMES / wall)
        print(f"round {k + 1}: cli {wall:.2f} s = {FRAMES / wall:.2f} frames/s, peak RSS {peak:.0f} MiB", flush=True)
        for name, dask_trim in (("dask", True), ("dask, glibc malloc", False)):
            wall, started, merge, before, after, same, split, threads = run_dask(directory, args.workers, args.shards, dask_trim)
            fps[name].append(FRAMES / wall)
            print(
                f"round {k + 1}: {name} {wall:.2f} s = {FRAMES / wall:.2f} frames/s ({args.workers} workers × {threads} thread(s), "
                f"{args.shards} shards, frames per worker {split}; cluster start {started:.1f} s, merge {merge:.3f} s), "
                f"worker peak RSS before {', '.join(f'{m:.0f}' for m in before)} MiB, after {', '.join(f'{m:.0f}' for m in after)} MiB; "
                f"merged archive {'equals' if same else 'DIFFERS FROM'} the CLI's",
                flush=True,
            )
            if not same:
                sys.exit("the merged archive differs from the CLI's: not the same work")
    for name, values in fps.items():
        print(f"{name} frames/s: {min(values):.2f}–{max(values):.2f} (median {statistics.median(values):.2f})")


if __name__ == "__main__":
    main()
