"""Level of detail (fine mesh following a coarse simulation) and scene placement."""

from __future__ import annotations

import numpy as np
import pytest

from leafsim.config.species import get_species
from leafsim.scene.lod import LevelOfDetail, lod_error
from leafsim.scene.placement import HeightField, _floor, _samples
from leafsim.sim.model import LAYER_T


@pytest.fixture(scope="module")
def lod():
    sp = get_species("oak")
    return LevelOfDetail.build(sp, sp.params, 0, simulate=0.08, show=0.05)


def test_fine_mesh_shows_the_coarse_rest_leaf(lod):
    c, f = lod.coarse, lod.fine
    assert f.particle_count > 1.5 * c.particle_count
    shown = lod.show(c.state())
    T = f.particle_layer == LAYER_T
    d = np.linalg.norm(shown.particle_q[T] - f.particle_rest[T], axis=1)
    assert np.median(d) < 1e-12 and d.max() < 0.02 * f.length  # exact inside, chord error at the margin
    h = shown.particle_q[~T, 2]
    assert np.allclose(h, c.thickness, rtol=0.02)  # layer V at the coarse layer separation
    assert np.allclose(shown.particle_water, f.particle_water0)


def test_rigid_motion_and_bend_are_carried_over(lod):
    c, f = lod.coarse, lod.fine
    st = c.state()
    a = 0.6
    R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])
    st.particle_q[:] = st.particle_q @ R.T + [0.05, -0.02, 0.01]
    shown = lod.show(st)
    expect = f.particle_rest @ R.T + [0.05, -0.02, 0.01]
    interior = np.linalg.norm(lod.show(c.state()).particle_q - f.particle_rest, axis=1) < 1e-12
    assert interior.mean() > 0.8
    assert np.abs(shown.particle_q[interior] - expect[interior]).max() < 1e-12  # barycentric: exact for rigid motion
    # a bend z = k y²: the fine leaf follows it, the probe error against the coarse leaf is small
    st = c.state()
    st.particle_q[:, 2] += 0.4 * st.particle_q[:, 1] ** 2 / c.length
    shown = lod.show(st)
    e = lod_error(lod.shape, f, shown, c, st)
    assert e["position_rms"] < 0.01 and e["d_margin_lift"] < 0.01 and e["lod_margin_lift"] > 0.1


def test_colours_follow_the_coarse_pigments(lod):
    from leafsim.sim.simulator import Simulator

    c = lod.coarse
    sim = Simulator(c, lod.coarse_params.with_overrides({"dynamics.dt": 0.05, "colour.age_rate": 1.0}), effects=["colour"])
    st = sim.state()
    for _ in range(30):
        sim.step(st)
    shown = lod.show(st)
    assert shown.pigments.age == pytest.approx(st.pigments.age)
    assert shown.pigments.chlorophyll.mean() == pytest.approx(st.pigments.chlorophyll[c.particle_layer == LAYER_T].mean(), abs=0.05)
    assert shown.pigments.chlorophyll.mean() < 0.9  # it did age


def _square(n=6, size=0.04, z=0.0):
    x = np.linspace(0, size, n)
    X, Y = np.meshgrid(x, x)
    pos = np.column_stack([X.ravel(), Y.ravel(), np.full(n * n, z)])
    tri = []
    for i in range(n - 1):
        for j in range(n - 1):
            a = i * n + j
            tri += [[a, a + 1, a + n + 1], [a, a + n + 1, a + n]]
    return {"positions": pos, "triangles": np.array(tri), "thickness": np.float64(0.0004)}


def test_floor_leaves_never_interpenetrate():
    """Flat and curled leaves dropped on a small patch: every later leaf's underside is above
    every earlier leaf's top wherever they overlap (cell resolution)."""
    rng = np.random.default_rng(0)
    views = []
    for k in range(12):
        v = _square()
        if k % 2:  # a curled one
            p = v["positions"]
            p[:, 2] = 0.3 * (p[:, 0] - 0.02) ** 2 / 0.04 + rng.uniform(0, 0.002)
        views.append(v)
    layout = {"size": [0.05, 0.05], "cell": 0.002, "clearance": 0.0005}
    placed = _floor(layout, 3, views)
    pts = [_samples(v["positions"] @ R.T + t, v["triangles"], 0.002) for v, (R, t) in zip(views, placed)]
    size = np.asarray(layout["size"])
    reach = max(float(np.ptp(v["positions"][:, :2], 0).max()) for v in views)
    hf = HeightField(-0.5 * size - reach, size + 2 * reach, layout["cell"])  # the raster _floor uses
    per_cell = []
    for p in pts:
        i, j = hf.cells(p)
        lo, hi = np.full(hf.shape, np.inf), np.full(hf.shape, -np.inf)
        np.minimum.at(lo, (i, j), p[:, 2])
        np.maximum.at(hi, (i, j), p[:, 2])
        per_cell.append((lo, hi))
    stacked = 0
    for j in range(len(pts)):
        assert pts[j][:, 2].min() >= -1e-12  # nothing below the ground
        for i in range(j):
            both = np.isfinite(per_cell[i][0]) & np.isfinite(per_cell[j][0])
            if both.any():
                stacked += 1
                gap = per_cell[j][0][both] - (per_cell[i][1][both] + 0.0004)  # underside of j − top of i
                assert gap.min() >= 0.0005 - 1e-12, (i, j, gap.min())
    assert stacked > 10  # the patch is small: leaves really landed on each other
    assert max(t[2] for _, t in placed) > 0.002
