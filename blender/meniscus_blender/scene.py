"""Blender's side of playback: an object ``Fluid`` (a mesh) and its child ``Droplets`` (a
mesh of loose vertices that a Geometry Nodes modifier turns into a point cloud with each
droplet's radius), whose geometry is swapped for the archive's frame whenever the scene's
frame changes. Both carry a ``velocity`` point attribute in the object's space, which
Cycles uses for motion blur. The simulation's +Y is turned to Blender's +Z by the
objects' rotation."""

import math

import bpy
import numpy as np
from bpy.app.handlers import persistent

from .core import ArchivePlayer

ARCHIVE_KEY = "meniscus_archive"
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
        _fill(mesh, ".edge_verts", "value", np.ascontiguousarray(edges[0], dtype=np.int32).ravel(),
              (mesh.edges, "vertices"))
    mesh.loops.add(3 * nt)
    _fill(mesh, ".corner_vert", "value", np.ascontiguousarray(triangles, dtype=np.int32).ravel(),
          (mesh.loops, "vertex_index"))
    if edges is not None:
        _fill(mesh, ".corner_edge", "value", np.ascontiguousarray(edges[1], dtype=np.int32),
              (mesh.loops, "edge_index"))
    mesh.polygons.add(nt)
    mesh.polygons.foreach_set("loop_start", np.arange(0, 3 * nt, 3, dtype=np.int32))
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


def show_frame(scene, fluid, frame=None):
    """Swaps the archive's frame for scene frame ``frame`` (default: the current one)
    into ``fluid`` and its droplets. Returns the archive frame shown."""
    import time

    path = bpy.path.abspath(fluid[ARCHIVE_KEY])
    p = player(path)
    n = p.held(scene.frame_current if frame is None else frame)
    if fluid.get("meniscus_frame") == n and fluid.data.vertices:
        return n
    start = time.perf_counter()
    (vertices, triangles, attributes, edges), (centres, radii, drops) = p.decode(n)
    set_fluid(fluid.data, vertices, triangles, attributes, edges)
    droplets = next((c for c in fluid.children if c.get(ARCHIVE_KEY) == "droplets"), None)
    if droplets is not None:
        set_droplets(droplets.data, centres, radii, drops)
    fluid["meniscus_frame"] = n
    last_swap["seconds"], last_swap["frame"] = time.perf_counter() - start, n
    return n


def load_archive(context, path, up_axis="Y"):
    """Creates the playback objects of the archive at ``path`` in the scene, sets the
    scene's frame range to the archive's and shows the current frame. Returns ``Fluid``."""
    scene = context.scene
    absolute = bpy.path.abspath(path)
    forget(absolute)
    p = player(absolute)
    name = bpy.path.display_name_from_filepath(absolute) or "Fluid"
    fluid = bpy.data.objects.new(name, bpy.data.meshes.new(name))
    fluid[ARCHIVE_KEY] = path
    drops = bpy.data.objects.new(f"{name} droplets", bpy.data.meshes.new(f"{name} droplets"))
    drops[ARCHIVE_KEY] = "droplets"
    modifier = drops.modifiers.new("Points", "NODES")
    modifier.node_group = droplets_group()
    context.collection.objects.link(fluid)
    context.collection.objects.link(drops)
    drops.parent = fluid
    if up_axis == "Y":
        fluid.rotation_euler = (math.pi / 2, 0.0, 0.0)
    scene.frame_start, scene.frame_end = p.frames[0], p.frames[-1]
    # Geometry is swapped on frame change: renders must not read it meanwhile.
    scene.render.use_lock_interface = True
    show_frame(scene, fluid)
    return fluid


def playback_objects(scene):
    return [o for o in scene.objects if o.get(ARCHIVE_KEY) and o[ARCHIVE_KEY] != "droplets"]


@persistent
def on_frame_change(scene, depsgraph=None):
    for fluid in playback_objects(scene):
        try:
            show_frame(scene, fluid)
        except Exception as e:  # a missing archive must not break playback of the rest
            print(f"meniscus: {fluid.name}: {e}")


@persistent
def on_load(_):
    forget()


def register():
    if on_frame_change not in bpy.app.handlers.frame_change_pre:
        bpy.app.handlers.frame_change_pre.append(on_frame_change)
    if on_load not in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.append(on_load)


def unregister():
    for handlers, fn in ((bpy.app.handlers.frame_change_pre, on_frame_change),
                         (bpy.app.handlers.load_post, on_load)):
        if fn in handlers:
            handlers.remove(fn)
    forget()
