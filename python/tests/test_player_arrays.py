"""The arrays a player swaps in per frame (the Blender extension's): the fluid alone, its
edges as Blender stores them, the droplets' attributes and radius."""

import numpy as np

import meniscus
from conftest import DATA, RADIUS


def test_fluid_arrays_are_the_merged_mesh_without_the_spheres():
    positions, attributes = meniscus.read_particles(DATA / "ParticleData_Fluid_25.vtk")
    mesh = meniscus.reconstruct(positions, RADIUS, attributes={"velocity": attributes["velocity"]})
    vertices, triangles, normals, fluid_attributes = mesh.fluid()
    v, t = len(vertices), len(triangles)
    assert np.array_equal(vertices, mesh.vertices[:v])
    assert np.array_equal(triangles, mesh.triangles[:t])
    assert np.array_equal(normals, mesh.normals[:v])
    assert np.array_equal(fluid_attributes["velocity"], mesh.attributes["velocity"][:v])
    spheres = len(mesh.sphere_centers)
    assert spheres > 0
    # Every sphere vertex carries its particle's value; the sphere's radius is r.
    per = (len(mesh.vertices) - v) // spheres
    drops = mesh.sphere_attributes["velocity"]
    assert drops.shape == (spheres, 3)
    assert np.array_equal(drops, mesh.attributes["velocity"][v::per])
    assert abs(mesh.sphere_radius - RADIUS) < 1e-6 * RADIUS + 1e-9


def test_fluid_edges_number_every_side_once():
    positions = np.fromfile(DATA / "ParticleData_Fluid_25.xyz", dtype="<f4").reshape(-1, 3)
    mesh = meniscus.reconstruct(positions, RADIUS)
    _, triangles, _, _ = mesh.fluid()
    edges, corner_edges = mesh.fluid_edges()
    assert edges.dtype == np.int32 and corner_edges.dtype == np.int32
    assert len(corner_edges) == 3 * len(triangles)
    # Side k of a triangle joins corners k and k + 1: its edge has those two vertices.
    a = triangles.ravel()
    b = np.roll(triangles, -1, axis=1).ravel()
    ends = edges[corner_edges]
    assert np.array_equal(np.sort(ends, axis=1), np.sort(np.stack([a, b], axis=1), axis=1))
    # Each vertex pair once, every edge used (a closed manifold surface: by two sides).
    pairs = np.sort(edges, axis=1)
    assert len(np.unique(pairs, axis=0)) == len(edges)
    uses = np.bincount(corner_edges, minlength=len(edges))
    assert uses.min() >= 1 and (uses == 2).mean() > 0.99


def manifold_numbering(triangles):
    """The edges of a closed, consistently oriented triangle mesh numbered as
    ``fluid_edges`` numbers them (the sides with a < b, in side order; every other side
    takes its twin's), or None when the mesh is not one."""
    a = triangles.ravel().astype(np.int64)
    b = np.roll(triangles, -1, axis=1).ravel().astype(np.int64)
    own = a < b
    keys = (a << 32) | b
    order = np.argsort(keys[own])
    own_keys = keys[own][order]
    if len(np.unique(own_keys)) != len(own_keys) or 2 * own.sum() != len(a):
        return None
    numbers = np.full(len(a), -1, dtype=np.int64)
    numbers[own] = np.arange(own.sum())
    twin = (b[~own] << 32) | a[~own]
    at = np.searchsorted(own_keys, twin).clip(0, len(own_keys) - 1)
    if not np.array_equal(own_keys[at], twin) or len(np.unique(at)) != len(at):
        return None
    numbers[~own] = numbers[own][order][at]
    edges = np.stack([a[own], b[own]], axis=1)
    return edges.astype(np.int32), numbers.astype(np.int32)


def test_subdivided_surfaces_number_their_edges_as_any_closed_surface(tmp_path, frame25):
    """Subdivided surfaces (a reconstruction's and an archive's two Loop steps, numbered
    through the layout of a Loop step) get the same edges, in the same order, as the
    numbering of any closed surface; so does one that is not subdivided."""
    archive = meniscus.Archive(tmp_path / "a.mseq")
    for subdivide in (0, 1, 2):
        mesh = meniscus.reconstruct(frame25, RADIUS, subdivide=subdivide, defer_subdivision=subdivide > 0)
        archive.append(subdivide, mesh, subdivide=subdivide)
    meshes = [meniscus.reconstruct(frame25, RADIUS, subdivide=1)] + [archive[n] for n in (0, 1, 2)]
    closed = 0
    for mesh in meshes:
        _, triangles, _, _ = mesh.fluid()
        edges, corner_edges = mesh.fluid_edges()
        want = manifold_numbering(triangles)
        if want is None:
            continue
        closed += 1
        assert np.array_equal(edges, want[0])
        assert np.array_equal(corner_edges, want[1])
    assert closed >= 3
