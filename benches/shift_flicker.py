#!/usr/bin/env python3
"""Lattice shimmer (issue 36): how much a reconstructed surface changes when the whole fluid
moves by a fraction of a cell. A surface that depends only on the particles moves with them;
one that depends on the marching-cubes lattice changes shape as the fluid drifts, which an
animation shows as crawling highlights.

For k = 0 .. K-1 every particle is shifted by d_k = (k/K) h (1, 0.618, 0.382) (h the tool's
cell size, world units); two fixed anchor particles far from the fluid pin the bounding box,
so that a tool aligning its grid to the bounding box cannot follow the shift. Each shifted
frame is reconstructed by COMMAND, the triangles near the anchors are dropped, the mesh is
shifted back by -d_k and compared with the k = 0 mesh:

* distance: points sampled uniformly by area on each mesh, exact distance to the closest
  point of the other mesh, both directions pooled: mean and 99th percentile, in r;
* normal change: angle between the face normals at a sample and at its closest point:
  mean and 95th percentile, degrees;
* volume change: largest |V_k - V_0| / V_0 (enclosed volume by the divergence theorem).

Each row is one k against k = 0; the last row is the mean over k (the largest for p99, p95
and the volume). Not a test: a benchmark for any command (meniscus, splashsurf).

    python3 benches/shift_flicker.py PARTICLES.xyz RADIUS [--cell H] [-k K] [--keep DIR] \
        -- COMMAND ... {in} ... {out} ...

PARTICLES: raw little-endian f32 triples (.xyz). `{in}` is replaced by the shifted .xyz,
`{out}` by the mesh path (PLY, binary or ASCII, or OBJ: the extension of `--out-ext`, default
.ply). H defaults to RADIUS (meniscus's default cell). Example, frame 25 with the default
pipeline:

    python3 benches/shift_flicker.py datasets/dambreak_small/ParticleData_Fluid_25.xyz 0.012 \
        -- target/release/meniscus reconstruct {in} -r 0.012 -q -o {out}

Needs numpy and scipy.
"""
import argparse
import os
import subprocess
import sys
import tempfile

import numpy as np
from scipy.spatial import cKDTree

DIRECTION = np.array([1.0, 0.618, 0.382])
SAMPLES = 200_000
CANDIDATES = 16


def read_ply(path):
    with open(path, "rb") as f:
        data = f.read()
    end = data.index(b"end_header") + len(b"end_header")
    end = data.index(b"\n", end) + 1
    header = data[:end].decode("ascii", "replace").splitlines()
    fmt = None
    elements = []
    for line in header:
        w = line.split()
        if not w:
            continue
        if w[0] == "format":
            fmt = w[1]
        elif w[0] == "element":
            elements.append([w[1], int(w[2]), []])
        elif w[0] == "property":
            elements[-1][2].append(w[1:])
    sizes = {"char": "i1", "uchar": "u1", "int8": "i1", "uint8": "u1", "short": "i2",
             "ushort": "u2", "int16": "i2", "uint16": "u2", "int": "i4", "uint": "u4",
             "int32": "i4", "uint32": "u4", "float": "f4", "float32": "f4",
             "double": "f8", "float64": "f8"}
    V = F = None
    if fmt == "ascii":
        words = data[end:].split()
        pos = 0
        for name, count, props in elements:
            if name == "vertex":
                n = len(props)
                arr = np.array(words[pos:pos + n * count], dtype=np.float64).reshape(count, n)
                names = [p[-1] for p in props]
                V = arr[:, [names.index(a) for a in "xyz"]]
                pos += n * count
            elif name == "face":
                tris = []
                for _ in range(count):
                    k = int(words[pos])
                    idx = [int(x) for x in words[pos + 1:pos + 1 + k]]
                    pos += 1 + k
                    tris += [[idx[0], idx[i], idx[i + 1]] for i in range(1, k - 1)]
                F = np.array(tris, dtype=np.int64).reshape(-1, 3)
            else:
                raise SystemExit(f"{path}: ASCII element {name} not supported")
        return V, F
    order = "<" if fmt == "binary_little_endian" else ">"
    pos = end
    for name, count, props in elements:
        if name == "face":
            p = props[0]
            if p[0] != "list":
                raise SystemExit(f"{path}: face without a list property")
            dt = np.dtype([("n", order + sizes[p[1]]), ("i", order + sizes[p[2]], 3)])
            arr = np.frombuffer(data, dt, count, pos)
            if count and not np.all(arr["n"] == 3):
                raise SystemExit(f"{path}: only triangles are supported")
            F = arr["i"].astype(np.int64)
            pos += dt.itemsize * count
        else:
            if any(p[0] == "list" for p in props):
                raise SystemExit(f"{path}: list property in element {name}")
            dt = np.dtype([(p[1], order + sizes[p[0]]) for p in props])
            arr = np.frombuffer(data, dt, count, pos)
            if name == "vertex":
                V = np.stack([arr[a].astype(np.float64) for a in "xyz"], 1)
            pos += dt.itemsize * count
    return V, F


