"""A picture of the extension's panel (docs/img/blender_panel.png), drawn from the
panel's own layout code: ``bpy`` as a Python module has no window to screenshot, so
``MENISCUS_PT_panel.draw`` (the real one, from the installed extension) is run into a
layout that records what it is asked to draw, for four states the extension really
reaches on the shipped dam-break frames (a sequence picked, its radius estimated; a bake
under way; the archive played back; live meshing), and the recording is painted in the
manner of Blender's dark sidebar with Pillow. Not a test, and not part of the extension.

    bash blender/build.sh
    target/bpy-venv/bin/pip install pillow
    target/bpy-venv/bin/python blender/panel_picture.py target/blender/meniscus-blender-0.1.0.zip \\
        docs/img/blender_panel.png
"""

import os
import shutil
import sys
import tempfile
import time
import types

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="meniscus-picture-"))

import bpy  # noqa: E402
from PIL import Image, ImageDraw, ImageFont  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FRAMES = (1, 9, 17, 25, 31, 45)
# Where the shot lives (its path shows in the panel): a fixed, readable one.
WORK = os.path.join(tempfile.gettempdir(), "meniscus-panel", "shot")

# --- The recording ------------------------------------------------------------------


class Recorder:
    """Stands for a ``UILayout``: records what ``draw`` asks for, in order (boxes, rows
    and columns as nested recorders; labels, properties, operators, progress bars)."""

    def __init__(self, kind="column"):
        self.kind, self.items, self.alert, self.enabled = kind, [], False, True

    def _nest(self, kind):
        child = Recorder(kind)
        self.items.append(child)
        return child

    def box(self):
        return self._nest("box")

    def row(self, align=False, **_):
        return self._nest("row")

    def column(self, align=False, **_):
        return self._nest("column")

    def separator(self, **_):
        self.items.append(("separator",))

    def label(self, text="", icon="NONE", **_):
        self.items.append(("label", text, icon, self.alert))

    def prop(self, data, name, text=None, icon="NONE", **_):
        p = data.bl_rna.properties[name]
        value = getattr(data, name)
        shown = p.name if text is None else text
        if p.type == "ENUM":
            value = p.enum_items[value].name
        elif p.type == "FLOAT":
            value = f"{value:.{p.precision}f}"
        self.items.append(("prop", p.type, p.subtype, shown, value, self.alert))

    def operator(self, idname, text=None, icon="NONE", **_):
        module, name = idname.split(".")
        label = getattr(getattr(bpy.ops, module), name).get_rna_type().name if text is None else text
        self.items.append(("operator", label, icon))

    def progress(self, factor=0.0, text="", **_):
        self.items.append(("progress", factor, text))


def record(ui):
    layout = Recorder()
    ui.MENISCUS_PT_panel.draw(types.SimpleNamespace(layout=layout), bpy.context)
    return layout


# --- The states ---------------------------------------------------------------------


def states(zip_path):
    """The panel recorded in four states, as (title, recording)."""
    shutil.rmtree(WORK, ignore_errors=True)
    os.makedirs(os.path.join(WORK, "dambreak"))
    for k in FRAMES:
        shutil.copy(os.path.join(ROOT, "datasets", "dambreak_small", f"ParticleData_Fluid_{k}.xyz"),
                    os.path.join(WORK, "dambreak", f"ParticleData_Fluid_{k}.xyz"))
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default", enable_on_install=True)
    ui = sys.modules[next(m for m in sys.modules if m.endswith(".meniscus.ui"))]
    bpy.ops.wm.save_as_mainfile(filepath=os.path.join(WORK, "shot.blend"))
    context = bpy.context
    settings = context.scene.meniscus
    shots = []

    # A folder of numbered frames, as the file browser gives it (an absolute path); the
    # panel estimates the radius of the first frame.
    settings.source = os.path.join(WORK, "dambreak") + os.sep
    shots.append(("Sequence picked", record(ui)))

    # A bake under way, as the Bake button's invoke starts it and its timer updates it.
    job = ui._bake_job(settings)
    ui._job["job"] = job
    settings.progress, settings.status = 0.0, f"baking {job.total} frame(s)…"
    job.start()
    while job.done < 2 and not job.finished:
        time.sleep(0.02)
    timer = types.SimpleNamespace(type="TIMER")
    ui.MENISCUS_OT_bake.modal(types.SimpleNamespace(_timer=None), context, timer)
    shots.append(("Baking", record(ui)))
    job.join()
    ui._job["job"] = None
    ui._after_bake(context, settings, job)  # what the timer does when the bake ends
    context.scene.frame_set(17)
    shots.append(("Playing back", record(ui)))

    bpy.ops.meniscus.live_start()
    context.scene.frame_set(9)
    context.scene.frame_set(17)
    shots.append(("Live", record(ui)))
    bpy.ops.meniscus.live_stop()
    return shots


