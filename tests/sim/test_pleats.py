"""``shrink.plication``: the fresh blade's pleats along its main veins and laterals
(leafsim.sim.pleats, docs/method.md §4).  Off by default; on, every bending hinge's rest angle
gains the dihedral angle of a height field that is zero on the veins and rises in the panels
between them, the same function of position on every mesh, so the blade pleats (valleys on the
veins) by the same amount on a mesh √2 finer."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from leafsim.config.species import get_species
from leafsim.pipeline import build_leaf
from leafsim.sim.curl import wrinkles
from leafsim.sim.effects.shrink import PLEAT_MAX_ANGLE, Shrink
from leafsim.sim.pleats import pleat_angles, pleat_field
from leafsim.sim.run import Run
from leafsim.sim.shape import leaf_frame

DEPTH = 0.012  # hornbeam's


def _model(key: str, spacing: float, **over):
    sp = get_species(key)
    p = sp.params.with_overrides({"mesh.spacing": spacing, "dynamics.path": "own", **over})
    return build_leaf(sp, p, 0).model, p


@pytest.fixture(scope="module")
def hornbeam():
    return _model("hornbeam", 0.0199)


def test_off_by_default_adds_nothing():
    model, p = _model("maple", 0.035)
    assert p["shrink.plication"] == 0.0
    sh = Shrink(model)
    sh.configure(p)
    assert sh.pleat is None


def test_the_field_is_zero_on_the_veins_and_the_stalk_and_rises_in_the_panels(hornbeam):
    model, _ = hornbeam
    u = pleat_field(model)
    T = model.blade_T
    order = model.particle_vein_order
    veins = T & (order >= 0) & (order <= 1)
    assert veins.sum() > 100
    assert np.all(u[veins] == 0.0)
    assert np.all(u[model.particle_petiole] == 0.0)
    assert np.all(u[model.particle_layer != 0] == 0.0)
    panels = T & ~veins
    # −Δu = 1 with u = 0 on the veins: positive inside (the discrete maximum principle holds
    # on a Delaunay mesh; allow a few obtuse corners)
    assert np.mean(u[panels] > 0.0) > 0.99 and u.min() > -1e-3
    assert np.percentile(u[T], 95) == pytest.approx(1.0, rel=1e-9)
    # a sublateral (order 2) is not a fold line: the panels rise across it
    sub = T & (order == 2)
    assert sub.any() and np.median(u[sub]) > 0.2


def test_the_field_is_the_same_function_of_position_on_a_finer_mesh(hornbeam):
    coarse, _ = hornbeam
    fine, _ = _model("hornbeam", 0.0141)
    uc, uf = pleat_field(coarse), pleat_field(fine)
    Tc, Tf = np.flatnonzero(coarse.blade_T), np.flatnonzero(fine.blade_T)
    d, k = cKDTree(coarse.particle_rest[Tc, :2]).query(fine.particle_rest[Tf, :2])
    near = d < 0.1 * coarse.spacing  # the particles both meshes share (veins, outline) and close ones
    assert near.sum() > 300
    a, b = uf[Tf][near], uc[Tc][k[near]]
    panel = (a > 0.05) | (b > 0.05)
    assert np.corrcoef(a[panel], b[panel])[0, 1] > 0.97
    assert np.median(np.abs(a[panel] - b[panel])) < 0.05


def test_the_rest_angles_are_linear_in_the_depth_and_zero_on_vein_hinges(hornbeam):
    model, p = hornbeam
    sh = Shrink(model)
    sh.configure(p.with_overrides({"shrink.plication": DEPTH}))
    unit = pleat_angles(model)
    assert np.array_equal(sh.pleat, np.clip(DEPTH * unit, -PLEAT_MAX_ANGLE, PLEAT_MAX_ANGLE))
    assert np.all(sh.pleat[model.hinge_vein] == 0.0)
    assert np.abs(sh.pleat).max() > 0.05  # pleats, not noise: a few degrees on the fold hinges
    sh.configure(p.with_overrides({"shrink.plication": 1.5 * DEPTH}))
    assert np.allclose(sh.pleat, np.clip(1.5 * DEPTH * unit, -PLEAT_MAX_ANGLE, PLEAT_MAX_ANGLE))
    sh.configure(p)  # the species' own value again (hornbeam's)
    assert (sh.pleat is None) == (p["shrink.plication"] == 0.0)


def test_a_fresh_leaf_asks_for_its_pleats_with_valleys_on_top(hornbeam):
    """At full water the bilayer asks for nothing, so the hinges' rest angles are the pleats;
    the hinges on a lateral's own edges fold it concave towards the top (positive: the
    convention of the bilayer, whose top dries first and lifts the margin)."""
    model, p = hornbeam
    sim_p = p.with_overrides({"shrink.plication": DEPTH})
    sh = Shrink(model)
    sh.configure(sim_p)
    st = model.state()
    sh.apply(st)
    assert np.allclose(st.hinge_rest, sh.pleat, rtol=0.0, atol=1e-9)  # the bilayer: rounding only
    sh.configure(sim_p.with_overrides({"shrink.plication": 0.0}))
    sh.apply(st)
    assert np.abs(st.hinge_rest).max() < 1e-9
    # the hinges whose shared edge runs along a lateral (both ends on it): valleys
    order = model.particle_vein_order
    a, b = model.hinge_idx[:, 2], model.hinge_idx[:, 3]
    on_lateral = (order[a] == 1) & (order[b] == 1)
    assert on_lateral.sum() > 50
    th = DEPTH * pleat_angles(model)[on_lateral]
    assert np.mean(th > 0.0) > 0.8 and np.median(th) > 0.1


def _pleated(spacing: float, depth: float, frames: int = 120):
    """(model, positions in the leaf's frame) of a fresh hornbeam after ``frames`` on the ground."""
    model, p = _model("hornbeam", spacing, **{"shrink.plication": depth})
    run = Run(model, p, seed=0, name="hornbeam")
    for _ in run.frames(until=lambda st: st.frame >= frames):
        pass
    assert np.isfinite(run.state.particle_q).all()
    return model, leaf_frame(model, run.state)


@pytest.mark.slow
def test_the_blade_pleats_with_valleys_on_the_veins_alike_on_two_meshes():
    flat = wrinkles(*_pleated(0.0199, 0.0))["wrinkle_rms_L"]
    rms = {}
    for spacing in (0.0199, 0.0141):
        model, q = _pleated(spacing, DEPTH)
        rms[spacing] = wrinkles(model, q)["wrinkle_rms_L"]
        T = model.blade_T
        u = pleat_field(model)
        # the blade takes the pleats its rest angles ask for: the asked height field's own
        # wrinkle RMS (0.00124 L on both meshes), nearly all of it (0.00117–0.00120 L measured)
        target = model.particle_rest.copy()
        target[:, 2] += DEPTH * model.length * u
        assert rms[spacing] > 0.85 * wrinkles(model, target)["wrinkle_rms_L"]
        order = model.particle_vein_order
        # valleys on the veins: a lateral lies below the middles of the panels beside it
        lat = T & (order == 1)
        mid = T & (u > 0.6)
        tree = cKDTree(model.particle_rest[mid, :2])
        d, k = tree.query(model.particle_rest[lat, :2], k=4)
        z_mid = q[mid, 2][k].mean(1)
        assert np.median(z_mid - q[lat, 2]) > 0.2 * DEPTH * model.length
    assert flat < 0.05 * rms[0.0199]  # the fresh flat blade has none
    assert rms[0.0141] == pytest.approx(rms[0.0199], rel=0.1)  # converged: 0.00117 / 0.00120 L
