"""The window's layout at any size: ``Frame view`` fits the whole leaf between the panels, in a
view narrower than tall too (1024 × 768 leaves 264 px between the panels: maple's side lobes were
cut off on both sides); the window is never smaller than its panels; the progress text keeps
its start."""

from types import SimpleNamespace

# hard dependencies (pyproject.toml): a broken install must fail here, not skip the GUI tests
import imgui_bundle  # noqa: F401
import numpy as np
import pytest


@pytest.mark.parametrize("size", [(1280, 800), (1024, 768), (1920, 1080)])
def test_frame_view_fits_the_leaf_in_the_view(size):
    from leafsim.gui.app import LeafApp
    from leafsim.interactive.session import Session

    app = LeafApp(Session("maple", build=False), window_size=size)
    lo, hi = np.array([-0.06, -0.05, 0.0]), np.array([0.06, 0.07, 0.004])  # a maple-sized box [m]
    app.renderer = SimpleNamespace(mesh=object(), lo=lo, hi=hi, center=(lo + hi) / 2)
    app.frame_leaf()
    corners = np.array([[a, b, c, 1.0] for a in (lo[0], hi[0]) for b in (lo[1], hi[1]) for c in (lo[2], hi[2])])
    clip = corners @ app.view_proj().T
    ndc = clip[:, :2] / clip[:, 3:4]
    assert (clip[:, 3] > 0).all() and np.abs(ndc).max() <= 1.0, (size, ndc)
    assert np.abs(ndc).max() > 0.3  # and it is not a speck


def test_window_is_never_smaller_than_its_panels():
    """A window asked for smaller than both panels and a usable view between them opens at the
    smallest size (640 x 400 overlapped the panels; 800 x 600 left a 90 px view)."""
    from leafsim.gui.app import LeafApp
    from leafsim.gui.layout import LEFT_W, MIN_WINDOW, RIGHT_W
    from leafsim.interactive.session import Session

    for size, want in (((640, 400), MIN_WINDOW), ((800, 900), (MIN_WINDOW[0], 900)), ((1280, 800), (1280, 800))):
        app = LeafApp(Session("oak", build=False), window_size=size)
        rp = app.runner_params()
        assert tuple(rp.app_window_params.window_geometry.size) == want
        assert app.window_size == want and want[0] - LEFT_W - RIGHT_W >= 280


def test_progress_text_is_cut_at_its_end():
    """The status bar's progress text keeps its start (the species and stage) and ends in
    '...' when the bar is too narrow (centred, it lost its start)."""
    from leafsim.gui.panels.status_bar import fit_text

    def measure(s):
        return SimpleNamespace(x=7.0 * len(s))

    text = "building aspen_senescent: blade: the coarser mesh that carries the drying (dynamics.path)"
    out = fit_text(text, 210.0, measure)
    assert out.startswith("building aspen_senescent") and out.endswith("...") and measure(out).x <= 210.0
    assert len(fit_text(text, 210.0 + 7.0, measure)) >= len(out)
    assert fit_text("paused  0 sim s / s", 210.0, measure) == "paused  0 sim s / s"


def test_orbiting_keeps_the_eye_above_the_ground():
    """With the ground shown the eye never goes below it (from there the stalk and the veins
    showed through the ground's underside); without it any pitch is allowed."""
    from leafsim.gui.panels.view import keep_above_ground
    from leafsim.render.camera import OrbitCamera

    r = SimpleNamespace(mesh=object(), lo=np.array([-0.05, -0.05, 0.0]), radius=0.07)
    cam = OrbitCamera(yaw=-90.0, pitch=55.0)
    cam.target = np.array([0.0, 0.0, 0.01])
    cam.distance = 0.3
    for _ in range(200):
        cam.drag(0.0, -5.0)  # drag upwards: the eye goes down
        keep_above_ground(cam, r)
    ground = r.lo[2] - 0.004 * r.radius
    assert cam.eye[2] > ground and cam.pitch < 5.0
    free = OrbitCamera(yaw=-90.0, pitch=55.0)
    for _ in range(200):
        free.drag(0.0, -5.0)
    assert free.pitch == -89.0


def test_the_view_caption_keeps_the_water_in_a_small_window():
    """The caption under the 3-D view fits the view: at 1024 x 700 it ran on under the stats
    panel and the water left was hidden. It drops the species name, then the clock; the water
    stays."""
    from leafsim.gui.panels.view import caption

    def measure(s):
        return 7.0 * len(s)

    parts = ("Hornbeam-like", "frame 1685", "t = 3.370 s", "water 41.9 %")
    full = "  ".join(parts)
    assert caption(*parts, measure(full), measure) == full
    assert caption(*parts, measure(full) - 1, measure) == "frame 1685  t = 3.370 s  water 41.9 %"
    assert caption(*parts, 7.0 * 26, measure) == "frame 1685  water 41.9 %"
    assert caption(*parts, 7.0 * 5, measure) == "water 41.9 %"  # (too narrow for anything: the water, clipped)


def test_the_eye_is_kept_above_the_ground_with_the_mouse_over_a_panel():
    """The ground's check runs every frame, not only while the mouse is over the view: switching
    the ground on (a checkbox, the mouse on a panel) with the eye below it showed the leaf through
    the ground's underside until the mouse moved back over the view."""
    from leafsim.gui.panels.view import ViewOverlay
    from leafsim.render.camera import OrbitCamera

    r = SimpleNamespace(mesh=object(), lo=np.array([-0.05, -0.05, 0.0]), radius=0.07)
    cam = OrbitCamera(yaw=-90.0, pitch=-60.0)
    cam.target = np.array([0.0, 0.0, 0.01])
    cam.distance = 0.3
    app = SimpleNamespace(renderer=r, camera=cam, show_ground=True, leaf_rect_px=(0, 0, 800, 600))
    ViewOverlay(app).mouse(SimpleNamespace(want_capture_mouse=True))
    assert cam.eye[2] > r.lo[2] - 0.004 * r.radius and cam.pitch > -60.0
