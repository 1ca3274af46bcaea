"""Offscreen renders of a real species before and after drying (EGL, pixel assertions)."""

import numpy as np

from leafsim.interactive.session import Session
from leafsim.render.offscreen import OffscreenRenderer, default_camera
from leafsim.render.options import RenderOptions


def test_drying_changes_the_rendered_leaf():
    s = Session("maple", overrides={"mesh.spacing": 0.04, "osmosis.evaporation_top": 0.21, "osmosis.evaporation_bottom": 0.14,
                                    "colour.age_rate": 3.0}, build=True)
    r = OffscreenRenderer(320, 240, samples=0)
    try:
        mesh = s.render_mesh()
        cam = default_camera(mesh.positions)
        before = r.render_array(mesh, camera=cam).astype(float)
        bg = before[2, 2]
        leaf0 = np.abs(before - bg).sum(-1) > 30
        assert 0.05 < leaf0.mean() < 0.8  # the leaf is there and framed
        cy, cx = np.argwhere(leaf0).mean(0)
        assert abs(cx - 160) < 60 and abs(cy - 120) < 60
        g0 = before[leaf0].mean(0)
        assert g0[1] > g0[0] and g0[1] > g0[2]  # young leaf is green
        s.step(400)
        after = r.render_array(s.render_update(), camera=cam).astype(float)
        leaf1 = np.abs(after - bg).sum(-1) > 30
        g1 = after[leaf1].mean(0)
        assert g1[0] - g1[1] > g0[0] - g0[1] + 20  # redder/browner after drying and ageing
        assert (leaf0 != leaf1).mean() > 0.002  # the silhouette moved (shrink/curl)
        views = [r.render_array(None, camera=cam, options=RenderOptions(view=v)) for v in ("particles", "springs", "water")]
        for a in range(3):
            for b in range(a + 1, 3):
                assert np.abs(views[a].astype(int) - views[b]).mean() > 1.0
    finally:
        r.release()


def test_the_default_camera_fills_the_picture():
    """Headless renders frame the leaf tightly for the picture's aspect: the leaf's silhouette
    spans ≥ 80 % of the tighter axis (the bounding-sphere framing left it at 40-50 %), centred,
    and nothing is cut off at the edges."""
    s = Session("oak", overrides={"mesh.spacing": 0.06}, build=True)
    for w, h in ((320, 240), (240, 320)):
        r = OffscreenRenderer(w, h, samples=0)
        try:
            mesh = s.render_mesh()
            img = r.render_array(mesh, camera=default_camera(mesh.positions, aspect=w / h)).astype(float)
        finally:
            r.release()
        leaf = np.abs(img - img[1, 1]).sum(-1) > 30
        ys, xs = np.nonzero(leaf)
        span = max((xs.max() - xs.min() + 1) / w, (ys.max() - ys.min() + 1) / h)
        assert span >= 0.8, (w, h, span)
        assert not (leaf[0].any() or leaf[-1].any() or leaf[:, 0].any() or leaf[:, -1].any())
        assert abs((xs.max() + xs.min()) / 2 - w / 2) < 0.05 * w and abs((ys.max() + ys.min()) / 2 - h / 2) < 0.05 * h


def test_a_frame_is_the_same_picture_whatever_was_drawn_before(tmp_path):
    """``leafsim run --every`` draws a state the same whether it is the writer's first frame
    (populate) or follows others (update): the bounds that frame the shadow map were taken from
    the previous frame's top layer, so a resumed run's or another --every's frame differed in
    ~1300 shadow-edge pixels by up to 21 levels."""
    from leafsim.config.species import get_species
    from leafsim.pipeline import build_leaf
    from leafsim.render.sequence import FrameWriter
    from leafsim.sim.run import Run, Stop

    sp = get_species("oak")
    params = sp.params.with_overrides({"mesh.spacing": 0.04})
    model = build_leaf(sp, params, 0).model
    run = Run(model, params, seed=0)
    first = run.state.copy()
    for _ in run.frames(Stop(frames=60)):
        pass
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    after = FrameWriter(model, params, None, tmp_path / "a", run.sim.state())
    after.write(0, first)
    alone = FrameWriter(model, params, None, tmp_path / "b", run.sim.state())
    assert after.write(60, run.state).read_bytes() == alone.write(60, run.state).read_bytes()
