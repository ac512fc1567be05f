"""Blender's side of playback and live meshing: an object ``Fluid`` (a mesh) and its
child ``Droplets`` (a mesh of loose vertices that a Geometry Nodes modifier turns into a
point cloud with each droplet's radius), whose geometry is swapped whenever the scene's
frame changes: for the archive's frame (playback) or for the current frame's particle
file meshed by the library (live); a frame between two archived or exported frames
holds the one before (``core.held_frame``). Both carry a ``velocity`` point attribute
in the object's space, which Cycles uses for motion blur. The simulation's +Y is turned
to Blender's +Z by the objects' rotation."""

import ctypes
import math
import os
import threading
import time

import bpy
import numpy as np
from bpy.app.handlers import persistent

from . import core
from .core import ArchivePlayer

ARCHIVE_KEY = "meniscus_archive"
# On a live fluid: the particle sequence as picked; beside it its radius (0: the
# estimate) and whether the radius is forced.
LIVE_KEY = "meniscus_live"
LIVE_RADIUS = "meniscus_live_radius"
LIVE_FORCE = "meniscus_live_force"
DROPLETS_GROUP = "meniscus droplets"

# Open archives, by path (a handler runs on every frame change).
_players = {}
# Time of the last swap, seconds (read by the benchmark and shown in the panel).
last_swap = {"seconds": 0.0, "frame": None}


def player(path):
    p = _players.get(path)
    if p is None:
        p = _players[path] = ArchivePlayer(path)
    return p


def forget(path=None):
    if path is None:
        _players.clear()
    else:
        _players.pop(path, None)


def _set_attributes(mesh, attributes, count):
    """Point attributes of 1 (FLOAT), 2 (FLOAT2), 3 (FLOAT_VECTOR) or 4 (FLOAT_COLOR)
    components; `velocity`/`vel`/`v` becomes Blender's `velocity`."""
    for name, values in attributes.items():
        values = np.ascontiguousarray(values, dtype=np.float32)
        if len(values) != count:
            continue
        k = 1 if values.ndim == 1 else values.shape[1]
        if k == 3 and name.lower() in ("velocity", "vel", "v"):
            name = "velocity"
        kind, field = {1: ("FLOAT", "value"), 2: ("FLOAT2", "vector"), 3: ("FLOAT_VECTOR", "vector"),
                       4: ("FLOAT_COLOR", "color")}.get(k, (None, None))
        if kind is None or name in mesh.attributes:
            continue
        mesh.attributes.new(name, kind, "POINT").data.foreach_set(field, values.ravel())


def _fill(mesh, name, field, values, fallback):
    """Writes ``values`` into the mesh's attribute ``name`` (a plain copy), or through the
    slower RNA path ``fallback`` (collection, property) where a Blender has no such
    attribute."""
    attribute = mesh.attributes.get(name)
    if attribute is not None:
        attribute.data.foreach_set(field, values)
    else:
        fallback[0].foreach_set(fallback[1], values)


def _int32(values):
    """``values`` as a flat int32 array: a view of the library's uint32 (its indices are
    below 2^31) or int32 arrays, a copy of anything else."""
    values = np.ascontiguousarray(values)
    if values.dtype in (np.uint32, np.int32):
        return values.view(np.int32).ravel()
    return values.astype(np.int32).ravel()


# Face offsets 0, 3, 6, ... of the largest triangle mesh swapped in so far (grown on
# demand): every triangle mesh's loop_start is a prefix of it.
_triangle_offsets = np.zeros(0, dtype=np.int32)


def _offsets_of(count):
    global _triangle_offsets
    if len(_triangle_offsets) < count:
        _triangle_offsets = np.arange(0, 3 * max(count, 2 * len(_triangle_offsets)), 3, dtype=np.int32)
    return _triangle_offsets[:count]


