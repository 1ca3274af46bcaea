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



def tick_labels(values) -> list[str]:
    """The colour bar's tick labels: 3 significant digits, more where that would print two
    ticks alike (a field spanning 99.6-100 % read "100" at every tick)."""
    labels = [f"{v:.3g}" for v in values]
    for digits in range(4, 10):
        if len(set(labels)) == len(labels):
            break
        labels = [f"{v:.{digits}g}" for v in values]
    return labels

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
            txt = f"{sp.name}  frame {s.frame}  {clock_text(s.state, s.params)}  water {100 * s.water_fraction():.1f} %"
            dl.add_text((x0 + 12, y0 + h - 24), imgui.get_color_u32((0.1, 0.1, 0.1, 1.0)), txt)
            if app.view in HEAT_UNITS and app.renderer is not None and app.renderer.mesh is not None:
                self.legend(dl, x0 + w - 70, y0 + 44, h * 0.33)

    def legend(self, dl, x: float, y: float, height: float) -> None:
        """Colour bar of the heat map with its range, ticks and unit."""
        app = self.app
        label, unit, k = HEAT_UNITS[app.view]
        opts = app.render_options()
        lo, hi = app.renderer.scalar_range(opts)
        tw = imgui.calc_text_size(label).x
        # a light card behind the bar, its ticks and its label: they stay legible where the leaf
        # reaches under them (a wide leaf's lobe ran under the bar, its numbers unreadable)
        dl.add_rect_filled((min(x - 10, x + 54 - tw), y - 42), (x + 66, y + height + 28),
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
        ts = np.linspace(0.0, 1.0, 5)
        for t, text in zip(ts, tick_labels((lo + (hi - lo) * ts) * k)):
            ty = y + height * (1.0 - t)
            dl.add_line((x + 18, ty), (x + 23, ty), ink)
            dl.add_text((x + 26, ty - 7), ink, text)
        dl.add_text((x + 60 - tw, y - 36), ink, label)
        dl.add_text((x, y - 20), ink, f"[{unit}]")
        if not opts.scalar_range:
            note = "2nd..98th pct"
            dl.add_text((x + 60 - imgui.calc_text_size(note).x, y + height + 8), ink, note)

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
        if io.want_capture_mouse or app.renderer is None:
            return
        _, _, _, h = app.leaf_rect_px
        dx, dy = io.mouse_delta.x, io.mouse_delta.y
        if imgui.is_mouse_down(imgui.MouseButton_.left) and (dx or dy):
            app.camera.drag(dx, dy)
        if (imgui.is_mouse_down(imgui.MouseButton_.right) or imgui.is_mouse_down(imgui.MouseButton_.middle)) and (dx or dy):
            app.camera.pan(dx, dy, h)
        if io.mouse_wheel:
            app.camera.zoom(io.mouse_wheel)
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
