"""The panel (View3D ▸ Sidebar ▸ meniscus), its settings and operators: pick a particle
sequence, see its estimated radius, choose a preset, bake to a ``.mseq`` (or a USD
stage) with a progress bar and a cancel button, play an archive back, or mesh the
sequence live on frame change (a viewport and a render preset)."""

import os

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

from . import core, scene

# The bake under way (one at a time), read by the modal operator and the panel.
_job = {"job": None}


def _on_source(self, context):
    """A new source: its radius is estimated again."""
    self.estimated_radius = 0.0
    self.source_info = ""
    try:
        seq = core.resolve_sequence(bpy.path.abspath(self.source))
        self.source_info = f"{len(seq.frames)} frame(s), {seq.frames[0]}–{seq.frames[-1]}"
        self.estimated_radius = core.estimate_radius(seq)
    except Exception as e:
        self.source_info = str(e)


PRESET_ITEMS = [
    ("STEADY", "Steady", "For animation: shading that does not flicker from frame to frame"),
    ("STILL", "Still", "The best still frame: decimated, smoothed and subdivided"),
    ("PREVIEW", "Preview", "Fast: a coarser grid, no subdivision or decimation"),
    ("PAPER", "Paper", "Akinci et al. 2013's pipeline"),
]


def _on_live_preset(self, context):
    """A preset changed: the live fluid is shown again with the preset of the moment."""
    for fluid in scene.live_objects(context.scene):
        scene.show_live(context.scene, fluid)


class MeniscusSettings(bpy.types.PropertyGroup):
    source: StringProperty(
        name="Particles", subtype="FILE_PATH", update=_on_source,
        description="A particle sequence: a file of it, a {} pattern, a folder of numbered frames or a .pvd")
    source_info: StringProperty(name="Sequence")
    estimated_radius: FloatProperty(name="Estimated radius", precision=5)
    radius: FloatProperty(
        name="Radius", default=0.0, min=0.0, precision=5,
        description="Particle radius r, world units; 0 takes the estimate. A radius far from the estimate is refused")
    force_radius: BoolProperty(
        name="Force radius", default=False,
        description="Run with the given radius even where the library refuses it (radius_check=False)")
    preset: EnumProperty(name="Preset", default="STEADY", items=PRESET_ITEMS)
    output: StringProperty(
        name="Cache", subtype="FILE_PATH", default="//meniscus.mseq",
        description="The cache: a .mseq archive (played back here) or a USD stage (.usdc, imported after the bake)")
    progress: FloatProperty(name="Progress", subtype="PERCENTAGE", min=0.0, max=100.0, default=0.0)
    status: StringProperty(name="Status")
    archive: StringProperty(name="Archive", subtype="FILE_PATH", description="A .mseq archive to play back")
    live_viewport_preset: EnumProperty(
        name="Viewport", default="PREVIEW", items=PRESET_ITEMS, update=_on_live_preset,
        description="The preset live meshing uses in the viewport (Preview: several times faster than Steady)")
    live_render_preset: EnumProperty(
        name="Render", default="STEADY", items=PRESET_ITEMS, update=_on_live_preset,
        description="The preset live meshing uses while a render runs (Steady: no flicker from frame to frame)")
    live_cache_mib: IntProperty(
        name="Cache MiB", default=512, min=16, soft_max=8192,
        description="Memory kept for recently meshed frames (per preset), the least recently used dropped first")
    live_status: StringProperty(name="Live status")


def _bake_job(settings):
    seq = core.resolve_sequence(bpy.path.abspath(settings.source))
    output = bpy.path.abspath(settings.output)
    return core.BakeJob(seq, output, radius=settings.radius, preset=settings.preset,
                        radius_check=not settings.force_radius,
                        usd=output.lower().endswith((".usdc", ".usda", ".usd")))


def _after_bake(context, settings, job):
    if job.error:
        settings.status = job.error
        return {"CANCELLED"}
    settings.progress = 100.0 * job.fraction
    if job.cancelled:
        settings.status = f"cancelled after {job.done} of {job.total} frames (the cache keeps them)"
    else:
        settings.status = f"baked {job.done} frame(s) to {job.output}"
    if job.done and os.path.exists(job.output):
        if job.usd:
            bpy.ops.wm.usd_import(filepath=job.output)
        else:
            settings.archive = job.output
            scene.load_archive(context, job.output)
    return {"FINISHED"}


class MENISCUS_OT_bake(bpy.types.Operator):
    """Bake the particle sequence to the cache, off Blender's main thread"""

    bl_idname = "meniscus.bake"
    bl_label = "Bake"

    _timer = None

    def execute(self, context):
        # Run through (scripts, background mode): the bake on this thread.
        settings = context.scene.meniscus
        try:
            job = _bake_job(settings)
        except Exception as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        job.run()
        result = _after_bake(context, settings, job)
        if job.error:
            self.report({"ERROR"}, job.error)
        return result

    def invoke(self, context, event):
        if _job["job"] is not None:
            self.report({"WARNING"}, "a bake is under way")
            return {"CANCELLED"}
        settings = context.scene.meniscus
        try:
            job = _bake_job(settings)
        except Exception as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        _job["job"] = job
        settings.progress, settings.status = 0.0, f"baking {job.total} frame(s)…"
        job.start()
        self._timer = context.window_manager.event_timer_add(0.25, window=context.window)
        context.window_manager.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        job = _job["job"]
        settings = context.scene.meniscus
        if event.type == "ESC":
            job.cancel()
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        settings.progress = 100.0 * job.fraction
        if job.last:
            settings.status = f"frame {job.last.get('frame')} {job.last.get('status')} ({job.done}/{job.total})"
        for area in context.screen.areas if context.screen else []:
            area.tag_redraw()
        if not job.finished:
            return {"PASS_THROUGH"}
        context.window_manager.event_timer_remove(self._timer)
        _job["job"] = None
        result = _after_bake(context, settings, job)
        if job.error:
            self.report({"ERROR"}, job.error)
        return result


