"""Shared fixtures: the dambreak frame 25 and the CLI's output for it."""

import os
import pathlib
import subprocess

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
DATA = ROOT / "datasets" / "dambreak_small"
RADIUS = 0.012


def cli_command(*args):
    """The command line running the meniscus CLI of this checkout (built by cargo,
    honouring CARGO_TARGET_DIR) with ``args``."""
    binary = os.environ.get("MENISCUS_BIN")
    command = [binary] if binary else ["cargo", "run", "--release", "--quiet", "--bin", "meniscus", "--"]
    return command + [str(a) for a in args]


def run_cli(*args):
    """Runs the meniscus CLI with ``args``; it must succeed."""
    subprocess.run(cli_command(*args), cwd=ROOT, check=True)


@pytest.fixture(scope="session")
def frame25():
    """Frame 25's positions, (N, 3) float32 (raw little-endian .xyz)."""
    return np.fromfile(DATA / "ParticleData_Fluid_25.xyz", dtype="<f4").reshape(-1, 3)


@pytest.fixture(scope="session")
def cli_ply(tmp_path_factory):
    """The CLI's PLY of frame 25 with default options."""
    out = tmp_path_factory.mktemp("cli") / "b.ply"
    run_cli("reconstruct", DATA / "ParticleData_Fluid_25.xyz", "--particle-radius", RADIUS, "-o", out, "--quiet")
    return out
