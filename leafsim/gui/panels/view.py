"""What is drawn over the 3-D view: the scaled view texture, the photo compare (overlay or
blink), the caption, the heat map's colour bar; and the mouse (orbit, pan, zoom)."""

from __future__ import annotations

import math
import time

import numpy as np
from imgui_bundle import imgui

from leafsim.appearance.colormaps import colormap
from leafsim.gui.layout import HEAT_UNITS
from leafsim.gui.photo import overlay_grid
from leafsim.sim.environment import clock_text


#: the heat map's colour bar sits on this card (RGBA)
LEGEND_CARD = (0.97, 0.97, 0.95, 0.82)



#: the widest line of the colour bar's label [px] (a longer label wraps)
LEGEND_TEXT_W = 120.0


def wrap_words(text: str, width: float, measure) -> list[str]:
    """``text`` in lines of at most ``width`` px (``measure(s)`` → px), broken between words (a
    word wider than that keeps a line of its own)."""
    lines: list[str] = []
    for word in text.split():
        if lines and measure(lines[-1] + " " + word) <= width:
            lines[-1] += " " + word
        else:
            lines.append(word)
    return lines or [""]


def tick_labels(values) -> list[str]:
    """The colour bar's tick labels: 3 significant digits, more where that would print two
    ticks alike (a field spanning 99.6-100 % read "100" at every tick)."""
    labels = [f"{v:.3g}" for v in values]
    for digits in range(4, 10):
        if len(set(labels)) == len(labels):
            break
        labels = [f"{v:.{digits}g}" for v in values]
    return labels

def caption(name: str, frame: str, clock: str, water: str, width: float, measure) -> str:
    """The caption under the 3-D view within ``width`` px (``measure(text)`` its width): the whole
    "NAME  frame N  t = …  water …", else without the name, then without the clock; the water
    left is kept last (a small window cut the caption at the stats panel, the water first)."""
    for parts in ((name, frame, clock, water), (frame, clock, water), (frame, water), (water,)):
        text = "  ".join(parts)
        if measure(text) <= width:
            return text
    return water


