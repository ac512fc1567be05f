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
from typing import Any, Callable, Literal, Mapping, Sequence, TypedDict, Union

from typing_extensions import Unpack

import numpy as np
import numpy.typing as npt

__version__: str

_Path = Union[str, os.PathLike[str]]

class ReconstructOptions(TypedDict, total=False):
    """The reconstruction settings, taken as keywords by ``reconstruct`` and
    ``reconstruct_file`` (``**options``); named as the CLI's flags, with the same defaults.

    Any other keyword is a TypeError naming it; ``None`` for a setting is its default,
    except for ``decimate``, ``decimate_error``, ``isolated_spheres`` and ``keep_inside``,
    which it turns off.
    """

    influence_radius: float
    """Kernel support R, multiples of r. Default 4."""
    cell_size: float
    """Marching-cubes cell size h, multiples of r. Default 1 (``"steady"``: 0.71)."""
    t_low: float
    """Lower eigenvalue threshold of the concavity factor. Default 0.4."""
    t_high: float
    """Upper eigenvalue threshold of the concavity factor. Default 3.5."""
    particle_coverage: float
    """Coverage radius, multiples of r: particles the surface would leave outside are
    enclosed in a ball of this radius (0: off). Default 0.9."""
    iso_offset: float
    """Iso-level offset, multiples of r (moves the surface outwards). Default 0
    (``"steady"``: -0.05)."""
    kernel: Literal["isotropic", "anisotropic"]
    """Particle kernel: ``"isotropic"`` (the paper's Solenthaler field) or
    ``"anisotropic"`` (Yu & Turk 2013 kernels stretched along the local surface).
    Default ``"anisotropic"``; ``**PAPER`` gives the paper's whole pipeline."""
    kernel_radius: float
    """Anisotropic kernels: radius of an unstretched kernel, multiples of r. Default 3.5."""
    max_stretch: float
    """Anisotropic kernels: largest ratio of the longest to the shortest axis. Default 1.75."""
    min_neighbours: int
    """Anisotropic kernels: fewest neighbours within R for a stretched kernel. Default 8."""
    centre_smoothing: float
    """Anisotropic kernels: centre smoothing in [0, 1] (0: the particle positions).
    Default 0."""
    isolated_spheres: int | None
    """Icosphere level of the spheres standing for isolated particles; None keeps them in
    the field. Default 2."""
    decimate: float | str | None
    """Quadric decimation: the fraction of triangles removed, in [0, 1); ``"adaptive"``
    (stop on an error bound only: 0.1 r unless ``decimate_error``); None or ``"off"``.
    Default 0.81 (the paper's 0.8 with the anisotropic surface's triangle count held)."""
    decimate_error: float | None
    """Error bound of decimation, multiples of r (no collapse moves the surface by more);
    with a fraction, whichever is reached first stops it; None: no bound. Default 0.1."""
    smooth: int
    """Smoothing steps after decimation (0: off): remove the field's small bumps.
    Default 2 (``"steady"``: 10)."""
    smooth_method: Literal["taubin", "laplacian"]
    """How the smoothing steps move the vertices: ``"taubin"`` (little shrinkage, the
    finest noise stays) or ``"laplacian"`` (each vertex to its neighbours' mean: removes
    the noise, shrinks unless bounded by ``smooth_max_inward``). Default ``"taubin"``
    (``"steady"``: ``"laplacian"``)."""
    smooth_max_inward: float | None
    """Farthest smoothing may move a vertex inwards, multiples of r; None: no bound.
    Default None (``"steady"``: 0.2)."""
    smooth_feature_angle: float | None
    """Feature weights of the smoothing's inward moves, degrees (Laplacian steps only):
    neighbours whose normals differ by more than about this angle pull less, so the edges
    of resting water and crests stay while flat noise goes; None: plain steps. Default None
    (``"steady"``: 7)."""
    subdivide: int
    """Loop subdivision steps after decimation (0: off). Default 1 (``"steady"``: 0)."""
    defer_subdivision: bool
    """Leave the ``subdivide`` Loop steps to whoever reads the mesh: it comes back as the
    control mesh, its particles kept inside the surface it becomes once subdivided
    (for ``Archive.append(n, mesh, subdivide=...)``, as the CLI's ``.mseq`` does).
    Default False."""
    keep_inside: float | None
    """Least depth of every non-isolated particle centre under the final surface,
    multiples of r, in [0, 1]: where decimation or subdivision left one shallower or
    outside, the surface over it is pushed out; None leaves the surface as they made it.
    Default 0.25."""
    normal_smoothing: int
    """Smoothing steps of the written vertex normals (0: the area-weighted normals):
    steadier shading from frame to frame. Default 0 (``"steady"``: 3)."""
    tile_size: int | None
    """Tile edge in marching-cubes cells; default: from the memory budget."""
    memory_budget: int | str | None
    """Bytes, or a size such as ``"2GiB"``; default: half the available memory."""
    temp_dir: _Path | None
    """Directory of a tiled run's spill file; default: the system's temporary directory."""

