"""Screenshots of the GUI for docs/ (run under a display or xvfb-run):

    .venv/bin/python tools/gui_screenshots.py   # docs/gui.png, gui_error.png, gui_heatmap.png, gui_photo.png

The real application is driven by the ImGui test engine (as the GUI tests do): the default
view after drying for a while, the status bar showing an error, the water heat map with its
colour bar, and grapevine (whose photo is stored base up) with the photo turned beside the
model and laid over it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def shot(name: str, species: str, setup, overrides=None) -> None:
    from imgui_bundle import hello_imgui
    from imgui_bundle.immapp import testing

    from leafsim.base.fileio import write_png_atomic
    from leafsim.gui.app import LeafApp, _configure_threads, without_test_time_limit
    from leafsim.interactive.session import Session

    _configure_threads()
    session = Session(species, overrides=overrides)
    app = LeafApp(session)

    def body(ctx):
        setup(ctx, app)
        ctx.yield_(4)

    rp = app.runner_params()
    without_test_time_limit(rp)  # drying maple to frame 900 takes minutes on a small machine
    testing.run(test_function=body, runner_params=rp, add_ons_params=app.addons())
    img = np.asarray(hello_imgui.final_app_window_screenshot())
    out = ROOT / "docs" / name
    write_png_atomic(out, np.ascontiguousarray(img[:, :, :3]), rgb=True)
    print(f"wrote {out}")


def _dry(ctx, app, frames):
    """Simulate ``frames`` frames (synchronously: a picture, not a benchmark), then play a
    few frames in the window."""
    s = app.session
    s.playback.play_until(frames)  # in the worker, the window drawing meanwhile
    while s.frame < frames:
        ctx.yield_()
    ctx.item_click("**/###play")
    ctx.yield_(20)
    ctx.item_click("**/###play")
    ctx.yield_(130)  # the fps shown is over the last 120 frames


def default_view(ctx, app):
    app.session.set_params({"colour.age_rate": 0.3})
    _dry(ctx, app, 900)


def with_error(ctx, app):
    blocker = Path("/tmp/leafsim_not_a_folder")
    blocker.write_text("a file where the export folder should be")
    _dry(ctx, app, 60)
    ctx.item_input_value("**/export folder", str(blocker))
    ctx.item_click("**/Export frame")
    ctx.yield_(3)
    ctx.mouse_move_to_pos((300, 785))  # hover: the full message as a tooltip
    ctx.yield_(3)
    blocker.unlink()


def photo_compare(ctx, app):
    _dry(ctx, app, 300)
    app.photo_compare = "overlay"
    app.photo_alpha = 0.45
    ctx.yield_(3)


def heat_map(ctx, app):
    _dry(ctx, app, 700)
    app.view = "water"
    ctx.yield_(3)


if __name__ == "__main__":
    shot("gui.png", "maple", default_view)
    shot("gui_error.png", "oak", with_error)
    shot("gui_heatmap.png", "maple", heat_map)
    shot("gui_photo.png", "grapevine", photo_compare)
