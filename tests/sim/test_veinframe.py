"""The anisotropic bilayer curl: the vein direction field at the hinges, and that a drying blade
bends about axes along its veins when ``shrink.curl_anisotropy`` asks for it."""

import numpy as np
import pytest

from helpers.synthetic import ellipse_shape, synthetic_veins
from leafsim.base.geometry import resample_polyline
from leafsim.blade.build import build_blade
from leafsim.config.params import ParamSet
from leafsim.sim.effects.shrink import Shrink
from leafsim.sim.simulator import Simulator
from leafsim.sim.veinframe import hinge_alignment, vein_field, vein_frame_curl
from leafsim.veins.graph import MAIN, Vein, VeinGraph

SPACING = 0.06


def _veins(shape, direction: str) -> VeinGraph:
    """Straight main veins: one midrib along y, or five parallel veins across the blade (x)."""
    L = shape.length
    step = 0.02 * L
    if direction == "y":
        lines = [((0.0, 0.0), (0.0, 0.97 * L))]
    else:
        half = 0.5 * 0.07  # the ellipse's half width
        lines = []
        for y in np.linspace(0.2, 0.8, 5) * L:
            hw = 0.85 * half * np.sqrt(max(1.0 - (2.0 * y / L - 1.0) ** 2, 0.0))
            lines.append(((-hw, y), (hw, y)))
    veins = []
    for a, b in lines:
        p = resample_polyline(np.array([a, b], float), step)
        veins.append(Vein(order=MAIN, points=p, widths=np.full(len(p), 0.006 * L)))
    return VeinGraph(veins=veins)


def _edges(model):
    xy = model.particle_rest[:, :2]
    e = xy[model.hinge_idx[:, 3]] - xy[model.hinge_idx[:, 2]]
    return e / np.linalg.norm(e, axis=1, keepdims=True)


def test_field_of_one_straight_midrib_is_its_direction_everywhere():
    """One straight vein along y: t = ±(0, 1) and coherence 1 at every point, so a hinge's
    alignment is exactly 2 e_y² − 1 (+1 for an edge along the vein, −1 across it)."""
    s = ellipse_shape()
    m = build_blade(s, _veins(s, "y"), ParamSet({"mesh.spacing": SPACING}), seed=1)
    t, c = vein_field(m, m.particle_rest[:, :2])
    assert np.allclose(np.abs(t[:, 1]), 1.0, atol=1e-9) and np.allclose(c, 1.0, atol=1e-9)
    e = _edges(m)
    assert np.allclose(hinge_alignment(m), 2.0 * e[:, 1] ** 2 - 1.0, atol=1e-9)


def test_field_follows_the_laterals_between_them():
    """With laterals at 40° off the midrib, hinges lying along a lateral chain (its own
    particles) are aligned with the field (s > 0.8 for most), and no value leaves [−1, 1]."""
    s = ellipse_shape()
    m = build_blade(s, synthetic_veins(s), ParamSet({"mesh.spacing": 0.03}), seed=1)
    a = hinge_alignment(m)
    assert a.min() >= -1.0 - 1e-12 and a.max() <= 1.0 + 1e-12
    lateral = set()
    for v in np.flatnonzero(m.vein_order == 1):
        lateral |= set(m.vein_particles[m.vein_start[v]:m.vein_start[v + 1]].tolist())
    on = np.array([int(i) in lateral and int(j) in lateral for i, j in m.hinge_idx[:, 2:]])
    assert on.sum() >= 5
    assert np.median(a[on]) > 0.8


def test_field_converges_under_mesh_refinement():
    """The field is built from the veins resampled at a fixed length of the leaf, so at fixed
    points it does not depend on the mesh: spacings 0.03 and 0.02 L agree with 0.012 L to
    < 2° at the 90th percentile where the veins agree (coherence > 0.3)."""
    s = ellipse_shape()
    v = synthetic_veins(s)
    g = np.stack(np.meshgrid(np.linspace(-0.03, 0.03, 25), np.linspace(0.005, 0.115, 40)), -1).reshape(-1, 2)
    fields = {sp: vein_field(build_blade(s, v, ParamSet({"mesh.spacing": sp}), seed=1), g) for sp in (0.03, 0.02, 0.012)}
    t_ref, c_ref = fields[0.012]
    ok = c_ref > 0.3
    assert ok.mean() > 0.5
    for sp in (0.03, 0.02):
        t, c = fields[sp]
        ang = np.degrees(np.arccos(np.clip(np.abs((t * t_ref).sum(1)), 0.0, 1.0)))
        assert np.percentile(ang[ok], 90) < 2.0 and np.abs(c - c_ref).max() < 0.1, (sp, np.percentile(ang[ok], 90))


