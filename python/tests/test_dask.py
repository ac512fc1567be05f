"""Frames as tasks on an existing engine: a Dask distributed cluster of two worker
processes reconstructs the shipped dam-break sequence shard by shard, each task into its
own archive; merged, they are the archive one process writes, byte for byte. The same
code runs on a real cluster with ``Client("tcp://scheduler:8786")`` (the paths then on a
shared file system)."""

import os

import pytest

import meniscus
from conftest import DATA, RADIUS, run_cli

distributed = pytest.importorskip("dask.distributed", reason="dask[distributed] is not installed")

PATTERN = str(DATA / "ParticleData_Fluid_{}.xyz")
SHARDS = 3  # more tasks than workers: the scheduler hands them out as workers free up


def reconstruct_shard(index, count, pattern, parts):
    """One task: shard ``index`` of ``count`` into its own archive (never shared: two
    writers must not append to one archive). ``skip_existing`` lets a retried task resume;
    ``keep_going`` keeps a broken frame from costing the others. One thread: the worker
    processes share the cores."""
    archive = os.path.join(parts, f"part_{index}.mseq")
    reports = meniscus.reconstruct_file(
        pattern, archive, RADIUS, shard=(index, count), skip_existing=True, keep_going=True, threads=1
    )
    return archive, os.getpid(), [(r["frame"], r["status"]) for r in reports]


def test_dask_shards_merged_equal_one_process(tmp_path):
    parts = tmp_path / "parts"
    parts.mkdir()
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster, distributed.Client(cluster) as client:
        futures = client.map(reconstruct_shard, range(SHARDS), count=SHARDS, pattern=PATTERN, parts=str(parts))
        results = client.gather(futures)
        workers = set(client.run(os.getpid).values())
    archives = [archive for archive, _, _ in results]
    # Every task ran in one of the cluster's worker processes, not in this one.
    assert len(workers) == 2 and os.getpid() not in workers
    assert {pid for _, pid, _ in results} <= workers
    frames = [f for _, _, done in results for f in done]
    assert all(status == "done" for _, status in frames)
    assert sorted(n for n, _ in frames) == [1, 9, 17, 25, 31, 45]
    merged = tmp_path / "merged.mseq"
    assert meniscus.merge_archives(archives, merged)["frames"] == 6
    # The single-process reference, through the same function, and the CLI's archive.
    one = tmp_path / "one.mseq"
    meniscus.reconstruct_file(PATTERN, str(one), RADIUS)
    cli = tmp_path / "cli.mseq"
    run_cli("reconstruct", PATTERN, "--particle-radius", RADIUS, "-o", cli, "--quiet")
    assert merged.read_bytes() == one.read_bytes() == cli.read_bytes()
    assert meniscus.Archive(merged).verify()["clean"]