def read_obj(path):
    V, F = [], []
    with open(path) as f:
        for line in f:
            w = line.split()
            if not w:
                continue
            if w[0] == "v":
                V.append([float(x) for x in w[1:4]])
            elif w[0] == "f":
                idx = [int(x.split("/")[0]) for x in w[1:]]
                idx = [i - 1 if i > 0 else len(V) + i for i in idx]
                F += [[idx[0], idx[i], idx[i + 1]] for i in range(1, len(idx) - 1)]
    return np.array(V, np.float64), np.array(F, np.int64).reshape(-1, 3)


def read_mesh(path):
    return read_obj(path) if path.endswith(".obj") else read_ply(path)


class Surface:
    def __init__(self, V, F):
        self.A = V[F[:, 0]]
        self.AB = V[F[:, 1]] - self.A
        self.AC = V[F[:, 2]] - self.A
        n = np.cross(self.AB, self.AC)
        self.area2 = np.linalg.norm(n, axis=1)
        keep = self.area2 > 0
        self.A, self.AB, self.AC, n, self.area2 = (
            self.A[keep], self.AB[keep], self.AC[keep], n[keep], self.area2[keep])
        self.normal = n / self.area2[:, None]
        self.tree = cKDTree(self.A + (self.AB + self.AC) / 3)
        self.volume = np.einsum("ij,ij->i", self.A, n).sum() / 6

    def sample(self, count, rng):
        face = rng.choice(len(self.A), count, p=self.area2 / self.area2.sum())
        u, v = rng.random(count), rng.random(count)
        flip = u + v > 1
        u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
        return self.A[face] + u[:, None] * self.AB[face] + v[:, None] * self.AC[face], face

    def closest(self, P):
        """Distance from each point to the surface and the face it is closest to, over the
        faces whose centroids are among the CANDIDATES nearest."""
        _, cand = self.tree.query(P, CANDIDATES, workers=-1)
        best = np.full(len(P), np.inf)
        face = np.zeros(len(P), np.int64)
        for j in range(CANDIDATES):
            f = cand[:, j]
            d2 = closest_on_triangles(P, self.A[f], self.AB[f], self.AC[f])
            better = d2 < best
            best[better] = d2[better]
            face[better] = f[better]
        return np.sqrt(best), face