def test_shrink_caps_the_scaled_rest_angle():
    """Shrink.apply on a strongly dried blade with β = 0.8: every rest angle stays within
    HINGE_MAX_ANGLE after the vein-frame factor, vein hinges get none, and where no cap acts a
    hinge's angle is (1 + β s) × the isotropic one."""
    from leafsim.sim.effects.shrink import HINGE_MAX_ANGLE

    s = ellipse_shape()
    m = build_blade(s, synthetic_veins(s), ParamSet({"mesh.spacing": 0.03}), seed=1)
    rest = {}
    for beta in (0.0, 0.8):
        p = ParamSet({"mesh.spacing": 0.03, "shrink.curl_anisotropy": beta, "shrink.sigma_surface_top": 0.3,
                      "dynamics.plasticity": 0.0})
        sh = Shrink(m)
        sh.configure(p)
        st = m.state()
        st.particle_water[:] *= np.where(m.particle_layer == 1, 0.8, 0.95)  # the top dried more: curl
        sh.apply(st)
        rest[beta] = st.hinge_rest.copy()
    iso, ani = rest[0.0], rest[0.8]
    assert np.abs(ani).max() <= HINGE_MAX_ANGLE + 1e-12 and np.abs(ani).max() == pytest.approx(HINGE_MAX_ANGLE)
    assert np.all(ani[m.hinge_vein] == 0.0) and np.all(iso[m.hinge_vein] == 0.0)
    free = ~m.hinge_vein & (np.abs(ani) < HINGE_MAX_ANGLE) & (np.abs(iso) < HINGE_MAX_ANGLE) & (np.abs(iso) > 1e-6)
    assert free.sum() > 20
    assert np.allclose(ani[free], iso[free] * (1.0 + 0.8 * hinge_alignment(m)[free]))


def test_curl_factor_scales_the_rest_angles_by_orientation():
    """The Shrink effect multiplies the bilayer rest angle by 1 + β s off the veins (0 on
    them): a hinge along the vein gets (1 + β) / (1 − β) × the rest angle of one across it."""
    s = ellipse_shape()
    m = build_blade(s, _veins(s, "y"), ParamSet({"mesh.spacing": SPACING}), seed=1)
    sh = Shrink(m)
    sh.configure(ParamSet({"mesh.spacing": SPACING, "shrink.curl_anisotropy": 0.5}))
    a = hinge_alignment(m)
    expect = np.where(m.hinge_vein, 0.0, 1.0 + 0.5 * a)
    assert np.allclose(sh.hinge_curl, expect)
    sh.configure(ParamSet({"mesh.spacing": SPACING, "shrink.curl_anisotropy": 0.0}))
    assert np.array_equal(sh.hinge_curl, np.where(m.hinge_vein, 0.0, 1.0))


def _dried_curl(model, beta):
    p = ParamSet({"mesh.spacing": SPACING, "effects.colour": False, "osmosis.evaporation_top": 0.07,
                  "osmosis.evaporation_bottom": 0.0525, "shrink.curl_anisotropy": beta})
    sim = Simulator(model, p)
    st = sim.state()
    for _ in range(900):
        sim.step(st)
    assert np.isfinite(st.particle_q).all()
    assert st.particle_water.sum() < 0.05 * model.particle_water0.sum()
    return vein_frame_curl(model, st.particle_q)


@pytest.mark.parametrize("direction", ["y", "x"])
def test_drying_blade_bends_about_its_veins(direction):
    """The same ellipse dried with its veins along y (a midrib) or across it (five parallel
    veins): with β = 1 the bending runs across the veins whichever way they lie (vein-frame
    curl > 0.3 and above the isotropic blade's by > 0.2), so the roll axis follows the veins,
    not the outline."""
    s = ellipse_shape()
    m = build_blade(s, _veins(s, direction), ParamSet({"mesh.spacing": SPACING}), seed=1)
    iso, aniso = _dried_curl(m, 0.0), _dried_curl(m, 1.0)
    assert aniso > 0.3 and aniso > iso + 0.2, (iso, aniso)