PAPER: ReconstructOptions
"""The keywords that make the defaults the pipeline of Akinci et al. 2013 exactly:
``{"particle_coverage": 0.0, "kernel": "isotropic", "decimate": 0.8, "decimate_error": None,
"smooth": 0, "keep_inside": None}`` (``reconstruct(points, r, **PAPER)`` is
``preset="paper"``; the CLI's ``--paper``)."""
STEADY: ReconstructOptions
"""The keywords that make the defaults the steady surface for animation (``preset="steady"``,
the CLI's ``--preset steady``): ``{"cell_size": 0.71, "iso_offset": -0.05, "decimate": None,
"decimate_error": None, "smooth": 10, "smooth_method": "laplacian", "smooth_max_inward": 0.2,
"smooth_feature_angle": 7.0, "subdivide": 0, "normal_smoothing": 3}``."""

VELOCITY_NAMES: tuple[str, ...]
"""The attribute names a file's default attribute selection (``reconstruct_file``'s
``attributes=None``) takes as the velocity, compared ignoring case: ``("v", "vel",
"velocity")``."""

Preset = Literal["still", "steady", "paper"]

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
    def sphere_centers(self) -> npt.NDArray[np.float32]:
        """Centres of the isolated-particle spheres, (S, 3) float32 (their vertices are in
        ``vertices`` after the fluid's)."""
    def fluid(self) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint32], npt.NDArray[np.float32], dict[str, npt.NDArray[np.float32]]]:
        """The fluid surface alone, without the spheres and without merging (what a player
        swaps in each frame): ``(vertices (V, 3), triangles (T, 3), normals (V, 3) or (0, 3),
        attributes name -> (V,) or (V, k))``."""
    def fluid_edges(self) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.int32]]:
        """The fluid surface's edges as Blender's meshes store them: ``(edges (E, 2) int32,
        each vertex pair once, corner_edges (3T,) int32, the edge from corner k of a
        triangle to its next corner)``."""
    @property
    def sphere_attributes(self) -> dict[str, npt.NDArray[np.float32]]:
        """Per-sphere attributes (each isolated particle's value): name -> (S,) or (S, k)
        float32."""
    @property
    def sphere_radius(self) -> float:
        """Radius of the sphere template (the particle radius r; the mean distance of its
        vertices from its centre), 0 without spheres: sphere k has radius
        ``sphere_radius * sphere_scales[k]``."""
    @property
    def sphere_scales(self) -> npt.NDArray[np.float32]:
        """Each sphere's scale, (S,) float32: its radius over the particle radius (1 when the
        particles share one radius)."""
    @property
    def vertex_count(self) -> int:
        """Number of vertices."""
    @property
    def triangle_count(self) -> int:
        """Number of triangles."""
    def write(self, path: _Path, *, normals: bool = True, frame: int = 0) -> int:
        """Writes the surface to ``path`` (.ply, .obj, .glb, .gltf, .vtk, or a USD stage .usdc,
        .usda, .usd, by extension), as the CLI does (glTF keeps the spheres instanced, USD
        has them as a point cloud with widths and velocities); a stage holds it at time code ``frame``. Returns the
        bytes written."""