def _set_triangle_offsets(mesh, count):
    """Sets the face offsets (``loop_start``) of ``mesh``'s ``count`` triangles, just
    added: 0, 3, 6, ... RNA's ``polygons.foreach_set("loop_start")`` sets them one face
    at a time (30 ms for 1 M faces in bpy 5.0.1; they are no attribute that ``foreach_set``
    copies in one go, no bpy call removes faces so that a kept mesh keeps its offsets, and
    ``clear_geometry`` frees them). A face's RNA pointer (``MeshPolygon.as_pointer()``) is
    the address of its offset in the mesh's offsets array (``loop_start`` reads and writes
    through it), so the offsets are copied there in one go (1 ms) when that layout is
    seen: consecutive faces 4 bytes apart and the end offset, which ``polygons.add`` sets,
    equal to the corner count; and read back through RNA. Otherwise, RNA's setter."""
    offsets = _offsets_of(count)
    if count == 0:
        return
    polygons = mesh.polygons
    try:
        first, last = polygons[0].as_pointer(), polygons[count - 1].as_pointer()
        if first and last - first == 4 * (count - 1):
            block = np.ctypeslib.as_array((ctypes.c_int32 * (count + 1)).from_address(first))
            if block[count] == len(mesh.loops) == 3 * count:
                block[:count] = offsets
                if all(polygons[i].loop_start == 3 * i for i in (0, count // 2, count - 1)):
                    return
    except (TypeError, ValueError, AttributeError):
        pass
    polygons.foreach_set("loop_start", offsets)


def set_fluid(mesh, vertices, triangles, attributes, edges=None):
    """Replaces ``mesh``'s geometry with a triangle mesh (smooth shaded). ``edges`` =
    (edges (E, 2), corner_edges (3T,)) as ``meniscus.Mesh.fluid_edges`` gives them;
    without them Blender computes the edges (0.8 s for 1 M triangles)."""
    mesh.clear_geometry()
    nv, nt = len(vertices), len(triangles)
    mesh.vertices.add(nv)
    _fill(mesh, "position", "vector", np.ascontiguousarray(vertices, dtype=np.float32).ravel(),
          (mesh.vertices, "co"))
    if edges is not None:
        mesh.edges.add(len(edges[0]))
        _fill(mesh, ".edge_verts", "value", _int32(edges[0]), (mesh.edges, "vertices"))
    mesh.loops.add(3 * nt)
    _fill(mesh, ".corner_vert", "value", _int32(triangles), (mesh.loops, "vertex_index"))
    if edges is not None:
        _fill(mesh, ".corner_edge", "value", _int32(edges[1]), (mesh.loops, "edge_index"))
    mesh.polygons.add(nt)
    _set_triangle_offsets(mesh, nt)
    _set_attributes(mesh, attributes, nv)
    mesh.update()


def set_droplets(mesh, centres, radii, attributes):
    """Replaces ``mesh``'s geometry with loose vertices at the droplets' centres, with a
    ``radius`` attribute (the Geometry Nodes modifier makes the point cloud)."""
    mesh.clear_geometry()
    n = len(centres)
    mesh.vertices.add(n)
    if n:
        mesh.vertices.foreach_set("co", np.ascontiguousarray(centres, dtype=np.float32).ravel())
    mesh.attributes.new("radius", "FLOAT", "POINT").data.foreach_set(
        "value", np.ascontiguousarray(radii, dtype=np.float32))
    _set_attributes(mesh, attributes, n)
    mesh.update()


def droplets_group():
    """The node group turning the droplets' vertices into points of their radius."""
    group = bpy.data.node_groups.get(DROPLETS_GROUP)
    if group is not None:
        return group
    group = bpy.data.node_groups.new(DROPLETS_GROUP, "GeometryNodeTree")
    group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = group.nodes, group.links
    source, sink = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    to_points = nodes.new("GeometryNodeMeshToPoints")
    radius = nodes.new("GeometryNodeInputNamedAttribute")
    radius.data_type = "FLOAT"
    radius.inputs["Name"].default_value = "radius"
    links.new(source.outputs[0], to_points.inputs["Mesh"])
    links.new(radius.outputs["Attribute"], to_points.inputs["Radius"])
    links.new(to_points.outputs["Points"], sink.inputs[0])
    return group


def droplets_of(fluid):
    """The droplets child of a playback or live fluid, or None."""
    return next((c for c in fluid.children if c.get(ARCHIVE_KEY) == "droplets"), None)


def swap(fluid, parts):
    """Swaps ``parts`` (``core.mesh_parts``: the fluid's arrays and the droplets') into
    ``fluid`` and its droplets child."""
    (vertices, triangles, attributes, edges), (centres, radii, drops) = parts
    set_fluid(fluid.data, vertices, triangles, attributes, edges)
    droplets = droplets_of(fluid)
    if droplets is not None:
        set_droplets(droplets.data, centres, radii, drops)


def show_frame(scene, fluid, frame=None):
    """Swaps the archive's frame for scene frame ``frame`` (default: the current one)
    into ``fluid`` and its droplets. Returns the archive frame shown."""
    path = bpy.path.abspath(fluid[ARCHIVE_KEY])
    p = player(path)
    n = p.held(scene.frame_current if frame is None else frame)
    if fluid.get("meniscus_frame") == n and fluid.data.vertices:
        return n
    start = time.perf_counter()
    swap(fluid, p.decode(n))
    fluid["meniscus_frame"] = n
    last_swap["seconds"], last_swap["frame"] = time.perf_counter() - start, n
    return n


def _new_objects(context, name, up_axis):
    """A fluid object ``name`` and its droplets child (the point-cloud modifier on it),
    linked into the context's collection; the droplets marked as such."""
    fluid = bpy.data.objects.new(name, bpy.data.meshes.new(name))
    drops = bpy.data.objects.new(f"{name} droplets", bpy.data.meshes.new(f"{name} droplets"))
    drops[ARCHIVE_KEY] = "droplets"
    modifier = drops.modifiers.new("Points", "NODES")
    modifier.node_group = droplets_group()
    context.collection.objects.link(fluid)
    context.collection.objects.link(drops)
    drops.parent = fluid
    if up_axis == "Y":
        fluid.rotation_euler = (math.pi / 2, 0.0, 0.0)
    # Geometry is swapped on frame change: renders must not read it meanwhile.
    context.scene.render.use_lock_interface = True
    return fluid


def load_archive(context, path, up_axis="Y"):
    """Creates the playback objects of the archive at ``path`` in the scene, sets the
    scene's frame range to the archive's and shows the current frame. Returns ``Fluid``."""
    scene = context.scene
    absolute = bpy.path.abspath(path)
    forget(absolute)
    p = player(absolute)
    name = bpy.path.display_name_from_filepath(absolute) or "Fluid"
    fluid = _new_objects(context, name, up_axis)
    fluid[ARCHIVE_KEY] = path
    scene.frame_start, scene.frame_end = p.frames[0], p.frames[-1]
    show_frame(scene, fluid)
    return fluid


def playback_objects(scene):
    return [o for o in scene.objects if o.get(ARCHIVE_KEY) and o[ARCHIVE_KEY] != "droplets"]


# Live meshing. The meshers (a sequence, its radius, the cache of recent frames), by
# (source, radius, forced); whether a render is under way (set by the render_init
# handler, cleared by render_complete/render_cancel: a frame change in between is the
# render's, and takes the render preset); and the last live frame's report (the panel
# shows it).
_meshers = {}
_render = {"running": False}
# "frame" is the scene frame; "held" the sequence frame whose file is shown there when
# the scene frame has no file of its own (None when it has, or for one unnumbered
# file); "kept" that the fluid already showed that file with that preset (no swap).
_NO_REPORT = {"frame": None, "held": None, "preset": None, "error": None, "cached": False, "kept": False,
              "seconds": 0.0, "mesh_seconds": 0.0, "triangles": 0, "droplets": 0}
live_report = dict(_NO_REPORT)
_report_lock = threading.Lock()


def live_objects(scene):
    return [o for o in scene.objects if o.get(LIVE_KEY)]


def mesher(scene, fluid):
    """The live mesher of ``fluid`` (made on first use: the sequence resolved, the
    radius estimated when not given), its cache bounded by the scene's setting."""
    key = (bpy.path.abspath(fluid[LIVE_KEY]), float(fluid.get(LIVE_RADIUS, 0.0)), bool(fluid.get(LIVE_FORCE, False)))
    m = _meshers.get(key)
    if m is None:
        sequence = core.resolve_sequence(key[0])
        m = _meshers[key] = core.LiveMesher(sequence, key[1], radius_check=not key[2])
    m.cache_bytes = int(scene.meniscus.live_cache_mib) << 20
    return m


def rendering():
    """Whether a render is under way (between render_init and render_complete/cancel)."""
    return _render["running"]


def live_preset(scene, render=None):
    """The preset live meshing uses now: the render preset under a render, else the
    viewport preset."""
    settings = scene.meniscus
    return settings.live_render_preset if (rendering() if render is None else render) else settings.live_viewport_preset


def _clear(fluid):
    fluid.data.clear_geometry()
    fluid.data.update()
    droplets = droplets_of(fluid)
    if droplets is not None:
        droplets.data.clear_geometry()
        droplets.data.update()


def show_live(scene, fluid, frame=None, render=None):
    """Meshes the particle file shown at scene frame ``frame`` (default: the current
    one) of the live fluid's sequence with the preset of the moment (``live_preset``),
    or takes it from the cache, and swaps it into ``fluid`` and its droplets. The file
    shown is the frame's own, or for a frame without one the last one before it (the
    first before the sequence), as playback holds an archive's frames
    (``core.held_frame``); the fluid is not swapped again while it shows that file with
    that preset. A file that fails to read or mesh clears them; the error goes to
    ``live_report`` (the panel) and the console, and is not raised. Returns the error
    or None."""
    n = scene.frame_current if frame is None else frame
    preset = live_preset(scene, render)
    start = time.perf_counter()
    report = dict(_NO_REPORT, frame=n, preset=preset)
    held = n
    try:
        m = mesher(scene, fluid)
        held = m.held(n)
        if m.sequence.files is not None and held != n:
            report["held"] = held
        shown = f"{held} {preset}"
        if fluid.get("meniscus_live_shown") == shown:
            # Already in the scene (a frame of the same gap, or the same frame again).
            droplets = droplets_of(fluid)
            report.update(cached=True, kept=True, triangles=len(fluid.data.polygons),
                          droplets=len(droplets.data.vertices) if droplets is not None else 0)
        else:
            hits = m.stats["hits"]
            parts = m.frame(n, preset)
            report["cached"] = m.stats["hits"] > hits
            report["mesh_seconds"] = 0.0 if report["cached"] else m.stats["seconds"][preset]
            swap(fluid, parts)
            report["triangles"], report["droplets"] = len(parts[0][1]), len(parts[1][0])
            fluid["meniscus_live_shown"] = shown
    except Exception as e:  # reported, never raised out of a handler
        where = f"frame {n}" if report["held"] is None else f"frame {n} (no file; frame {held} held)"
        report["error"] = f"{where}: {e}"
        print(f"meniscus: {fluid.name}: {report['error']}")
        try:
            _clear(fluid)
            if "meniscus_live_shown" in fluid:
                del fluid["meniscus_live_shown"]
        except Exception as e2:
            print(f"meniscus: {fluid.name}: clearing: {e2}")
    report["seconds"] = time.perf_counter() - start
    with _report_lock:
        live_report.update(report)
    return report["error"]


def start_live(context, source, radius=0.0, force=False, up_axis="Y"):
    """Live mode on the particle sequence ``source``: one fluid object (and its
    droplets) meshed from the current frame's particle file on every frame change (a
    frame without one holds the last file before it, see ``show_live``). The
    live objects before it are removed; the scene's range becomes the sequence's. The
    first frame meshed checks a given radius: a refused one raises ValueError (the
    library's message) and leaves the scene as it was. Returns the fluid."""
    scene = context.scene
    absolute = bpy.path.abspath(source)
    sequence = core.resolve_sequence(absolute)  # picked anew: the files are looked for again
    m = core.LiveMesher(sequence, radius, radius_check=not force,
                        cache_bytes=int(scene.meniscus.live_cache_mib) << 20)
    n = scene.frame_current
    m.frame(n, live_preset(scene, False))  # the radius checked before anything changes
    stop_live(scene)
    _meshers[(absolute, float(radius), bool(force))] = m
    name = os.path.splitext(os.path.basename(sequence.source))[0].replace("{}", "").strip(" _-.") or "Fluid"
    fluid = _new_objects(context, f"{name} live", up_axis)
    fluid[LIVE_KEY] = source
    fluid[LIVE_RADIUS] = float(radius)
    fluid[LIVE_FORCE] = bool(force)
    if sequence.files is not None:
        scene.frame_start, scene.frame_end = sequence.frames[0], sequence.frames[-1]
    show_live(scene, fluid)  # the current frame stays, as when an archive is loaded
    if live_report["frame"] == n and not live_report["error"]:
        # Meshed above (the radius check), shown here from the cache: report the meshing.
        live_report.update(cached=False, mesh_seconds=m.stats["seconds"][live_report["preset"]])
    return fluid


def stop_live(scene):
    """Leaves live mode: the live objects (and their meshes) are removed and the cached
    frames dropped; frame changes mesh nothing any more."""
    for fluid in live_objects(scene):
        for o in [fluid, *fluid.children]:
            mesh = o.data
            bpy.data.objects.remove(o)
            if mesh is not None and mesh.users == 0:
                bpy.data.meshes.remove(mesh)
    _meshers.clear()
    with _report_lock:
        live_report.update(_NO_REPORT)


@persistent
def on_frame_change(scene, depsgraph=None):
    for fluid in playback_objects(scene):
        try:
            show_frame(scene, fluid)
        except Exception as e:  # a missing archive must not break playback of the rest
            print(f"meniscus: {fluid.name}: {e}")
    for fluid in live_objects(scene):
        show_live(scene, fluid)


@persistent
def on_render_init(scene, _=None):
    _render["running"] = True


@persistent
def on_render_end(scene, _=None):
    # Blender changes to the current frame again after a render (frame_change_pre):
    # the live fluid then goes back to the viewport preset (cached).
    _render["running"] = False


@persistent
def on_load(_):
    forget()
    _meshers.clear()
    _render["running"] = False


HANDLERS = (("frame_change_pre", on_frame_change), ("load_post", on_load), ("render_init", on_render_init),
            ("render_complete", on_render_end), ("render_cancel", on_render_end))


def register():
    for name, fn in HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        if fn not in handlers:
            handlers.append(fn)


def unregister():
    for name, fn in HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        if fn in handlers:
            handlers.remove(fn)
    forget()
    _meshers.clear()
