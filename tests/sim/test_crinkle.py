"""The lamina's compression (leafsim.sim.crinkle): the compression a blade's triangles carry
against their springs' rest lengths, as a tensor over the flat rest plane lumped to particles,
its excess length Δ = ½ tr K, which the renderer draws as a sub-grid crinkle of mean squared
slope uᵀ(2K)u along a direction u (render.crinkle; the pixels are tested in
tests/render/test_renderer.py)."""

import math
from dataclasses import replace

import numpy as np
import pytest

from leafsim.config.species import get_species
from leafsim.pipeline import build_leaf
from leafsim.sim.crinkle import (crinkle_slopes, crinkle_stats, excess_of, lamina_compression, lamina_excess,
                                 one_way_share, principal, triangle_springs)
from leafsim.sim.kernels.crinkle import lamina_compression as kernel
from leafsim.sim.path import transfer_matrix
from leafsim.sim.simulator import Simulator

# 3× the default evaporation, as tests/sim/test_path.py: the hand-over comes within a few hundred frames
FAST = {"osmosis.evaporation_top": 0.042, "osmosis.evaporation_bottom": 0.0315, "effects.colour": False}


def _tensor(q, rest, flat):
    """K (xx, xy, yy) at the three particles of one triangle (0, 1, 2) with rest lengths
    ``rest`` (ab, bc, ca) and flat rest positions ``flat`` (3, 2)."""
    out, scratch = np.empty((3, 3)), np.empty(3)
    kernel(np.array([[0, 1, 2]]), np.array([[0, 1, 2]]), np.asarray(q, np.float64), np.asarray(rest, np.float64),
           np.ascontiguousarray(flat, np.float64), np.zeros(3, bool), out, scratch)
    return out


def _one(q, rest, flat=None):
    """Δ at the three particles of one triangle (0, 1, 2) (flat rest plane: the triangle's rest shape)."""
    flat = np.array([[0.0, 0.0], [rest[0], 0.0], [0.0, 1.0]]) if flat is None else flat
    return excess_of(_tensor(q, rest, flat))


def _rot(a, b):
    ca, sa, cb, sb = math.cos(a), math.sin(a), math.cos(b), math.sin(b)
    return np.array([[ca, -sa, 0], [sa, ca, 0], [0, 0, 1]]) @ np.array([[1, 0, 0], [0, cb, -sb], [0, sb, cb]])


def test_the_excess_of_one_triangle():
    """Half the sum of the two principal compressions, whatever the triangle's placement."""
    tri = np.array([[0.0, 0.0, 0.0], [2e-3, 0.0, 0.0], [0.7e-3, 1.6e-3, 0.0]])
    rest = np.array([np.linalg.norm(tri[1] - tri[0]), np.linalg.norm(tri[2] - tri[1]), np.linalg.norm(tri[0] - tri[2])])
    R = _rot(0.7, 1.1)
    assert np.allclose(_one(tri @ R.T + 0.03, rest), 0.0, atol=1e-12)       # moved and turned rigidly: none
    assert np.allclose(_one(tri * 1.02, rest), 0.0, atol=1e-12)             # stretched: none
    assert np.allclose(_one(tri * 0.97, rest), 0.03, rtol=1e-9)             # squeezed 3 % both ways: 3 %
    squeezed_x = tri * np.array([0.98, 1.0, 1.0])                           # 2 % along x only: 1 %
    assert np.allclose(_one(squeezed_x @ R.T, rest), 0.01, rtol=1e-9)
    sheared = tri * np.array([0.98, 1.03, 1.0])                             # squeezed one way, stretched the other
    assert np.allclose(_one(sheared, rest), 0.01, rtol=1e-9)
    assert np.allclose(_one(tri, np.zeros(3)), 0.0)                         # a degenerate rest triangle carries nothing