class MENISCUS_OT_cancel(bpy.types.Operator):
    """Stop the bake after the frame under way (the cache keeps the frames done)"""

    bl_idname = "meniscus.cancel"
    bl_label = "Cancel"

    def execute(self, context):
        if _job["job"] is not None:
            _job["job"].cancel()
        return {"FINISHED"}


class MENISCUS_OT_load(bpy.types.Operator):
    """Play a .mseq archive back as an animated mesh (each frame decoded on frame change)"""

    bl_idname = "meniscus.load_archive"
    bl_label = "Play Archive"

    filepath: StringProperty(subtype="FILE_PATH")

    def execute(self, context):
        path = self.filepath or context.scene.meniscus.archive
        try:
            scene.load_archive(context, path)
        except Exception as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        return {"FINISHED"}


class MENISCUS_OT_live_start(bpy.types.Operator):
    """Mesh the particle sequence live: each frame change meshes the current frame's particle file (viewport preset; the render preset under a render)"""

    bl_idname = "meniscus.live_start"
    bl_label = "Live"

    def execute(self, context):
        settings = context.scene.meniscus
        try:
            scene.start_live(context, settings.source, settings.radius, settings.force_radius)
        except Exception as e:
            settings.live_status = str(e)
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        settings.live_status = ""
        return {"FINISHED"}


class MENISCUS_OT_live_stop(bpy.types.Operator):
    """Leave live mode: the live objects are removed and the cached frames dropped"""

    bl_idname = "meniscus.live_stop"
    bl_label = "Stop Live"

    def execute(self, context):
        scene.stop_live(context.scene)
        context.scene.meniscus.live_status = ""
        return {"FINISHED"}


def live_label(report):
    """The panel's line on the live frame shown (``scene.live_report``, no error): the
    scene frame, and the file frame it holds when it has no file of its own."""
    if report["kept"]:
        how = "already shown"
    elif report["cached"]:
        how = "from the cache"
    else:
        how = f"meshed in {report['mesh_seconds']:.2f} s"
    frame = f"frame {report['frame']}"
    if report["held"] is not None:
        frame += f": no file, shows frame {report['held']}"
    return (f"{frame} ({report['preset'].title()}): {report['triangles']} triangles, "
            f"{report['droplets']} droplets, {how}")


def _draw_live(layout, context, settings):
    box = layout.box()
    box.label(text="Live")
    row = box.row()
    row.prop(settings, "live_viewport_preset")
    row.prop(settings, "live_render_preset")
    box.prop(settings, "live_cache_mib")
    live = scene.live_objects(context.scene)
    if not live:
        box.operator("meniscus.live_start", icon="PLAY")
        if settings.live_status:
            box.label(text=settings.live_status, icon="ERROR")
        return
    box.operator("meniscus.live_stop", icon="PAUSE")
    report = scene.live_report
    if report["error"]:
        row = box.row()
        row.alert = True
        row.label(text=report["error"], icon="ERROR")
    elif report["frame"] is not None:
        box.label(text=live_label(report))
    for m in scene._meshers.values():
        stats = m.stats
        box.label(text=f"cache: {stats['cached_frames']} frame(s), {stats['cached_bytes'] / 2**20:.0f} MiB, "
                       f"{stats['hits']} hit(s); radius {m.radius:.5g}")


class MENISCUS_PT_panel(bpy.types.Panel):
    bl_label = "meniscus"
    bl_idname = "MENISCUS_PT_panel"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "meniscus"

    def draw(self, context):
        settings = context.scene.meniscus
        layout = self.layout
        box = layout.box()
        box.label(text="Particles")
        box.prop(settings, "source")
        if settings.source_info:
            box.label(text=settings.source_info)
        if settings.estimated_radius > 0:
            box.label(text=f"Estimated radius: {settings.estimated_radius:.5g}")
        row = box.row()
        row.prop(settings, "radius")
        row.prop(settings, "force_radius", text="Force")
        box = layout.box()
        box.label(text="Bake")
        box.prop(settings, "preset")
        box.prop(settings, "output")
        if _job["job"] is not None:
            box.progress(factor=settings.progress / 100.0, text=settings.status)
            box.operator("meniscus.cancel", icon="CANCEL")
        else:
            box.operator("meniscus.bake", icon="RENDER_ANIMATION")
            if settings.status:
                box.label(text=settings.status)
        _draw_live(layout, context, settings)
        box = layout.box()
        box.label(text="Playback")
        box.prop(settings, "archive")
        box.operator("meniscus.load_archive", icon="PLAY")
        if scene.last_swap["frame"] is not None:
            box.label(text=f"frame {scene.last_swap['frame']}: {1000 * scene.last_swap['seconds']:.0f} ms")


classes = (MeniscusSettings, MENISCUS_OT_bake, MENISCUS_OT_cancel, MENISCUS_OT_load, MENISCUS_OT_live_start,
           MENISCUS_OT_live_stop, MENISCUS_PT_panel)


def register():
    for c in classes:
        bpy.utils.register_class(c)
    bpy.types.Scene.meniscus = PointerProperty(type=MeniscusSettings)


def unregister():
    del bpy.types.Scene.meniscus
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
