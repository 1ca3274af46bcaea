"""Real inertia: a leaf falls and swings at its physical speed.

The default scales the inertia × 64 for the drying's convergence (docs/accuracy.md), but
selectively (``dynamics.rigid_inertia``): only the deformation modes.  These tests pin down
that, unscaled and at the default alike, the XPBD loop moves a leaf as a whole exactly as Newton
does: a free fall over 10 cm in √(2 · 0.1 / g), a stiff leaf pinned at one point swinging down
from horizontal in a quarter period of its compound pendulum, a maple swinging from its stalk
in the unscaled leaf's period, a dropped leaf landing in the free-fall time; and that a leaf
drying on the ground is left alone."""

import dataclasses
import math

import numpy as np
import pytest
from scipy.special import ellipk

from helpers.synthetic import ellipse_shape, synthetic_veins
from leafsim.blade.build import build_blade
from leafsim.config.params import ParamSet
from leafsim.sim.simulator import Simulator

REAL = {"mesh.spacing": 0.05, "dynamics.damping": 0.0, "dynamics.air_damping": 0.0, "effects.osmosis": False,
        "effects.shrink": False, "effects.colour": False}
#: no inertia scaling, and the default's (× 64 with the rigid modes at their real inertia)
SCALINGS = pytest.mark.parametrize("scaling", [1.0, 64.0])


@pytest.fixture(scope="module")
def model():
    s = ellipse_shape()
    return build_blade(s, synthetic_veins(s), ParamSet(REAL), seed=4)


def _mass(model, st):
    return model.particle_cytosol + st.particle_water


@SCALINGS
@pytest.mark.parametrize("integrator", ["xpbd", "sun"])
def test_free_fall_over_10_cm_takes_the_physical_time(model, scaling, integrator):
    p = ParamSet({**REAL, "dynamics.scene": "free", "dynamics.mass_scaling": scaling, "dynamics.integrator": integrator})
    sim = Simulator(model, p)
    st = sim.state()
    m = _mass(model, st)
    z0 = float((m * st.particle_q[:, 2]).sum() / m.sum())
    prev_t, prev_drop = 0.0, 0.0
    while True:
        sim.step(st)
        drop = z0 - float((m * st.particle_q[:, 2]).sum() / m.sum())
        if drop >= 0.1:
            break
        prev_t, prev_drop = st.time, drop
    t = prev_t + (st.time - prev_t) * (0.1 - prev_drop) / (drop - prev_drop)
    expect = math.sqrt(2 * 0.1 / p["dynamics.gravity"])
    print(f"free fall: {t:.5f} s against {expect:.5f} s")
    assert t == pytest.approx(expect, rel=0.02)
    # and the inertia scaling without its selective part slows it by √64
    slow = Simulator(model, p.with_overrides({"dynamics.mass_scaling": 64.0, "dynamics.rigid_inertia": False}))
    st = slow.state()
    for _ in range(int(round(expect / p["dynamics.dt"]))):
        slow.step(st)
    drop = z0 - float((m * st.particle_q[:, 2]).sum() / m.sum())
    assert drop == pytest.approx(0.1 / 64, rel=0.05)


@SCALINGS
def test_stiff_leaf_swings_at_its_compound_pendulum_period(model, scaling):
    """Pinned at the base particle, released horizontal: the centre of mass passes below the
    pivot after T/4 = √(I / (m g d)) K(sin 45°) (a rigid pendulum released at 90°)."""
    pivot = int(model.base_particle)
    pinned = np.zeros(model.particle_count, bool)
    pinned[pivot] = True
    m1 = dataclasses.replace(model, particle_pinned=pinned)
    p = ParamSet({**REAL, "dynamics.scene": "hanging", "material.modulus": 2e9, "material.vein_modulus": 5e10,
                  "dynamics.dt": 0.001, "dynamics.mass_scaling": scaling})
    sim = Simulator(m1, p)
    st = sim.state()
    mass = _mass(m1, st)
    r = st.particle_q - st.particle_q[pivot]
    I = float((mass * (r[:, 1] ** 2 + r[:, 2] ** 2)).sum())
    com = (mass[:, None] * r).sum(0) / mass.sum()
    d = math.hypot(com[1], com[2])
    quarter = math.sqrt(I / (mass.sum() * p["dynamics.gravity"] * d)) * ellipk(0.5)  # scipy's K takes m = k²
    prev = None
    while st.time < 3 * quarter:
        sim.step(st)
        r = st.particle_q - st.particle_q[pivot]
        c = (mass[:, None] * r).sum(0) / mass.sum()
        if c[1] <= 0.0:  # the centre of mass is straight below the pivot
            t = prev[0] + (st.time - prev[0]) * prev[1] / (prev[1] - c[1])
            break
        prev = (st.time, c[1])
    else:
        pytest.fail("the leaf never swung below its pivot")
    print(f"pendulum quarter period: {t:.5f} s against {quarter:.5f} s")
    assert t == pytest.approx(quarter, rel=0.02), (t, quarter)
    # it stayed rigid: the centre of mass kept its distance from the pivot
    assert math.hypot(c[1], c[2]) == pytest.approx(d, rel=0.02)