def test_the_compression_has_the_directions_of_the_flat_plane():
    """K = Σ max(0, 1 − sₖ) uₖ uₖᵀ with uₖ the compressed material lines in the flat rest plane:
    a squeeze along one material direction shows there, turned as the flat plane is turned, and
    unchanged by a uniform shrink of the rest lengths against the flat plane."""
    tri = np.array([[0.0, 0.0, 0.0], [2e-3, 0.0, 0.0], [0.7e-3, 1.6e-3, 0.0]])
    rest = np.array([np.linalg.norm(tri[1] - tri[0]), np.linalg.norm(tri[2] - tri[1]), np.linalg.norm(tri[0] - tri[2])])
    flat = tri[:, :2]
    R = _rot(0.7, 1.1)
    assert np.allclose(_tensor(tri * np.array([0.98, 1.0, 1.0]) @ R.T, rest, flat), [0.02, 0.0, 0.0], atol=1e-12)
    assert np.allclose(_tensor(tri * np.array([1.0, 0.97, 1.0]), rest, flat), [0.0, 0.0, 0.03], atol=1e-12)
    for deg, xy in ((45.0, 0.01), (-45.0, -0.01)):  # squeezed 2 % along the material line at ±45°
        a = math.radians(deg)
        along = _rot(a, 0.0) @ np.diag([0.98, 1.0, 1.0]) @ _rot(-a, 0.0)
        assert np.allclose(_tensor(tri @ along.T, rest, flat), [0.01, xy, 0.01], atol=1e-12)
    b = math.radians(30.0)  # the flat plane turned by 30°: the tensor turns with it
    turned = flat @ np.array([[math.cos(b), math.sin(b)], [-math.sin(b), math.cos(b)]])
    c, s_ = math.cos(b), math.sin(b)
    assert np.allclose(_tensor(tri * np.array([0.98, 1.0, 1.0]), rest, turned), [0.02 * c * c, 0.02 * c * s_, 0.02 * s_ * s_],
                       atol=1e-12)
    assert np.allclose(_tensor(0.9 * tri * np.array([0.98, 1.0, 1.0]), 0.9 * rest, flat), [0.02, 0.0, 0.0], atol=1e-12)
    # a shrink that was not the same every way (the flat plane is no scaled copy of the rest
    # triangle): K keeps the compressions as its eigenvalues, and an even squeeze stays k I
    skewed = flat * np.array([1.2, 0.9])
    for q, want in ((tri * np.array([0.98, 0.995, 1.0]), (0.02, 0.005)), (tri * np.array([0.97, 0.97, 1.0]), (0.03, 0.03))):
        K = _tensor(q, rest, skewed)[0]
        big, small, _ = principal(K[None])
        assert big[0] == pytest.approx(want[0], rel=1e-9) and small[0] == pytest.approx(want[1], rel=1e-9)
    assert np.allclose(_tensor(tri * np.array([0.97, 0.97, 1.0]), rest, skewed)[0], [0.03, 0.0, 0.03], atol=1e-15)
    mirrored = flat * np.array([1.0, -1.0])  # the flat triangle runs the other way round
    assert np.allclose(_tensor(tri * np.array([0.98, 1.0, 1.0]), rest, mirrored)[0], [0.02, 0.0, 0.0], atol=1e-12)
    # the slope tensor: 2K, so along the squeeze √(2 · 0.02) and nothing along the crests
    S = crinkle_slopes(np.array([[0.01, -0.01, 0.01], [0.02, 0.0, 0.02], [-1e-6, 0.0, 0.01]]), gain=1.0)
    big, small, ang = principal(S)
    assert big[0] == pytest.approx(0.04) and small[0] == pytest.approx(0.0, abs=1e-15)
    assert math.degrees(ang[0]) == pytest.approx(-45.0)
    assert np.allclose(S[1], [0.04, 0.0, 0.04])      # isotropic: √(2Δ) every way
    assert S[2, 0] == pytest.approx(0.0, abs=1e-15) and S[2, 2] == pytest.approx(0.02)  # a prolonged tensor's negative part is clipped
    assert crinkle_slopes(S[:1] * 0.5, gain=2.0)[0] == pytest.approx(2.0 * 4.0 * 0.5 * S[0])
    assert one_way_share(np.array([[0.02, 0.0, 0.0], [0.01, 0.0, 0.01]]), np.array([1.0, 0.0])) == 1.0
    assert one_way_share(np.array([[0.02, 0.0, 0.0], [0.01, 0.0, 0.01]]), np.array([0.0, 1.0])) == 0.0


