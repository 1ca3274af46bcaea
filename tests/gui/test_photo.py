"""The photo beside the model is turned as the model is shown (base→apex as on screen)."""

from __future__ import annotations

import numpy as np
import pytest

from leafsim.gui.photo import UV_CORNERS, panel_quad, project, screen_rotation, texcoord_affine, uv_to_model
from leafsim.interactive.session import Session
from leafsim.render.camera import OrbitCamera


def _default_view(model):
    T = model.particle_layer == 0
    xyz = model.particle_rest[T]
    cam = OrbitCamera(yaw=-90.0, pitch=55.0)  # the app's "Frame view"
    cam.frame_bounds(np.stack([xyz.min(0), xyz.max(0)]), margin=1.05)
    rect = (380, 0, 570, 766)
    return xyz, cam.proj(rect[2] / rect[3]) @ cam.view(), rect


@pytest.mark.parametrize("species", ["grapevine", "oak"])
def test_panel_photo_has_the_models_orientation(species):
    s = Session(species, overrides={"mesh.spacing": 0.05})
    m = s.model
    T = m.particle_layer == 0
    xyz, vp, rect = _default_view(m)
    b = m.blade_particles[T]  # the petiole's texture coordinates sit on the midrib, off the map
    A = texcoord_affine(xyz[b, :2], m.particle_texcoord[T][b])
    np.testing.assert_allclose(A @ np.r_[xyz[0, :2], 1.0], m.particle_texcoord[T][0], atol=1e-9)
    base, apex = xyz[np.argmin(xyz[:, 1])], xyz[np.argmax(xyz[:, 1])]
    on_screen = project(np.stack([base, apex]), vp, rect)
    assert on_screen[1, 1] < on_screen[0, 1]  # the model: apex above base
    R = screen_rotation(vp, rect, xyz.mean(0), 0.01)
    quad, k = panel_quad(A, R, (0, 0, 300, 300))
    # where the panel draws the photo's texels of the base and the apex: bilinear in the quad
    def panel_pos(uv):
        u, v = uv
        q = quad
        return (1 - u) * (1 - v) * q[0] + u * (1 - v) * q[1] + u * v * q[2] + (1 - u) * v * q[3]
    uv_base, uv_apex = (A @ np.r_[base[:2], 1.0]), (A @ np.r_[apex[:2], 1.0])
    pb, pa = panel_pos(uv_base), panel_pos(uv_apex)
    assert pa[1] < pb[1] - 0.3 * (quad[:, 1].max() - quad[:, 1].min())  # apex well above base
    # left/right as on screen too (no mirror): the model's +x goes the same way in both
    right = xyz[np.argmax(xyz[:, 0])]
    sx = project(np.stack([xyz.mean(0), right]), vp, rect)
    pr = panel_pos(A @ np.r_[right[:2], 1.0])
    pc = panel_pos(A @ np.r_[xyz.mean(0)[:2], 1.0])
    assert np.sign(pr[0] - pc[0]) == np.sign(sx[1, 0] - sx[0, 0])
    assert quad[:, 0].min() >= -1e-6 and quad[:, 0].max() <= 300 + 1e-6


def test_grapevine_photo_is_stored_base_up():
    """The case that was upside down: grapevine's photo has the petiole at the top."""
    s = Session("grapevine", overrides={"mesh.spacing": 0.05})
    m = s.model
    T = m.blade_T
    xy = m.particle_rest[T][:, :2]
    A = texcoord_affine(xy, m.particle_texcoord[T])
    v_base = (A @ np.r_[xy[np.argmin(xy[:, 1])], 1.0])[1]
    v_apex = (A @ np.r_[xy[np.argmax(xy[:, 1])], 1.0])[1]
    assert v_base < v_apex  # base nearer the image's top row: drawn as stored it is upside down


def test_uv_round_trip():
    A = np.array([[17.0, -0.8, 0.56], [-0.4, -9.4, 0.95]])
    xy = uv_to_model(A, UV_CORNERS)
    np.testing.assert_allclose((np.c_[xy, np.ones(4)] @ A.T), UV_CORNERS, atol=1e-12)


def test_panel_photo_turns_with_a_hanging_leaf():
    """A leaf turned upright (hanging by its stalk, apex down) is shown apex down in the panel
    too: the rotation follows the leaf's own axes, not the rest frame's (it showed the stalk at
    the bottom while the leaf hung stalk up)."""
    from leafsim.gui.photo import leaf_axes
    from leafsim.render.camera import OrbitCamera

    rng = np.random.default_rng(0)
    rest = np.c_[rng.uniform(-0.03, 0.03, 200), rng.uniform(-0.05, 0.05, 200), np.zeros(200)]
    # hanging: the rest y axis (base -> apex) now points down (-z), x stays x
    turn = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
    now = rest @ turn.T + [0.0, 0.0, 0.3]
    ax = leaf_axes(rest, now)
    np.testing.assert_allclose(ax, turn[:, :2], atol=1e-12)
    cam = OrbitCamera(yaw=-90.0, pitch=0.0)  # looking at it from the side, horizontally
    cam.frame_bounds(np.stack([now.min(0), now.max(0)]), margin=1.2)
    rect = (0, 0, 400, 400)
    vp = cam.proj(1.0) @ cam.view()
    R = screen_rotation(vp, rect, now.mean(0), 0.01, ax)
    apex_dir = R @ np.array([0.0, 1.0])  # the photo's base -> apex on the panel (y down)
    assert apex_dir[1] > 0.9  # apex down, as the leaf hangs