def _swing(params, frames):
    """Maple released with its blade level beside the pinned tip of its stalk: the times its
    centre of mass passes under the pin."""
    from leafsim.config.species import load_library
    from leafsim.pipeline import build_leaf

    sp = load_library()["maple"]
    p = sp.params.with_overrides({"mesh.spacing": 0.04, "dynamics.scene": "hanging", "dynamics.path": "own",
                                  "effects.osmosis": False, "effects.shrink": False, "effects.colour": False, **params})
    m = build_leaf(sp, p, seed=0).model
    sim = Simulator(m, p)
    st = sim.state()
    w = m.particle_cytosol + st.particle_water
    t, y = [], []
    for _ in range(frames):
        sim.step(st)
        q = st.particle_q
        t.append(st.time)
        y.append(float((w @ q[:, 1]) / w.sum() - q[m.particle_pinned, 1].mean()))
    return [t[i] + (t[i + 1] - t[i]) * y[i] / (y[i] - y[i + 1]) for i in range(len(y) - 1) if y[i] * y[i + 1] < 0]


def test_a_maple_swings_from_its_stalk_at_its_physical_period():
    """Flexible stalk and blade, default damping: with the default inertia scaling (× 64, the
    rigid modes at their real inertia) the leaf swings under its pin when the unscaled leaf
    does, and back, within 2 %; scaled as a whole it would still be on its way down."""
    real = _swing({"dynamics.mass_scaling": 1.0}, 400)
    scaled = _swing({}, 400)
    print("unscaled", real, "selective × 64", scaled)
    assert len(real) >= 2 and len(scaled) >= 2
    assert scaled[0] == pytest.approx(real[0], rel=0.02)
    assert scaled[1] - scaled[0] == pytest.approx(real[1] - real[0], rel=0.02)
    slow = _swing({"dynamics.rigid_inertia": False}, int(round(real[0] / 0.002 * 2)))
    assert not slow  # twice the real time to the first pass, and not there yet


def test_a_dropped_leaf_lands_in_the_physical_time(model):
    """Dropped flat from 10 cm onto the ground: it touches down after √(2 · 0.1 / g) (within
    1 %) and comes to rest within a millimetre of where it landed (a dropped leaf used to bounce
    and then float down in slow motion)."""
    # no air (the exact free-fall time), the tissue's own damping (it comes to rest)
    p = ParamSet({**REAL, "dynamics.scene": "ground", "dynamics.damping": 25.0})
    sim = Simulator(model, p)
    st = sim.state()
    st.particle_q[:, 2] += 0.1 - st.particle_q[:, 2].min()
    prev = (0.0, 0.1)
    while st.time < 1.0:
        sim.step(st)
        z = float(st.particle_q[:, 2].min())
        if z <= 1e-4:
            break
        prev = (st.time, z)
    else:
        pytest.fail("the leaf never landed")
    v = math.sqrt(2 * p["dynamics.gravity"] * (0.1 - prev[1]))  # its speed the frame before touching down
    t = prev[0] + prev[1] / v
    expect = math.sqrt(2 * 0.1 / p["dynamics.gravity"])
    print(f"landed after {t:.4f} s against {expect:.4f} s")
    assert t == pytest.approx(expect, rel=0.01)
    landed = st.particle_q.copy()
    for _ in range(100):
        sim.step(st)
        assert float(st.particle_q[:, 2].min()) < 1e-3  # no bounce of a millimetre
    assert np.abs(st.particle_q - landed).max() < 1e-3
    assert np.abs(st.particle_qd).max() < 0.02 * v  # coming to rest (its tissue still rings)


def test_a_leaf_drying_on_the_ground_is_left_alone():
    """While a drying leaf touches the ground its contacts hold its weight: every position of
    every frame is the same with the rigid modes' real inertia on and off (oak's first 300
    frames, curling on the ground before any hop)."""
    from leafsim.config.species import load_library
    from leafsim.pipeline import build_leaf

    sp = load_library()["oak"]
    base = sp.params.with_overrides({"mesh.spacing": 0.06, "osmosis.evaporation_top": 0.042,
                                     "osmosis.evaporation_bottom": 0.0315, "effects.colour": False})
    m = build_leaf(sp, base, seed=0).model
    runs = [Simulator(m, base.with_overrides({"dynamics.rigid_inertia": on})) for on in (True, False)]
    states = [r.state() for r in runs]
    for _ in range(300):
        for r, st in zip(runs, states):
            r.step(st)
        assert np.array_equal(states[0].particle_q, states[1].particle_q)
    assert states[0].particle_q[:, 2].max() > 0.004 * m.length  # it is curling


def test_a_blade_pinned_over_its_base_has_no_rigid_mode_to_amplify(model):
    """Without a stalk the hanging scene pins a patch of the blade at its base: nothing can
    rotate about it, so nothing is amplified and the largest inertia scaling stays stable (the
    patch's stiff reaction, amplified × 4095, blew up by frame 5)."""
    assert model.particle_petiole is None and model.particle_pinned.sum() > 3
    p = ParamSet({**REAL, "dynamics.scene": "hanging", "dynamics.mass_scaling": 4096.0, "dynamics.damping": 25.0})
    sim = Simulator(model, p)
    st = sim.state()
    for _ in range(50):
        sim.step(st)  # the watchdog raises on a blow-up
    assert np.isfinite(st.particle_q).all()