def reconstruct(
    positions: npt.ArrayLike,
    particle_radius: float | None = None,
    *,
    attributes: Mapping[str, npt.ArrayLike] | None = None,
    threads: int | None = None,
    radius_check: bool = True,
    radius_attribute: str | None = None,
    preset: Preset | None = None,
    **options: Unpack[ReconstructOptions],
) -> Mesh:
    """Reconstructs the surface of the particles at ``positions``.

    Args:
        positions: (N, 3) float32 or float64 array, world units. A C-contiguous float32
            array is used in place, not copied.
        particle_radius: ``r``, world units (> 0). Default: estimated from the particles'
            spacing. A given ``r`` outside 0.5x-2x of the estimate is warned about
            (``UserWarning``); one that would leave most of the fluid's particles
            without a neighbour within the kernel's reach, below 0.05x or above 4x (one blob), is a
            ``ValueError`` (the CLI's message, naming ``radius_check=False``).
        attributes: name -> (N,) or (N, k) array of per-particle values (e.g. velocity),
            carried to the surface vertices (``Mesh.attributes``).
        threads: worker threads (default: all cores). The output does not depend on it.
        radius_check: False takes ``particle_radius`` as given, unchecked.
        radius_attribute: the attribute of ``attributes`` holding each particle's radius
            (``"none"``: none). Default: Houdini's ``pscale`` when present. Without
            ``particle_radius``, ``r`` is its median; a given one is checked against the
            median. Radii must be finite, > 0 and within 10× of their median either way
            (``FormatError`` naming the particle and its value); where they differ each
            particle is meshed with its own radius (influence radius, kernel, coverage
            ball, containment depth, isolated sphere), while the cell size and the other
            lengths stay multiples of ``r``.
        preset: the defaults the ``**options`` start from: ``"still"`` (the best still
            frame; the default), ``"steady"`` (for animation: shading that does not
            flicker from frame to frame) or ``"paper"`` (Akinci et al. 2013 exactly).
        **options: the reconstruction settings (``ReconstructOptions``): influence_radius,
            cell_size, t_low, t_high, particle_coverage, iso_offset, kernel, kernel_radius,
            max_stretch, min_neighbours, centre_smoothing, isolated_spheres, decimate,
            decimate_error, smooth, smooth_method, smooth_max_inward,
            smooth_feature_angle, subdivide, defer_subdivision, keep_inside, normal_smoothing, tile_size, memory_budget,
            temp_dir.
    """

def estimate_radius(positions: npt.ArrayLike) -> float:
    """The particle radius ``r`` the spacing of the particles at ``positions`` implies,
    world units (an SPH number density of a sample of them; within 9 % on the shipped
    frames): what ``reconstruct`` takes without ``particle_radius``."""

def read_particles(path: _Path) -> tuple[npt.NDArray[np.float32], dict[str, npt.NDArray[np.float32]]]:
    """Reads a particle file (.xyz, .vtk, .vtu, .vtp, .ply, .bgeo, by extension): positions (N, 3)
    float32 and every point attribute, name -> (N,) or (N, k) float32."""

