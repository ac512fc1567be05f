#!/usr/bin/env python3
"""The steady smoothing with guided feature weights, prototyped on the CLI's raw steady
mesh: the experiment behind "Guided feature weights" in docs/quality.md. Not part of the
pipeline.

The raw steady surface (`--preset steady --smooth 0 --keep-inside off
--normal-smoothing 0`) is smoothed here by STEPS plain Laplacian steps (Jacobi order, every
vertex to its neighbours' mean), no vertex moved more than BOUND·r inwards along its
starting normal (the preset's smoothing, `--smooth-max-inward`), and with `--sigma` the
feature weights: where a plain step would move a vertex inwards, each neighbour counts
with `exp(-(angle / sigma)^2)`, the angle between the two vertices' normals on a guidance
copy of the raw surface smoothed GUIDE plain steps (unbounded); outward moves stay plain.

    VENV/bin/python benches/feature_weights.py PARTICLES.xyz R OUT.ply [--sigma DEG]
        [--guide K] [--steps N] [--bound B] [--meniscus PATH]

PARTICLES.xyz is raw little-endian f32 x y z; R the particle radius. Then measure OUT.ply
with shared/eval/meshq.py (`--particles`, `--sphere`), multiscale_bump.py and, over a
sequence, seq_flicker.py `--shading` (OUT.ply carries no normals). Needs numpy, scipy and
trimesh (meshq's venv).
"""
import argparse
import os
import subprocess
import tempfile

import numpy as np
import scipy.sparse as sp
import trimesh


def vertex_normals(X, F):
    """Area-weighted vertex normals of positions X over triangles F."""
    fn = np.cross(X[F[:, 1]] - X[F[:, 0]], X[F[:, 2]] - X[F[:, 0]])
    vn = np.zeros_like(X)
    for k in range(3):
        np.add.at(vn, F[:, k], fn)
    return vn / (np.linalg.norm(vn, axis=1)[:, None] + 1e-30)


def smooth(V, F, r, steps=10, bound=0.2, sigma=0.0, guide=15):
    e = np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), 1), axis=0)
    rows, cols = np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]]
    A = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(V), len(V)))
    deg = np.asarray(A.sum(1)).ravel()
    N0 = vertex_normals(V, F)
    W = None
    if sigma > 0:
        G = V.copy()
        for _ in range(guide):
            G = (A @ G) / deg[:, None]
        gn = vertex_normals(G, F)
        angle = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", gn[rows], gn[cols]), -1, 1)))
        W = sp.csr_matrix((np.exp(-(angle / sigma) ** 2), (rows, cols)), shape=A.shape)
        wsum = np.asarray(W.sum(1)).ravel()
    X = V.copy()
    for _ in range(steps):
        move = (A @ X) / deg[:, None] - X
        if W is not None:
            weighted = ((W @ X) - wsum[:, None] * X) / deg[:, None]
            inwards = np.einsum("ij,ij->i", move, gn) < 0
            move = np.where(inwards[:, None], weighted, move)
        Y = X + move
        inward = -np.einsum("ij,ij->i", Y - V, N0)
        over = inward > bound * r
        Y[over] += (inward[over] - bound * r)[:, None] * N0[over]
        X = Y
    return X


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("particles")
    ap.add_argument("radius", type=float)
    ap.add_argument("out")
    ap.add_argument("--sigma", type=float, default=0.0, help="feature weights' angle, degrees (0: plain steps)")
    ap.add_argument("--guide", type=int, default=15, help="plain steps of the guidance copy")
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--bound", type=float, default=0.2, help="inward bound, multiples of r")
    ap.add_argument("--meniscus", default=os.path.join(os.path.dirname(__file__), "..", "target", "release", "meniscus"))
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        raw = os.path.join(tmp, "raw.ply")
        subprocess.run([a.meniscus, "reconstruct", a.particles, "-r", str(a.radius), "--preset", "steady",
                        "--smooth", "0", "--keep-inside", "off", "--normal-smoothing", "0",
                        "-o", raw, "--quiet", "--no-radius-check"], check=True)
        m = trimesh.load(raw, process=False)
    V, F = np.asarray(m.vertices, float), np.asarray(m.faces)
    X = smooth(V, F, a.radius, a.steps, a.bound, a.sigma, a.guide)
    trimesh.Trimesh(X, F, process=False).export(a.out)


if __name__ == "__main__":
    main()
