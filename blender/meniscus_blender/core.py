"""The extension's work that does not touch Blender: finding a sequence's frames, the
presets, the bake job (a thread running ``meniscus.reconstruct_file``), the archive
player (a frame decoded on demand) and the live mesher (a frame's particle file meshed
by ``meniscus.reconstruct``, recent frames kept). Blender's side is in ``ui.py`` and
``scene.py``."""

import bisect
import collections
import os
import re
import threading
import time
import xml.etree.ElementTree as ElementTree

# The reconstruction settings of each preset (keywords of meniscus.reconstruct_file):
# the library's presets by name ("steady", its default for a sequence: shading that does
# not flicker from frame to frame; "still", the best still frame; "paper", Akinci et al.
# 2013), and "preview", which trades detail for time (the still preset with a cell twice
# as large, no subdivision, no decimation, one smoothing step).
PRESETS = {
    "STEADY": {"preset": "steady"},
    "STILL": {"preset": "still"},
    "PREVIEW": {"preset": "still", "cell_size": 2.0, "subdivide": 0, "decimate": None, "smooth": 1},
    "PAPER": {"preset": "paper"},
}

PARTICLE_EXTENSIONS = (".xyz", ".vtk", ".vtu", ".vtp", ".ply", ".bgeo")


def preset_options(name):
    """The keywords of preset ``name`` (a copy)."""
    return dict(PRESETS[name])


def held_frame(frames, n):
    """The frame of ``frames`` (numbers, sorted, not empty) shown at scene frame ``n``:
    the last one at or before ``n``, the first one before it. Playback of an archive and
    live meshing both show a scene frame this way: a frame between two exported (or
    archived) frames holds the one before, the frames after the last hold the last."""
    i = bisect.bisect_right(frames, n)
    return frames[i - 1] if i else frames[0]


class Sequence:
    """A particle sequence as the user picked it: ``source`` (what reconstruct_file takes:
    a ``{}`` pattern or a ``.pvd``), ``frames`` (numbers, sorted), ``first`` (the
    file of the first frame) and ``files`` (frame number -> file; None for one
    unnumbered file, which stands for every frame)."""

    def __init__(self, source, frames, first, files=None):
        self.source, self.frames, self.first, self.files = source, frames, first, files

    def held(self, n):
        """The sequence frame whose file is shown at scene frame ``n`` (``held_frame``:
        the last one at or before ``n``, the first before it); the only frame of one
        unnumbered file."""
        return held_frame(self.frames, n)

    def file(self, n):
        """The particle file of sequence frame ``n``; ValueError when the sequence has
        none (``held`` gives the frame to ask for)."""
        if self.files is None:
            return self.first
        path = self.files.get(n)
        if path is None:
            raise ValueError(f"no particle file (the sequence has {len(self.frames)} frame(s), "
                             f"{self.frames[0]}–{self.frames[-1]})")
        return path

    def rescan(self):
        """Looks for the sequence's files again (the ``{}`` pattern's folder listed, the
        ``.pvd`` read), so that files written since are found. Returns whether the files
        changed; a listing that fails or finds nothing keeps the files known."""
        if self.files is None:
            return False
        try:
            fresh = resolve_sequence(self.source)
        except (OSError, ValueError, ElementTree.ParseError):
            return False
        if fresh.files is None or fresh.files == self.files:
            return False
        self.frames, self.first, self.files = fresh.frames, fresh.first, fresh.files
        return True

    def __repr__(self):
        return f"Sequence({self.source!r}, {len(self.frames)} frames)"


def _pattern_files(pattern):
    """The files a ``{}`` pattern matches, by frame number."""
    directory, name = os.path.split(pattern)
    head, _, tail = name.partition("{}")
    regex = re.compile(re.escape(head) + r"(-?\d+)" + re.escape(tail) + "$")
    found = {}
    for entry in os.listdir(directory or "."):
        m = regex.match(entry)
        if m:
            found.setdefault(int(m.group(1)), os.path.join(directory, entry))
    return found


def _folder_pattern(folder):
    """The ``{}`` pattern of the largest family of numbered particle files in ``folder``
    (``ParticleData_Fluid_7.vtk`` → ``ParticleData_Fluid_{}.vtk``)."""
    families = {}
    for entry in sorted(os.listdir(folder)):
        if not entry.lower().endswith(PARTICLE_EXTENSIONS):
            continue
        m = re.match(r"^(.*?)(\d+)(\.[^.]+)$", entry)
        if m:
            families.setdefault(m.group(1) + "{}" + m.group(3), []).append(entry)
    if not families:
        raise ValueError(f"{folder}: no numbered particle files ({', '.join(PARTICLE_EXTENSIONS)})")
    name = max(families, key=lambda k: (len(families[k]), k))
    return os.path.join(folder, name)