def test_the_excess_agrees_with_the_singular_values_of_any_deformation():
    """Random rest triangles under random deformations (shear, rotation, out of plane): the
    principal stretches are the singular values of the map from the rest triangle to the
    deformed one."""
    rng = np.random.default_rng(7)
    for _ in range(200):
        tri = np.zeros((3, 3))
        tri[1:, :2] = rng.normal(0.0, 1e-3, (2, 2))
        rest = np.array([np.linalg.norm(tri[1] - tri[0]), np.linalg.norm(tri[2] - tri[1]), np.linalg.norm(tri[0] - tri[2])])
        if rest.min() < 0.2 * rest.max():  # a sliver: the rest triangle's shape is ill-conditioned
            continue
        F = np.eye(3) + rng.normal(0.0, 0.05, (3, 3))
        q = tri @ F.T @ _rot(*rng.uniform(0, 6.3, 2)).T
        E = np.stack([tri[1, :2], tri[2, :2]], 1)  # rest edges (2 × 2)
        D = np.stack([q[1] - q[0], q[2] - q[0]], 1)  # deformed edges (3 × 2)
        s = np.linalg.svd(D @ np.linalg.inv(E), compute_uv=False)
        want = 0.5 * np.maximum(0.0, 1.0 - s).sum()
        assert np.allclose(_one(q, rest), want, rtol=1e-7, atol=1e-12)
        # over the rest triangle itself as the flat plane, K's eigenvalues are the compressions
        # and its directions the right singular vectors
        _, sv, Vt = np.linalg.svd(D @ np.linalg.inv(E))
        K = _tensor(q, rest, tri[:, :2])[0]
        want_K = sum(max(0.0, 1.0 - sk) * np.outer(v, v) for sk, v in zip(sv, Vt))
        assert np.allclose([K[0], K[1], K[2]], [want_K[0, 0], want_K[0, 1], want_K[1, 1]], rtol=1e-6, atol=1e-10)


@pytest.fixture(scope="module")
def maple():
    sp = get_species("maple")
    p = sp.params.with_overrides({**FAST, "dynamics.path": "draft"})
    return p, build_leaf(sp, p, 0).model


def test_a_fresh_leaf_has_none_and_a_swollen_rest_shape_is_all_excess(maple):
    p, m = maple
    st = replace(m.state(), path=None)  # the own mesh carries its mechanics
    d = lamina_excess(m, st)
    assert d.shape == (m.particle_count,) and d.min() >= 0.0 and d.max() < 1e-12  # the rest shape: nothing compressed
    order = m.particle_vein_order
    rods = (order >= 0) & (order <= 1)
    st.spring_rest[:] = 1.02 * m.spring_rest0  # every side 2 % too long for where it is
    d = lamina_excess(m, st)
    lamina = m.blade_T & ~rods
    assert np.allclose(d[lamina], 1.0 - 1.0 / 1.02, rtol=1e-9)  # stretch 1/1.02 both ways
    assert np.all(d[rods | (m.particle_layer != 0)] == 0.0)     # main and lateral veins are rods; layer V has none
    assert np.all(d[~m.blade_particles] == 0.0)                  # nor the stalk
    stats = crinkle_stats(m, st)  # over the lamina, by area
    assert stats["crinkle_excess_pct"] == pytest.approx(100 * (1 - 1 / 1.02), abs=1e-3)  # (rounded)
    assert stats["crinkle_share_above_half_percent"] == 1.0
    assert stats["crinkle_slope_rms_deg"] == pytest.approx(math.degrees(math.sqrt(2 * (1 - 1 / 1.02))), abs=0.01)
    sides = triangle_springs(m)
    ij = np.sort(m.spring_ij[sides.ravel()], 1)
    tri = m.blade_tri_T
    want = np.sort(np.stack([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]], 1).reshape(-1, 2), 1)
    assert np.array_equal(ij, want)