def reconstruct_file(
    input: str,
    output: str,
    particle_radius: float | None = None,
    *,
    attributes: str | Sequence[str] | None = None,
    threads: int | None = None,
    radius_check: bool = True,
    radius_attribute: str | None = None,
    frames: str | Sequence[int] | None = None,
    shard: str | tuple[int, int] | None = None,
    start: int | None = None,
    end: int | None = None,
    keep_going: bool = False,
    progress: Callable[[dict[str, Any]], Any] | None = None,
    skip_existing: bool = False,
    normals: bool = True,
    error_bound: float | None = None,
    attribute_error_bound: float = 1e-3,
    fps: float = 24.0,
    up_axis: str = "Y",
    meters_per_unit: float = 1.0,
    usd_droplets: str = "points",
    input_format: str | None = None,
    preset: Preset | None = None,
    **options: Unpack[ReconstructOptions],
) -> list[dict[str, Any]]:
    """Reconstructs a particle file, or a frame sequence (a ``{}`` pattern or a ParaView
    ``.pvd`` collection, whose datasets are frames 0, 1, 2, ... by timestep), into
    ``output`` as ``meniscus reconstruct INPUT -o OUTPUT`` does (the same library function): a mesh
    file, a ``{}`` pattern of them, one ``.mseq`` archive, one ``.glb``/``.gltf`` or one USD
    stage (``.usdc``, ``.usda``, ``.usd``; with ``{}``, a stage per frame) for a sequence. An archive is the CLI's, byte for byte (the control mesh of each frame is
    stored, subdivided when read).

    Args:
        particle_radius, radius_check, radius_attribute: as for ``reconstruct``; from
            the first frame (every frame's radii are checked as it is read).
        attributes: None (the velocity when the input has one), ``"none"``, ``"all"``,
            ``"a,b"`` or a list of names.
        threads: worker threads (default: all cores).
        frames: the frames of the pattern to take, as ``--frames``: ``"1-100"``,
            ``"1-100:2"`` (every second), ``"1,5,7-20"``, or a list of numbers. Every
            selected frame needs a file.
        shard: ``(i, n)`` or ``"i/n"``, as ``--shard``: every n-th frame of the selection
            from the i-th (0-based), round-robin.
        start, end: an inclusive range of frames (instead of ``frames``).
        keep_going: a frame that fails is reported (status ``"failed"``, ``error``) and the
            others are done; the call then returns normally. Default: the first failure
            raises (a ``.mseq`` output keeps the frames done before it).
        progress: called with each finished frame's ``--json-progress`` object: ``frame``,
            ``input``, ``output``, ``status`` (done/skipped/failed), ``triangles``,
            ``seconds``, ``peak_rss_bytes`` and, when failed, ``error``. An exception it
            raises stops the run and is raised.
        skip_existing: skip frames whose output exists (or that the ``.mseq`` holds).
        normals: write vertex normals.
        error_bound: ``.mseq`` position bound, world units; default 0.01 r (r as written,
            the CLI's).
        attribute_error_bound: ``.mseq`` attribute bound, in the attribute's units.
        fps: playback rate of a sequence written into one glTF; a USD stage's time codes
            per second.
        up_axis: a USD stage's up axis, ``"Y"`` (the simulators') or ``"Z"``.
        meters_per_unit: a USD stage's ``metersPerUnit``.
        usd_droplets: the isolated particles of a USD stage: ``"points"`` (a
            ``UsdGeomPoints`` prim with widths 2 r_i and velocities, which renderers
            draw as spheres and Blender blurs) or ``"instancer"`` (a point instancer of
            the sphere mesh).
        input_format: ``"xyz"``, ``"vtk"``, ``"ply"`` or ``"bgeo"``, instead of the extension.
        preset: as for ``reconstruct``; default ``"steady"`` for a sequence (a ``{}``
            pattern or a ``.pvd``, whatever frames are chosen), ``"still"`` for one file.
        **options: the reconstruction settings (``ReconstructOptions``).

    Returns:
        One report per frame, as the CLI's ``--stats`` JSON.
    """

def merge_archives(inputs: Sequence[_Path], output: _Path) -> dict[str, int]:
    """Joins ``.mseq`` archives (one per worker or task) into ``output`` without
    re-encoding, as ``meniscus archive merge``: frames in increasing order, records copied
    byte for byte, so the result equals the archive one writer makes of the same frames.
    A frame in two inputs, different error bounds or a damaged input is refused
    (``FormatError``) and ``output`` is not created. Returns ``inputs``, ``frames``,
    ``bytes``."""

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
    def append(self, frame: int, mesh: Mesh, *, error_bound: float | None = None, subdivide: int = 0) -> int:
        """Appends ``mesh`` as ``frame``; returns the bytes written. A frame number already
        held raises FileExistsError.

        ``subdivide``: Loop steps the reader runs on ``mesh``, which is then stored as a
        control mesh (a quarter of the triangles per step). The CLI archives frames so:
        ``archive.append(n, reconstruct(p, r, defer_subdivision=True), subdivide=1)`` writes the
        frame ``meniscus reconstruct ... -o run.mseq`` writes, byte for byte. A mesh
        reconstructed with subdivision is refused with ``subdivide`` > 0; by default it
        is stored as it is (all its triangles)."""
    def verify(self) -> dict[str, Any]:
        """Decodes and checks every frame: ``clean``, ``good``, ``damaged``, ``damage``,
        ``trailing_bytes``, ``recovered_by_scan``."""
