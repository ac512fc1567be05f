#!/usr/bin/env python3
"""Large-scale surface fits applied to a finished mesh: the experiment behind "Why the
sphere and box goals stay open" in docs/quality.md. Not part of the pipeline.

Each mesh vertex is projected onto an algebraic sphere (APSS, Guennebaud & Gross 2007)
fitted within a ball of radius H around it, to either

  mesh       the mesh's own vertices and normals (a curvature-keeping smoothing), or
  particles  the particle centres, weighted by how far each lies off the centroid of its
             4 r neighbourhood (interior particles weigh nothing), with that offset as
             normal; the vertex goes to r outside the fitted surface.

    VENV/bin/python benches/fit_experiment.py {mesh,particles} IN.ply PARTICLES.xyz R H OUT.ply

R is the particle radius, H the fit radius in multiples of R. Then measure OUT.ply with
shared/eval/meshq.py. Needs numpy, scipy and trimesh (meshq's venv).
"""
import sys

import numpy as np
import trimesh
from scipy.spatial import cKDTree


def fit(p, n, w):
    """Algebraic sphere u0 + u·x + u4|x|² through weighted points with normals, scaled
    so that its gradient has unit length on the surface; None when degenerate."""
    W = w.sum()
    if W < 1e-9:
        return None
    sp = w @ p / W
    sn = w @ n / W
    spn = w @ (p * n).sum(1) / W
    spp = w @ (p * p).sum(1) / W
    den = spp - sp @ sp
    if den <= 1e-20:
        return None
    u4 = 0.5 * (spn - sp @ sn) / den
    u = sn - 2 * u4 * sp
    u0 = -(u @ sp) - u4 * spp
    g2 = u @ u - 4 * u0 * u4
    if g2 <= 0:
        return None
    s = 1 / np.sqrt(g2)
    return u0 * s, u * s, u4 * s


def project(x, sphere, offset):
    """x moved onto the level set `offset` outside the algebraic sphere."""
    u0, u, u4 = sphere
    if abs(u4) < 1e-6:
        nu = np.linalg.norm(u)
        return x - ((u0 + u @ x) / nu - offset) * u / nu
    c = -u / (2 * u4)
    rad = np.sqrt(max(c @ c - u0 / u4, 0.0))
    new = rad + offset if u4 > 0 else rad - offset
    if new <= 0:
        return x
    v = x - c
    return c + new * v / np.linalg.norm(v)


def main():
    mode, mesh_in, particles, r, hf, out = sys.argv[1:7]
    r, h = float(r), float(hf) * float(r)
    m = trimesh.load(mesh_in, process=False)
    V = np.asarray(m.vertices, float)
    VN = np.asarray(m.vertex_normals, float)
    if mode == "mesh":
        src, nrm, weight, offset = V, VN, np.ones(len(V)), 0.0
    else:
        P = np.fromfile(particles, dtype="<f4").reshape(-1, 3).astype(float)
        tree = cKDTree(P)
        off = P - np.array([P[i].mean(0) for i in tree.query_ball_point(P, 4 * r)])
        mag = np.linalg.norm(off, axis=1)
        src, nrm, offset = P, off / np.maximum(mag, 1e-12)[:, None], r
        weight = np.clip(mag / (0.3 * 4 * r), 0, 1)
    tree = cKDTree(src)
    res = V.copy()
    for k, idx in enumerate(tree.query_ball_point(V, h)):
        idx = np.asarray(idx, int)
        if len(idx) == 0:
            continue
        d2 = ((src[idx] - V[k]) ** 2).sum(1) / h**2
        agree = np.clip(nrm[idx] @ VN[k], 0, 1)
        w = (1 - d2) ** 4 * weight[idx] * (agree**2 if mode == "mesh" else agree)
        sphere = fit(src[idx], nrm[idx], w)
        if sphere is not None:
            res[k] = project(V[k], sphere, offset)
    trimesh.Trimesh(res, m.faces, process=False).export(out)


if __name__ == "__main__":
    main()