def closest_on_triangles(P, A, AB, AC):
    """Squared distance from P to triangles (A, A + AB, A + AC), row by row (Ericson,
    Real-Time Collision Detection, 5.1.5)."""
    AP = P - A
    d1 = np.einsum("ij,ij->i", AB, AP)
    d2 = np.einsum("ij,ij->i", AC, AP)
    BP = AP - AB
    d3 = np.einsum("ij,ij->i", AB, BP)
    d4 = np.einsum("ij,ij->i", AC, BP)
    CP = AP - AC
    d5 = np.einsum("ij,ij->i", AB, CP)
    d6 = np.einsum("ij,ij->i", AC, CP)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v = vb / denom
        w = vc / denom
        s = np.stack([np.zeros(len(P)), v, w], 1)  # interior: weights of AB, AC
        # Edges and vertices, later regions overriding earlier ones as in Ericson's order.
        ab = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
        t = d1 / (d1 - d3)
        s[ab] = np.stack([np.zeros(ab.sum()), t[ab], np.zeros(ab.sum())], 1)
        ac = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
        t = d2 / (d2 - d6)
        s[ac] = np.stack([np.zeros(ac.sum()), np.zeros(ac.sum()), t[ac]], 1)
        bc = (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        s[bc] = np.stack([np.zeros(bc.sum()), 1 - t[bc], t[bc]], 1)
    s[(d1 <= 0) & (d2 <= 0)] = 0
    s[(d3 >= 0) & (d4 <= d3)] = [0, 1, 0]
    s[(d6 >= 0) & (d5 <= d6)] = [0, 0, 1]
    Q = A + s[:, 1:2] * AB + s[:, 2:3] * AC
    return np.einsum("ij,ij->i", P - Q, P - Q)


def compare(a, b, r, rng):
    dist, angle = [], []
    for x, y in ((a, b), (b, a)):
        P, fx = x.sample(SAMPLES, rng)
        d, fy = y.closest(P)
        dist.append(d / r)
        cos = np.clip(np.einsum("ij,ij->i", x.normal[fx], y.normal[fy]), -1, 1)
        angle.append(np.degrees(np.arccos(cos)))
    dist, angle = np.concatenate(dist), np.concatenate(angle)
    return (dist.mean(), np.percentile(dist, 99), angle.mean(), np.percentile(angle, 95),
            abs(b.volume - a.volume) / abs(a.volume))


def main():
    argv = sys.argv[1:]
    if "--" not in argv:
        sys.exit(__doc__)
    split = argv.index("--")
    ap = argparse.ArgumentParser(usage=__doc__)
    ap.add_argument("particles")
    ap.add_argument("radius", type=float)
    ap.add_argument("--cell", type=float, help="the tool's cell size h, world units (default: RADIUS)")
    ap.add_argument("-k", type=int, default=4, help="shifts (default 4)")
    ap.add_argument("--out-ext", default=".ply", help="extension of {out} (default .ply)")
    ap.add_argument("--keep", help="directory to keep the shifted inputs and meshes in")
    args = ap.parse_args(argv[:split])
    command = argv[split + 1:]
    if not command or not any("{in}" in c for c in command) or not any("{out}" in c for c in command):
        sys.exit("COMMAND must contain {in} and {out}")
    r, h = args.radius, args.cell or args.radius
    X = np.fromfile(args.particles, "<f4").reshape(-1, 3).astype(np.float64)
    lo, hi = X.min(0), X.max(0)
    pad = 20 * r + 2 * h
    anchors = np.array([lo - pad, hi + pad])
    work = args.keep or tempfile.mkdtemp(prefix="shift_flicker_")
    os.makedirs(work, exist_ok=True)
    rng = np.random.default_rng(1)
    surfaces = []
    print(f"{'k':>3} {'mean d/r':>9} {'p99 d/r':>8} {'mean deg':>9} {'p95 deg':>8} {'volume':>9}")
    rows = []
    for k in range(args.k):
        d = (k / args.k) * h * DIRECTION
        inp = os.path.join(work, f"shift{k}.xyz")
        out = os.path.join(work, f"shift{k}{args.out_ext}")
        np.concatenate([X + d, anchors]).astype("<f4").tofile(inp)
        cmd = [c.replace("{in}", inp).replace("{out}", out) for c in command]
        subprocess.run(cmd, check=True)
        V, F = read_mesh(out)
        centre = V[F].mean(1)
        near = np.zeros(len(F), bool)
        for a in anchors:
            near |= np.linalg.norm(centre - a, axis=1) < 3 * r + 2 * h
        surfaces.append(Surface(V - d, F[~near]))
        if k > 0:
            row = compare(surfaces[0], surfaces[k], r, rng)
            rows.append(row)
            print(f"{k:>3} {row[0]:9.4f} {row[1]:8.4f} {row[2]:9.2f} {row[3]:8.2f} {100 * row[4]:8.3f}%")
    if rows:
        m = np.array(rows)
        print(f"all {m[:, 0].mean():9.4f} {m[:, 1].max():8.4f} {m[:, 2].mean():9.2f} "
              f"{m[:, 3].max():8.2f} {100 * m[:, 4].max():8.3f}%")


if __name__ == "__main__":
    main()
