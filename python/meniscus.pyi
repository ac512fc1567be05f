"""Surface reconstruction for particle-based fluids (Akinci et al. 2013 pipeline), in process.

Options are named as the ``meniscus reconstruct`` command line's, with the same defaults and
units: lengths in multiples of the particle radius ``r`` unless said otherwise. The GIL is
released while the library works; Ctrl-C stops a run with ``KeyboardInterrupt``.

Errors: ``ValueError`` for an option that cannot work (the message names it, e.g.
``particle_radius``), ``OSError`` (``FileNotFoundError``, ...) for files that cannot be read
or written, ``FormatError`` (a ``ValueError``) for malformed or unsupported files,
``FileExistsError`` for frames an archive already holds, ``RuntimeError`` for internal errors.
"""

import os
from typing import Any, Mapping, Sequence, Union

import numpy as np
import numpy.typing as npt

__version__: str

_Path = Union[str, os.PathLike[str]]

class FormatError(ValueError):
    """A particle, mesh or archive file whose content is malformed or whose format is not supported."""

class Mesh:
    """A reconstructed surface: the fluid surface and the isolated-particle spheres.

    ``vertices``/``triangles`` hold the fluid surface followed by every sphere, as the CLI's
    PLY/OBJ/VTK output does; ``write`` writes exactly the CLI's file.
    """

    @property
    def vertices(self) -> npt.NDArray[np.float32]:
        """Vertex positions, (V, 3) float32, world units."""
    @property
    def triangles(self) -> npt.NDArray[np.uint32]:
        """Triangles, (T, 3) uint32 vertex indices, counter-clockwise seen from outside."""
    @property
    def normals(self) -> npt.NDArray[np.float32]:
        """Unit vertex normals, (V, 3) float32 ((0, 3) when the mesh has none)."""
    @property
    def attributes(self) -> dict[str, npt.NDArray[np.float32]]:
        """Per-vertex attributes carried from the particles: name -> (V,) or (V, k) float32."""
    @property
    def stats(self) -> dict[str, Any]:
        """The run's figures as the CLI's ``--stats`` JSON: counts and ``stages`` (stage,
        seconds, triangles, peak_rss_bytes); empty for a mesh read from an archive."""
    @property
    def vertex_count(self) -> int:
        """Number of vertices."""
    @property
    def triangle_count(self) -> int:
        """Number of triangles."""
    def write(self, path: _Path, *, normals: bool = True) -> int:
        """Writes the surface to ``path`` (.ply, .obj, .glb, .gltf or .vtk by extension), as the
        CLI does (glTF keeps the spheres instanced); returns the bytes written."""

def reconstruct(
    positions: npt.ArrayLike,
    particle_radius: float,
    *,
    attributes: Mapping[str, npt.ArrayLike] | None = None,
    influence_radius: float = 4.0,
    cell_size: float = 1.0,
    decimate: float | None = 0.8,
    subdivide: int = 1,
    isolated_spheres: int | None = 2,
    iso_offset: float = 0.0,
    threads: int | None = None,
    memory_budget: int | str | None = None,
) -> Mesh:
    """Reconstructs the surface of the particles at ``positions``.

    Args:
        positions: (N, 3) float32 or float64 array, world units. A C-contiguous float32
            array is used in place, not copied.
        particle_radius: ``r``, world units (> 0).
        attributes: name -> (N,) or (N, k) array of per-particle values (e.g. velocity),
            carried to the surface vertices (``Mesh.attributes``).
        influence_radius: kernel support, multiples of r.
        cell_size: lattice cell size, multiples of r.
        decimate: fraction of triangles removed by quadric decimation, in [0, 1); None: off.
        subdivide: Loop subdivision steps after decimation (0: off).
        isolated_spheres: icosphere level of the spheres standing for isolated particles;
            None keeps them in the field.
        iso_offset: iso-level offset, as the CLI's ``--iso-offset``.
        threads: worker threads (default: all cores). The output does not depend on it.
        memory_budget: bytes, or a size such as ``"2GiB"``; default: the available memory.
    """

def read_particles(path: _Path) -> tuple[npt.NDArray[np.float32], dict[str, npt.NDArray[np.float32]]]:
    """Reads a particle file (.xyz, .vtk, .ply, .bgeo, by extension): positions (N, 3)
    float32 and every point attribute, name -> (N,) or (N, k) float32."""

def reconstruct_file(
    input: str,
    output: str,
    particle_radius: float,
    *,
    attributes: str | Sequence[str] | None = None,
    influence_radius: float = 4.0,
    cell_size: float = 1.0,
    decimate: float | None = 0.8,
    subdivide: int = 1,
    isolated_spheres: int | None = 2,
    iso_offset: float = 0.0,
    threads: int | None = None,
    memory_budget: int | str | None = None,
    normals: bool = True,
    skip_existing: bool = False,
    error_bound: float | None = None,
    attribute_error_bound: float = 1e-3,
    fps: float = 24.0,
) -> list[dict[str, Any]]:
    """Reconstructs a particle file, or a ``{}`` frame sequence, into ``output`` as
    ``meniscus reconstruct INPUT -o OUTPUT`` does: a mesh file, a ``{}`` pattern of them, one
    ``.mseq`` archive or one ``.glb``/``.gltf`` for a sequence.

    ``attributes``: None (the velocity when the input has one), ``"none"``, ``"all"``,
    ``"a,b"`` or a list of names. ``error_bound`` (world units, default 0.01 r) and
    ``attribute_error_bound`` apply to ``.mseq`` outputs. Returns one report per frame, as
    the CLI's ``--stats`` JSON.
    """

class Archive:
    """A ``.mseq`` archive: one mesh per frame number. The file is created by the first append."""

    def __init__(self, path: _Path, *, error_bound: float | None = None, attribute_error_bound: float = 1e-3) -> None:
        """``error_bound`` (world units) bounds the positions of appended frames: by default
        the archive's own, or 0.01 x the particle radius of the first mesh appended."""
    def __len__(self) -> int:
        """Number of frames held."""
    def __contains__(self, frame: int) -> bool: ...
    @property
    def frames(self) -> list[int]:
        """Frame numbers held, in file order."""
    def __getitem__(self, frame: int) -> Mesh:
        """The decoded mesh of ``frame`` (with normals); KeyError when not held."""
    def append(self, frame: int, mesh: Mesh, *, error_bound: float | None = None) -> int:
        """Appends ``mesh`` as ``frame``; returns the bytes written. A frame number already
        held raises FileExistsError."""
    def verify(self) -> dict[str, Any]:
        """Decodes and checks every frame: ``clean``, ``good``, ``damaged``, ``damage``,
        ``trailing_bytes``, ``recovered_by_scan``."""