def resolve_sequence(path):
    """The sequence of ``path``: a ``{}`` pattern, a folder of numbered frames, a ParaView
    ``.pvd`` collection, or one particle file (a sequence of one frame). Raises
    ValueError saying what is wrong."""
    path = os.path.expanduser(path.strip())
    if not path:
        raise ValueError("no particle sequence chosen")
    if os.path.isdir(path):
        path = _folder_pattern(path)
    if "{}" in path:
        files = _pattern_files(path)
        if not files:
            raise ValueError(f"{path}: no file matches the pattern")
        numbers = sorted(files)
        return Sequence(path, numbers, files[numbers[0]], files)
    if not os.path.isfile(path):
        raise ValueError(f"{path}: no such file")
    if path.lower().endswith(".pvd"):
        root = ElementTree.parse(path).getroot()
        files = [d.get("file") for d in root.iter("DataSet")]
        if not files:
            raise ValueError(f"{path}: the collection lists no dataset")
        files = {k: os.path.join(os.path.dirname(path), f) for k, f in enumerate(files)}
        return Sequence(path, sorted(files), files[0], files)
    m = re.match(r"^(.*?)(\d+)(\.[^.]+)$", os.path.basename(path))
    if m:
        # One numbered file stands for its sequence when it has siblings.
        pattern = os.path.join(os.path.dirname(path), m.group(1) + "{}" + m.group(3))
        files = _pattern_files(pattern)
        if len(files) > 1:
            numbers = sorted(files)
            return Sequence(pattern, numbers, files[numbers[0]], files)
    return Sequence(path, [0], path)


def estimate_radius(sequence):
    """The particle radius the first frame's spacing implies (meniscus.estimate_radius)."""
    import meniscus

    positions, _ = meniscus.read_particles(sequence.first)
    return float(meniscus.estimate_radius(positions))


# How the library's refusal of a radius says to force it from Python, and the panel's
# check box that does the same.
FORCE_KEYWORD = "radius_check=False"
FORCE_BOX = "tick Force radius"
# How the library's messages name particles given as arrays.
IN_MEMORY = "particles in memory"


def library_error(e, radius_given, radius_check):
    """``(message, refused_radius)`` of the library's exception ``e``: its message as it
    is, except that a refused radius's way to force it (the keyword radius_check=False)
    is worded as the panel's check box."""
    message = str(e)
    refused = bool(radius_check and radius_given and isinstance(e, ValueError) and FORCE_KEYWORD in message)
    if refused:
        message = message.replace(FORCE_KEYWORD, FORCE_BOX)
    return message, refused


class BakeCancelled(Exception):
    """Raised in the progress callback to stop a bake the user cancelled."""


class BakeJob:
    """A bake on a thread of its own: ``meniscus.reconstruct_file(sequence, output, ...)``
    with a progress callback that counts finished frames and stops the run when
    ``cancel()`` was called (between frames: a frame under way is finished first, and a
    ``.mseq`` keeps the frames done). ``meniscus`` releases the GIL while it works, so
    Blender's main thread (the UI) runs on. Read ``done``, ``total``, ``error``,
    ``finished``, ``cancelled`` from the main thread."""

    def __init__(self, sequence, output, radius=None, preset="STEADY", radius_check=True, usd=False):
        self.sequence, self.output = sequence, output
        self.radius = radius if radius and radius > 0 else None
        self.options = preset_options(preset)
        self.radius_check = radius_check
        self.usd = usd
        self.total = len(sequence.frames)
        self.done = 0
        self.last = None
        self.error = None
        self.refused_radius = False
        self.reports = None
        self.finished = False
        self.cancelled = False
        self.started = None
        self._cancel = threading.Event()
        self._thread = None

    def _progress(self, report):
        self.done += 1
        self.last = report
        if self._cancel.is_set():
            raise BakeCancelled("cancelled")

    def run(self):
        """Bakes on the calling thread (the background and test route)."""
        import meniscus

        self.started = time.monotonic()
        directory = os.path.dirname(os.path.abspath(self.output))
        os.makedirs(directory, exist_ok=True)
        try:
            if os.path.exists(self.output):
                os.remove(self.output)  # a bake writes its cache anew
            self.reports = meniscus.reconstruct_file(
                self.sequence.source,
                self.output,
                self.radius,
                radius_check=self.radius_check,
                progress=self._progress,
                **self.options,
            )
        except BakeCancelled:
            self.cancelled = True
        except Exception as e:  # shown to the user as it is: the library's message
            self.error, self.refused_radius = library_error(e, self.radius is not None, self.radius_check)
        finally:
            self.finished = True

    def start(self):
        """Bakes on a new thread."""
        self._thread = threading.Thread(target=self.run, name="meniscus bake", daemon=True)
        self._thread.start()

    def cancel(self):
        self._cancel.set()

    def join(self, timeout=None):
        if self._thread is not None:
            self._thread.join(timeout)

    @property
    def fraction(self):
        return self.done / self.total if self.total else 0.0


