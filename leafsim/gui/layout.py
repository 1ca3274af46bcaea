"""The window's fixed layout and the small imgui helpers every panel uses.

Controls on the left, Stats on the right, the 3-D view between them and one status bar along
the bottom.  The panels cannot be moved or resized, and everything that comes and goes lives in
the status bar, whose height never changes: no widget ever moves under the user's mouse."""

from __future__ import annotations

from imgui_bundle import imgui

from leafsim.appearance.view import PIGMENT_VIEWS
from leafsim.gui.status import printable

LEFT_W, RIGHT_W, STATUS_H = 380, 330, 34
#: the smallest window: both panels and a 280 px view between them, and room for the controls
MIN_WINDOW = (LEFT_W + RIGHT_W + 280, 600)
BACKGROUND = (0.80, 0.84, 0.88)
PANEL_BG = (0.11, 0.11, 0.12)
#: resolution factors of the 3-D view (llvmpipe's cost is per pixel)
SCALES = (0.35, 0.5, 0.75, 1.0)
VIEWS = ("shaded", "wireframe", "particles", "springs", "mass", "water", *PIGMENT_VIEWS, "crinkle")
#: heat maps: (label of the colour bar, unit, scale applied to the field for the ticks)
HEAT_UNITS = {"mass": ("particle mass", "mg", 1.0), "water": ("water / initial water", "%", 100.0),
              **{p: (f"{p} / summer content", "%", 100.0) for p in PIGMENT_VIEWS},
              "crinkle": ("lamina's excess length (render.crinkle)", "%", 100.0)}
#: heat maps drawn over their own range even when "fit range to the data" is off (not fractions of 1)
OWN_RANGE = ("mass", "crinkle")
#: albedo of photo species: pigment colour with the photo's detail, the photo tinted by the
#: pigment change, or the pigment colour alone
ALBEDOS = ("detail", "photo", "colours")
COMPARES = ("off", "overlay", "blink")


def fixed_flags():
    """Window flags of a panel that never moves, resizes or draws its own background."""
    return (imgui.WindowFlags_.no_move | imgui.WindowFlags_.no_resize | imgui.WindowFlags_.no_collapse
            | imgui.WindowFlags_.no_background | imgui.WindowFlags_.no_saved_settings)


def tip(text: str) -> None:
    """A tooltip for the last item (a path in it may hold bytes that are not UTF-8), wrapped at
    46 ems (the quality levels' lines ran past a 1280-pixel window)."""
    if imgui.is_item_hovered(imgui.HoveredFlags_.for_tooltip):
        imgui.begin_tooltip()
        imgui.push_text_wrap_pos(imgui.get_font_size() * 46.0)
        imgui.text_unformatted(printable(text))
        imgui.pop_text_wrap_pos()
        imgui.end_tooltip()


def window_rects():
    """(W, H, left rect, right rect, status rect) in window pixels."""
    io = imgui.get_io()
    W, H = io.display_size.x, io.display_size.y
    top = H - STATUS_H
    return W, H, (0, 0, LEFT_W, top), (W - RIGHT_W, 0, RIGHT_W, top), (0, top, W, STATUS_H)


#: frames per second the window draws while "Dry to end" runs (a progress bar and the leaf)
DRY_UI_HZ = 3.0