class ViewOverlay:
    def __init__(self, app):
        self.app = app

    def draw(self) -> None:
        app = self.app
        s = app.session
        x0, y0, w, h = app.leaf_rect_px
        dl = imgui.get_background_draw_list()
        if s.ready and app.view_tex is not None and not app.view_direct:
            dl.add_image(imgui.ImTextureRef(app.view_tex.glo), (x0, y0), (x0 + w, y0 + h), (0, 1), (1, 0))
        if s.ready:
            self.photo_overlay(dl)
            sp = s.shown_species  # the leaf on screen: the old species while a switch builds
            txt = caption(sp.name, f"frame {s.frame}", clock_text(s.state, s.params), f"water {100 * s.water_fraction():.1f} %",
                          w - 24, lambda t: imgui.calc_text_size(t).x)
            # within the view: at 1024 x 700 the caption ran on under the stats panel, its water hidden
            dl.push_clip_rect((x0, y0), (x0 + w, y0 + h), True)
            dl.add_text((x0 + 12, y0 + h - 24), imgui.get_color_u32((0.1, 0.1, 0.1, 1.0)), txt)
            dl.pop_clip_rect()
            if app.view in HEAT_UNITS and app.renderer is not None and app.renderer.mesh is not None:
                self.legend(dl, x0 + w - 70, y0 + 8, h * 0.33)

    def legend(self, dl, x: float, card_top: float, height: float) -> None:
        """Colour bar of the heat map with its range, ticks and unit, on a card whose top is at
        ``card_top``; the bar is ``height`` px tall."""
        app = self.app
        label, unit, k = HEAT_UNITS[app.view]
        opts = app.render_options()
        lo, hi = app.renderer.scalar_range(opts)
        # the label wrapped to the card's width: on one line a long one ("lamina's excess length
        # (render.crinkle)") made a 265 px card that hid most of maple's right lobe
        ts = np.linspace(0.0, 1.0, 5)
        ticks = tick_labels((lo + (hi - lo) * ts) * k)
        # the card reaches past the widest tick label ("0.0323" touched its edge), the view's
        # right edge staying where it was: a wider label moves the bar left
        right = 26 + max(imgui.calc_text_size(t).x for t in ticks) + 8
        x -= max(right - 66.0, 0.0)
        lines = wrap_words(label, LEGEND_TEXT_W, lambda t: imgui.calc_text_size(t).x)
        lh = imgui.get_text_line_height()
        tw = max(imgui.calc_text_size(t).x for t in lines)
        top = card_top + 6
        y = top + lh * len(lines) + 22  # the bar, under the label and the unit
        # a light card behind the bar, its ticks and its label: they stay legible where the leaf
        # reaches under them (a wide leaf's lobe ran under the bar, its numbers unreadable)
        edge = x + max(right, 66.0)
        dl.add_rect_filled((min(x - 10, edge - 6 - tw), top - 6), (edge, y + height + 28),
                           imgui.get_color_u32(LEGEND_CARD), 6.0)
        n = 32
        for i in range(n):  # top = high
            c0 = colormap(opts.colormap, 1.0 - i / n)
            c1 = colormap(opts.colormap, 1.0 - (i + 1) / n)
            y_a, y_b = y + height * i / n, y + height * (i + 1) / n
            u0 = imgui.get_color_u32((*c0, 1.0))
            u1 = imgui.get_color_u32((*c1, 1.0))
            dl.add_rect_filled_multi_color((x, y_a), (x + 18, y_b), u0, u0, u1, u1)
        ink = imgui.get_color_u32((0.1, 0.1, 0.1, 1.0))
        dl.add_rect((x, y), (x + 18, y + height), ink)
        for t, text in zip(ts, ticks):
            ty = y + height * (1.0 - t)
            dl.add_line((x + 18, ty), (x + 23, ty), ink)
            dl.add_text((x + 26, ty - 7), ink, text)
        for i, t in enumerate(lines):  # right-aligned, as the card's right edge is fixed
            dl.add_text((edge - 6 - imgui.calc_text_size(t).x, top + lh * i), ink, t)
        dl.add_text((x, y - 20), ink, f"[{unit}]")
        if not opts.scalar_range:
            note = "2nd..98th pct"
            dl.add_text((edge - 6 - imgui.calc_text_size(note).x, y + height + 8), ink, note)

    def photo_overlay(self, dl) -> None:
        """The photo projected onto the leaf's rest place (overlay or blink compare)."""
        app = self.app
        if app.photo_compare == "off" or app.photo_tex_masked is None or app.photo_affine is None:
            return
        if app.photo_compare == "blink" and int(time.monotonic() / 0.6) % 2 == 0:
            return
        alpha = 1.0 if app.photo_compare == "blink" else float(app.photo_alpha)
        pts, uv = overlay_grid(app.photo_affine, app.photo_z, app.view_proj(), app.leaf_rect_px)
        col = imgui.get_color_u32((1.0, 1.0, 1.0, alpha))
        ref = imgui.ImTextureRef(app.photo_tex_masked.glo)
        n = pts.shape[0] - 1
        for i in range(n):
            for j in range(n):
                q = [pts[i, j], pts[i, j + 1], pts[i + 1, j + 1], pts[i + 1, j]]
                t = [uv[i, j], uv[i, j + 1], uv[i + 1, j + 1], uv[i + 1, j]]
                dl.add_image_quad(ref, *[tuple(map(float, p)) for p in q], *[tuple(map(float, c)) for c in t], col)

    def mouse(self, io) -> None:
        app = self.app
        if app.renderer is None:
            return
        if not io.want_capture_mouse:
            _, _, _, h = app.leaf_rect_px
            dx, dy = io.mouse_delta.x, io.mouse_delta.y
            if imgui.is_mouse_down(imgui.MouseButton_.left) and (dx or dy):
                app.camera.drag(dx, dy)
            if (imgui.is_mouse_down(imgui.MouseButton_.right) or imgui.is_mouse_down(imgui.MouseButton_.middle)) and (dx or dy):
                app.camera.pan(dx, dy, h)
            if io.mouse_wheel:
                app.camera.zoom(io.mouse_wheel)
        # every frame, the mouse over a panel or not: the ground switched on with the eye below
        # it (or the leaf falling past it) showed the leaf through the ground's underside
        if app.show_ground:
            keep_above_ground(app.camera, app.renderer)


def keep_above_ground(camera, renderer) -> None:
    """With the ground shown, the eye stays above it: orbiting below it drew the stalk and the
    veins through the ground's underside (the ground plane lies just under the leaf's lowest
    point, as the renderer draws it)."""
    if renderer is None or getattr(renderer, "mesh", None) is None:
        return
    gz = float(renderer.lo[2]) - 0.004 * float(renderer.radius)
    lift = gz + 0.02 * float(renderer.radius) - float(np.asarray(camera.target, np.float64)[2])
    lowest = math.degrees(math.asin(float(np.clip(lift / max(camera.distance, 1e-12), -1.0, 1.0))))
    if camera.pitch < lowest:
        camera.pitch = float(min(lowest, 89.0))