# glibc's M_MMAP_THRESHOLD (mallopt), and the threshold playback sets: glibc's own
# largest dynamic one, which the meniscus command sets too.
_M_MMAP_THRESHOLD = -3
PLAYBACK_MMAP_THRESHOLD = 32 << 20


def keep_frame_buffers():
    """Lets the process's heap hand out blocks up to 32 MiB (``M_MMAP_THRESHOLD``),
    where the meniscus package sets 4 MiB at import: a played-back frame's arrays (a
    1 M-triangle frame's decoded mesh and edges, and the arrays Blender allocates for
    the mesh swapped in, 6–12 MiB each) then reuse the heap the previous frame freed
    instead of being mapped anew, whose fresh pages the kernel faults in and zeroes on
    first touch (a third of the CPU time of a frame's decode and swap, measured). Only
    with glibc (elsewhere, or with ``MENISCUS_TUNE_MALLOC=0``, the package's opt-out of
    allocator settings, nothing is changed). Returns whether it was set."""
    import ctypes
    import platform
    import sys

    import meniscus  # noqa: F401  (its settings at import come first)

    if os.environ.get("MENISCUS_TUNE_MALLOC") == "0" or not sys.platform.startswith("linux"):
        return False
    if platform.libc_ver()[0] != "glibc":
        return False
    try:
        return bool(ctypes.CDLL(None).mallopt(_M_MMAP_THRESHOLD, PLAYBACK_MMAP_THRESHOLD))
    except (OSError, AttributeError):
        return False


class ArchivePlayer:
    """A ``.mseq`` archive opened once; ``frame(n)`` decodes the frame shown at scene
    frame ``n`` (the last held frame at or before ``n``; the first before it)."""

    def __init__(self, path):
        import meniscus

        self.path = path
        keep_frame_buffers()
        self.archive = meniscus.Archive(path)
        self.frames = sorted(self.archive.frames)
        if not self.frames:
            raise ValueError(f"{path}: the archive holds no frame")

    def held(self, n):
        """The archive frame shown at scene frame ``n`` (``held_frame``)."""
        return held_frame(self.frames, n)

    def decode(self, frame):
        """``(fluid, droplets)`` of archive frame ``frame`` (see ``mesh_parts``)."""
        return mesh_parts(self.archive[frame])


def mesh_parts(mesh):
    """``(fluid, droplets)`` of a ``meniscus.Mesh`` as the scene swaps them in: fluid =
    (vertices, triangles, attributes, (edges, corner_edges)), droplets = (centres, radii,
    attributes)."""
    vertices, triangles, _normals, attributes = mesh.fluid()
    edges = mesh.fluid_edges()
    radii = mesh.sphere_scales * mesh.sphere_radius
    return (vertices, triangles, attributes, edges), (mesh.sphere_centers, radii, mesh.sphere_attributes)


def _nbytes(value):
    """Bytes of the arrays in a nest of tuples and dicts."""
    if isinstance(value, (tuple, list)):
        return sum(_nbytes(v) for v in value)
    if isinstance(value, dict):
        return sum(_nbytes(v) for v in value.values())
    return int(getattr(value, "nbytes", 0))


def live_attributes(attributes):
    """The particle attributes a live frame passes to ``meniscus.reconstruct``, those a
    bake takes by default: the velocity (the first attribute named as one of the
    library's ``VELOCITY_NAMES``, in any case), and Houdini's per-particle radius ``pscale`` when
    present (the library meshes each particle with its own radius, as in a bake)."""
    import meniscus

    chosen = {}
    velocity = next((k for k in attributes if k.lower() in meniscus.VELOCITY_NAMES), None)
    if velocity is not None:
        chosen[velocity] = attributes[velocity]
    if "pscale" in attributes:
        chosen["pscale"] = attributes["pscale"]
    return chosen


