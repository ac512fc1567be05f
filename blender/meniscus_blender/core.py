"""The extension's work that does not touch Blender: finding a sequence's frames, the
presets, the bake job (a thread running ``meniscus.reconstruct_file``) and the archive
player (a frame decoded on demand). Blender's side is in ``ui.py`` and ``scene.py``."""

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


class Sequence:
    """A particle sequence as the user picked it: ``source`` (what reconstruct_file takes:
    a ``{}`` pattern or a ``.pvd``), ``frames`` (numbers, sorted) and ``first`` (the
    file of the first frame)."""

    def __init__(self, source, frames, first):
        self.source, self.frames, self.first = source, frames, first

    def __repr__(self):
        return f"Sequence({self.source!r}, {len(self.frames)} frames)"


def _pattern_frames(pattern):
    """Frame numbers of the files a ``{}`` pattern matches, and the first file."""
    directory, name = os.path.split(pattern)
    head, _, tail = name.partition("{}")
    regex = re.compile(re.escape(head) + r"(-?\d+)" + re.escape(tail) + "$")
    found = {}
    for entry in os.listdir(directory or "."):
        m = regex.match(entry)
        if m:
            found.setdefault(int(m.group(1)), os.path.join(directory, entry))
    numbers = sorted(found)
    return numbers, (found[numbers[0]] if numbers else None)


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
        numbers, first = _pattern_frames(path)
        if not numbers:
            raise ValueError(f"{path}: no file matches the pattern")
        return Sequence(path, numbers, first)
    if not os.path.isfile(path):
        raise ValueError(f"{path}: no such file")
    if path.lower().endswith(".pvd"):
        root = ElementTree.parse(path).getroot()
        files = [d.get("file") for d in root.iter("DataSet")]
        if not files:
            raise ValueError(f"{path}: the collection lists no dataset")
        first = os.path.join(os.path.dirname(path), files[0])
        return Sequence(path, list(range(len(files))), first)
    m = re.match(r"^(.*?)(\d+)(\.[^.]+)$", os.path.basename(path))
    if m:
        # One numbered file stands for its sequence when it has siblings.
        pattern = os.path.join(os.path.dirname(path), m.group(1) + "{}" + m.group(3))
        numbers, first = _pattern_frames(pattern)
        if len(numbers) > 1:
            return Sequence(pattern, numbers, first)
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
            self.error = str(e)
            # A refused radius: the library's message, its way to force it (the keyword
            # radius_check=False) worded as the panel's check box.
            self.refused_radius = self.radius_check and self.radius is not None and isinstance(e, ValueError) \
                and FORCE_KEYWORD in self.error
            if self.refused_radius:
                self.error = self.error.replace(FORCE_KEYWORD, FORCE_BOX)
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


class ArchivePlayer:
    """A ``.mseq`` archive opened once; ``frame(n)`` decodes the frame shown at scene
    frame ``n`` (the last held frame at or before ``n``; the first before it)."""

    def __init__(self, path):
        import meniscus

        self.path = path
        self.archive = meniscus.Archive(path)
        self.frames = sorted(self.archive.frames)
        if not self.frames:
            raise ValueError(f"{path}: the archive holds no frame")

    def held(self, n):
        """The archive frame shown at scene frame ``n``."""
        best = self.frames[0]
        for f in self.frames:
            if f <= n:
                best = f
            else:
                break
        return best

    def decode(self, frame):
        """``(fluid, droplets)`` of archive frame ``frame``: fluid = (vertices, triangles,
        attributes, (edges, corner_edges)), droplets = (centres, radii, attributes)."""
        mesh = self.archive[frame]
        vertices, triangles, _normals, attributes = mesh.fluid()
        edges = mesh.fluid_edges()
        radii = mesh.sphere_scales * mesh.sphere_radius
        return (vertices, triangles, attributes, edges), (mesh.sphere_centers, radii, mesh.sphere_attributes)