@pytest.mark.parametrize("override", [False, True])
def test_on_the_drying_path_the_excess_is_the_carrier_meshs(maple, override):
    """While the coarse mesh carries the mechanics the own mesh's positions are its prolongation,
    whose fine-scale error is strain of its own: the excess is the coarse mesh's, prolonged (0 on
    the own mesh's main and lateral veins); after the hand-over it is the own mesh's.  The
    carrier is read from the state, so it follows the Simulator also when the Simulator runs
    effects its parameters leave off (``override``: pbd and gravity off in the parameters, on in
    the Simulator's effect list).  It grows as the leaf dries, never negative or NaN."""
    p, m = maple
    if override:
        p = p.with_overrides({"effects.pbd": False, "effects.gravity": False})
        sim = Simulator(m, p, effects=["osmosis", "shrink", "pbd", "gravity", "bending", "ground", "self_collision"])
    else:
        sim = Simulator(m, p)
    st = sim.state()
    P = transfer_matrix(m.path, m)
    order = m.particle_vein_order
    rods = (order >= 0) & (order <= 1)
    cache = {}
    seen, last_path = [], None
    while m.water_fraction(st.particle_water) > 0.1:
        sim.step(st)
        if st.frame % 40:
            continue
        d = lamina_excess(m, st, cache)
        assert np.isfinite(d).all() and d.min() >= 0.0 and np.all(d[rods] == 0.0)
        if sim.on_path:
            coarse = lamina_excess(m.path, st.path)
            want = np.maximum(P @ coarse, 0.0)
            want[rods | (m.particle_layer != 0)] = 0.0
            assert np.allclose(d, want)
            last_path = d
        else:
            assert np.array_equal(d, lamina_excess(m, replace(st, path=None)))
        seen.append((m.water_fraction(st.particle_water), float(np.average(d[m.blade_T], weights=m.particle_area[m.blade_T]))))
        if override and last_path is not None:
            break  # the carrier follows the Simulator's effects: enough
    assert last_path is not None
    if override:
        return
    assert not sim.on_path  # both phases were seen
    w, mean = np.array(seen).T
    assert mean[0] < 0.2 * mean[-1]  # the fresh blade is nearly free of it; the drying makes it
    assert 0.002 < mean[-1] < 0.05   # tenths of a per cent to a few per cent (maple dried: about 1 %)


def test_the_window_draws_the_excess_as_a_heat_map(maple):
    """The view's ``crinkle`` heat-map field is the excess of its layer-T vertices (the GUI's
    "crinkle" view), and a dried-looking blade's heat map spreads over the colour map."""
    from leafsim.appearance.view import LeafView
    from leafsim.gui.layout import HEAT_UNITS, VIEWS
    from leafsim.render.offscreen import OffscreenRenderer, default_camera
    from leafsim.render.options import RenderOptions

    p, m = maple
    st = replace(m.state(), path=None)
    rng = np.random.default_rng(0)
    st.spring_rest[:] = m.spring_rest0 * (1.0 + 0.03 * rng.random(len(m.spring_rest0)))  # patchy excess
    view = LeafView(m)
    fields = view.scalar_fields(st)
    assert np.array_equal(fields["crinkle"], lamina_excess(m, st)[view.T].astype(np.float32))
    assert "crinkle" in VIEWS and "crinkle" in HEAT_UNITS
    r = OffscreenRenderer(200, 160)
    try:
        mesh = view.mesh(st, p)
        img = r.render_array(mesh, default_camera(mesh.positions, aspect=200 / 160), RenderOptions(view="crinkle", ground=False))
    finally:
        r.release()
    leaf = np.abs(img.astype(int) - img[0, 0].astype(int)).sum(-1) > 30
    assert leaf.sum() > 2000 and img[leaf].astype(float).std(axis=0).max() > 20  # a heat map, not one colour