# Live mode looks for a sequence's files again (``Sequence.rescan``) when a scene frame
# has no known file, at most once in this many seconds.
RESCAN_SECONDS = 1.0


class LiveMesher:
    """Meshes a sequence's frames on demand, for live mode: ``frame(n, preset)`` reads
    the particle file shown at scene frame ``n`` (``held(n)``: its own, or across a gap
    the last one before, as playback holds an archive's frames) with
    ``meniscus.read_particles`` and meshes it
    (``meniscus.reconstruct``) with the preset's keywords at one radius for the whole
    sequence (``radius``, or the first frame's estimate, as a bake takes it; a given
    radius is checked by the library on the first frame meshed, as a bake checks it on
    its first frame), and
    returns its ``mesh_parts``. The results of recent frames are kept per preset, the
    least recently used dropped first beyond ``cache_bytes``; a file changed on disk
    (its size or time) is meshed again. A scene frame with no known file has the
    sequence's files looked for again (``Sequence.rescan``) when the last look is
    ``rescan_seconds`` old, so files written after Live was pressed are found.
    ``stats``: ``meshed`` and ``hits`` (calls
    answered by meshing and from the cache), ``seconds`` (the last meshing's, by
    preset), ``cached_frames``, ``cached_bytes``, ``rescans`` (looks that found the
    files changed). Errors are the library's (a refused
    radius worded as the panel's, see ``library_error``), as ValueError/OSError."""

    def __init__(self, sequence, radius=None, radius_check=True, cache_bytes=512 << 20):
        self.sequence = sequence
        self.given = bool(radius and radius > 0)
        self.radius = float(radius) if self.given else estimate_radius(sequence)
        self.radius_check = radius_check
        self._checked = False
        self.cache_bytes = int(cache_bytes)
        self._cache = collections.OrderedDict()  # key -> (parts, bytes)
        self._lock = threading.Lock()
        self.rescan_seconds = RESCAN_SECONDS
        self._scanned = time.monotonic()
        self.stats = {"meshed": 0, "hits": 0, "seconds": {}, "cached_frames": 0, "cached_bytes": 0,
                      "rescans": 0}

    def _held(self, n):
        files = self.sequence.files
        if files is not None and n not in files and time.monotonic() - self._scanned >= self.rescan_seconds:
            if self.sequence.rescan():
                self.stats["rescans"] += 1
            self._scanned = time.monotonic()
        return self.sequence.held(n)

    def held(self, n):
        """The sequence frame whose file is shown at scene frame ``n`` (``Sequence.held``),
        the files looked for again first when ``n`` has none and the last look is
        ``rescan_seconds`` old."""
        with self._lock:
            return self._held(n)

    def _key(self, n, preset):
        n = self._held(n)
        path = self.sequence.file(n)
        st = os.stat(path)
        return (n, preset, path, st.st_mtime_ns, st.st_size)

    def _mesh(self, path, preset):
        import meniscus

        positions, attributes = meniscus.read_particles(path)
        try:
            check = self.radius_check and self.given and not self._checked
            mesh = meniscus.reconstruct(positions, self.radius, attributes=live_attributes(attributes),
                                        radius_check=check, **preset_options(preset))
            self._checked = True
        except ValueError as e:
            message, refused = library_error(e, self.given, self.radius_check)
            if refused:
                # The library names the arrays it was given; the user knows the file.
                raise ValueError(message.replace(IN_MEMORY, path, 1)) from e
            raise
        return mesh_parts(mesh)

    def frame(self, n, preset):
        """``(fluid, droplets)`` of the file shown at scene frame ``n`` (``held(n)``) with
        preset ``preset`` (a key of PRESETS)."""
        with self._lock:
            key = self._key(n, preset)
            cached = self._cache.get(key)
            if cached is not None:
                self._cache.move_to_end(key)
                self.stats["hits"] += 1
                return cached[0]
            start = time.perf_counter()
            parts = self._mesh(key[2], preset)
            self.stats["seconds"][preset] = time.perf_counter() - start
            self.stats["meshed"] += 1
            size = _nbytes(parts)
            if size <= self.cache_bytes:
                self._cache[key] = (parts, size)
                total = sum(s for _, s in self._cache.values())
                while total > self.cache_bytes:
                    total -= self._cache.popitem(last=False)[1][1]
            self.stats["cached_frames"] = len(self._cache)
            self.stats["cached_bytes"] = sum(s for _, s in self._cache.values())
            return parts

    def clear(self):
        with self._lock:
            self._cache.clear()
            self.stats["cached_frames"] = self.stats["cached_bytes"] = 0
