"""meniscus inside Blender: bake particle sequences to a compressed .mseq cache (or a USD
stage) off the main thread, and play an archive back as an animated mesh with its
droplets, velocity on both for motion blur; or mesh a sequence live on frame change (a
viewport and a render preset, recent frames cached). See docs/blender.md."""

from . import scene, ui


def register():
    ui.register()
    scene.register()


def unregister():
    scene.unregister()
    ui.unregister()