# --- The painting -------------------------------------------------------------------

S = 2  # pixels per Blender UI pixel (a 2x display)
ROW, GAP, PAD, WIDTH = 20 * S, 3 * S, 6 * S, 400 * S
FONT_SIZE = 11 * S
REGION, PANEL, HEADER, BOX, BOX_EDGE = (48, 48, 48), (56, 56, 56), (66, 66, 66), (44, 44, 44), (36, 36, 36)
BUTTON, FIELD, NUMBER, TEXT, DIM = (84, 84, 84), (29, 29, 29), (40, 40, 40), (230, 230, 230), (160, 160, 160)
BLUE, ALERT, OUTLINE = (71, 114, 179), (230, 80, 80), (30, 30, 30)


def font():
    for path in ("/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf", "DejaVuSans.ttf"):
        try:
            return ImageFont.truetype(path, FONT_SIZE)
        except OSError:
            pass
    return ImageFont.load_default(size=FONT_SIZE)


FONT = font()


def fit(text, width):
    """``text`` cut in the middle with an ellipsis to ``width`` pixels (as Blender
    shortens paths)."""
    if FONT.getlength(text) <= width:
        return text
    keep = len(text)
    while keep > 2:
        keep -= 1
        head, tail = text[:keep // 2], text[len(text) - (keep - keep // 2):]
        if FONT.getlength(head + "…" + tail) <= width:
            return head + "…" + tail
    return "…"


def icon(draw, name, x, y, colour=TEXT):
    """A small glyph for Blender's icon ``name`` at (x, y), the row's top left; returns
    the width taken."""
    if name in (None, "NONE"):
        return 0
    c, r = (x + 8 * S, y + ROW // 2), 5 * S
    if name == "PLAY":
        draw.polygon([(c[0] - r + S, c[1] - r), (c[0] - r + S, c[1] + r), (c[0] + r, c[1])], fill=colour)
    elif name == "PAUSE":
        draw.rectangle([c[0] - r + S, c[1] - r, c[0] - S, c[1] + r], fill=colour)
        draw.rectangle([c[0] + S, c[1] - r, c[0] + r - S, c[1] + r], fill=colour)
    elif name == "CANCEL":
        draw.ellipse([c[0] - r, c[1] - r, c[0] + r, c[1] + r], outline=colour, width=S)
        d = r // 2
        draw.line([c[0] - d, c[1] - d, c[0] + d, c[1] + d], fill=colour, width=S)
        draw.line([c[0] - d, c[1] + d, c[0] + d, c[1] - d], fill=colour, width=S)
    elif name == "RENDER_ANIMATION":
        draw.rectangle([c[0] - r, c[1] - r + S, c[0] + r, c[1] + r - S], outline=colour, width=S)
        for k in (-1, 1):
            draw.line([c[0] + k * r // 2, c[1] - r + S, c[0] + k * r // 2, c[1] + r - S], fill=colour, width=S)
    elif name == "ERROR":
        draw.polygon([(c[0], c[1] - r), (c[0] - r, c[1] + r), (c[0] + r, c[1] + r)], fill=(230, 170, 40))
        draw.line([c[0], c[1] - r // 3, c[0], c[1] + r // 3], fill=(30, 30, 30), width=S)
    elif name == "FILEBROWSER":
        draw.rectangle([c[0] - r, c[1] - r // 2, c[0] + r, c[1] + r], fill=colour)
        draw.rectangle([c[0] - r, c[1] - r, c[0] - r // 4, c[1] - r // 2], fill=colour)
    return 18 * S


def text(draw, x, y, s, colour=TEXT, width=None, anchor="lm"):
    if width is not None:
        s = fit(s, width)
    draw.text((x, y + ROW // 2), s, font=FONT, fill=colour, anchor=anchor)


def field(draw, x, y, w, fill, outline=OUTLINE):
    draw.rounded_rectangle([x, y, x + w, y + ROW], radius=4 * S, fill=fill, outline=outline, width=1)


def height(item):
    if isinstance(item, Recorder):
        if item.kind == "row":
            return max((height(i) for i in item.items), default=0)
        inner = sum(height(i) for i in item.items) + GAP * max(len(item.items) - 1, 0)
        return inner + (2 * PAD if item.kind == "box" else 0)
    return ROW // 2 if item[0] == "separator" else ROW


def paint(draw, item, x, y, w):
    """Paints ``item`` in the box (x, y, width w); returns its height."""
    if isinstance(item, Recorder):
        h = height(item)
        if item.kind == "box":
            draw.rounded_rectangle([x, y, x + w, y + h], radius=5 * S, fill=BOX, outline=BOX_EDGE, width=S)
            x, y, w = x + PAD, y + PAD, w - 2 * PAD
        if item.kind == "row" and item.items:
            each = (w - GAP * (len(item.items) - 1)) / len(item.items)
            for k, child in enumerate(item.items):
                paint(draw, child, round(x + k * (each + GAP)), y, round(each))
            return h
        for child in item.items:
            y += paint(draw, child, x, y, w) + GAP
        return h
    kind = item[0]
    if kind == "label":
        _, s, glyph, alert = item
        dx = icon(draw, glyph, x, y)
        text(draw, x + dx + (0 if dx else 2 * S), y, s, ALERT if alert else TEXT, w - dx - 2 * S)
    elif kind == "operator":
        _, s, glyph = item
        field(draw, x, y, w, BUTTON)
        tw = FONT.getlength(s) + (18 * S if glyph != "NONE" else 0)
        left = x + (w - tw) / 2
        dx = icon(draw, glyph, round(left), y)
        text(draw, left + dx, y, s)
    elif kind == "progress":
        _, factor, s = item
        field(draw, x, y, w, NUMBER)
        if factor > 0:
            draw.rounded_rectangle([x, y, x + max(8 * S, round(w * factor)), y + ROW], radius=4 * S, fill=BLUE)
        text(draw, x + w / 2, y, s, width=w - 8 * S, anchor="mm")
    elif kind == "prop":
        _, ptype, subtype, name, value, _alert = item
        if ptype == "BOOLEAN":
            b = 12 * S
            top = y + (ROW - b) // 2
            draw.rounded_rectangle([x + 2 * S, top, x + 2 * S + b, top + b], radius=3 * S,
                                   fill=BLUE if value else BUTTON, outline=OUTLINE)
            if value:
                draw.line([x + 5 * S, top + b // 2, x + 7 * S, top + b - 3 * S, x + b - S, top + 3 * S],
                          fill=TEXT, width=2 * S)
            text(draw, x + b + 6 * S, y, name, width=w - b - 6 * S)
        elif ptype in ("FLOAT", "INT"):
            field(draw, x, y, w, BUTTON)
            text(draw, x + 8 * S, y, name, width=w / 2)
            text(draw, x + w - 8 * S, y, str(value), anchor="rm")
        else:  # a label, then the field (string, path or menu)
            split = round(w * 0.36)
            text(draw, x + 2 * S, y, name, DIM, split - 4 * S)
            fx, fw = x + split, w - split
            if ptype == "ENUM":
                field(draw, fx, fy := y, fw, NUMBER)
                text(draw, fx + 6 * S, fy, str(value), width=fw - 24 * S)
                cx, cy = fx + fw - 10 * S, y + ROW // 2
                draw.polygon([(cx - 4 * S, cy - 2 * S), (cx + 4 * S, cy - 2 * S), (cx, cy + 3 * S)], fill=DIM)
            else:
                path = subtype in ("FILE_PATH", "DIR_PATH")
                field(draw, fx, y, fw - (22 * S if path else 0), FIELD)
                text(draw, fx + 6 * S, y, str(value), width=fw - (34 * S if path else 12 * S))
                if path:
                    field(draw, fx + fw - 20 * S, y, 20 * S, BUTTON)
                    icon(draw, "FILEBROWSER", fx + fw - 18 * S, y)
    return height(item)


def panel_image(title, recording):
    """One sidebar: the state's title above, the region with the meniscus panel and its
    tab on the right."""
    body = height(recording)
    caption, header, tab = 30 * S, 24 * S, 22 * S
    h = caption + header + body + 2 * PAD + 8 * S
    image = Image.new("RGB", (WIDTH + tab, h), (35, 35, 35))
    draw = ImageDraw.Draw(image)
    draw.text((WIDTH // 2, caption // 2), title, font=FONT, fill=TEXT, anchor="mm")
    top = caption
    draw.rectangle([0, top, WIDTH + tab, h], fill=REGION)
    # The sidebar's tab column, "meniscus" written upwards.
    draw.rectangle([WIDTH, top, WIDTH + tab, h], fill=(40, 40, 40))
    label = Image.new("RGB", (round(FONT.getlength("meniscus")) + 16 * S, tab - 4 * S), (72, 72, 72))
    ImageDraw.Draw(label).text((8 * S, (tab - 4 * S) // 2), "meniscus", font=FONT, fill=TEXT, anchor="lm")
    image.paste(label.rotate(90, expand=True), (WIDTH + 2 * S, top + 4 * S))
    x, w = 4 * S, WIDTH - 8 * S
    draw.rounded_rectangle([x, top + 4 * S, x + w, h - 4 * S], radius=5 * S, fill=PANEL)
    draw.rounded_rectangle([x, top + 4 * S, x + w, top + 4 * S + header], radius=5 * S, fill=HEADER)
    cx, cy = x + 12 * S, top + 4 * S + header // 2
    draw.polygon([(cx - 4 * S, cy - 2 * S), (cx + 4 * S, cy - 2 * S), (cx, cy + 3 * S)], fill=TEXT)
    draw.text((x + 22 * S, cy), "meniscus", font=FONT, fill=TEXT, anchor="lm")
    paint(draw, recording, x + PAD, top + 4 * S + header + PAD, w - 2 * PAD)
    return image


def main(zip_path, out, columns=2):
    images = [panel_image(title, rec) for title, rec in states(zip_path)]
    gap = 12 * S
    rows = [images[k:k + columns] for k in range(0, len(images), columns)]
    width = max(sum(i.width for i in row) + gap * (len(row) + 1) for row in rows)
    heights = [max(i.height for i in row) for row in rows]
    sheet = Image.new("RGB", (width, sum(heights) + gap * (len(rows) + 1)), (35, 35, 35))
    y = gap
    for row, h in zip(rows, heights):
        x = gap
        for i in row:
            sheet.paste(i, (x, y))
            x += i.width + gap
        y += h + gap
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    sheet.save(out, optimize=True)
    print(out, sheet.size)


if __name__ == "__main__":
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    main(args[0], args[1])
