"""Wilting: a leaf hanging from its petiole droops as its cells lose turgor, then stiffens as it
dries (``material.turgor_share``); without turgor the drying leaf only stiffens."""

import numpy as np
import pytest

from helpers.synthetic import ellipse_shape, synthetic_veins
from leafsim.blade.build import build_blade
from leafsim.config.params import ParamSet
from leafsim.sim.simulator import Simulator

# a lamina of 50 MPa: stiff enough that the turgid leaf holds itself up (apex ≈ 0.3 L below the
# petiole; at the default 10 MPa this synthetic leaf already hangs half down when fresh)
BASE = {"mesh.spacing": 0.05, "dynamics.scene": "hanging", "dynamics.dt": 0.005, "effects.colour": False,
        "material.modulus": 5e7}
WILT = {"material.turgor_share": 0.8, "material.stiffening_power": 3.0}


@pytest.fixture(scope="module")
def model():
    s = ellipse_shape()
    return build_blade(s, synthetic_veins(s), ParamSet(BASE), seed=4)


def _hang_and_dry(model, extra):
    """Apex height / L: of the fresh leaf settled under its weight, at the turgor-loss point
    (RWC first ≤ 0.85), its lowest while drying, and dried."""
    apex = int(np.argmax(model.particle_rest[:, 1]))
    L = model.length
    p = ParamSet({**BASE, **extra})
    st = Simulator(model, p.with_overrides({"effects.osmosis": False})).state()
    settle = Simulator(model, p.with_overrides({"effects.osmosis": False}))
    for _ in range(400):
        settle.step(st)
    fresh = st.particle_q[apex, 2] / L
    sim = Simulator(model, p)
    w0 = model.particle_water0.sum()
    at_tlp, low = None, fresh
    while st.particle_water.sum() > 0.001 * w0:
        sim.step(st)
        z = st.particle_q[apex, 2] / L
        low = min(low, z)
        if at_tlp is None and st.particle_water.sum() <= 0.85 * w0:
            at_tlp = z
        assert np.isfinite(st.particle_q).all()
    for _ in range(200):
        sim.step(st)
    return fresh, at_tlp, low, st.particle_q[apex, 2] / L


def test_hanging_leaf_wilts_then_dries_stiff(model):
    fresh, at_tlp, low, dry = _hang_and_dry(model, WILT)
    assert at_tlp < fresh - 0.03, (fresh, at_tlp)  # droops as turgor goes
    assert low < fresh - 0.1, (fresh, low)         # lowest just past the turgor-loss point
    assert dry > low + 0.3, (low, dry)             # the dried leaf is stiff again (and curled)


def test_without_turgor_the_drying_leaf_does_not_droop(model):
    fresh, at_tlp, low, dry = _hang_and_dry(model, {})
    assert at_tlp > fresh - 0.02, (fresh, at_tlp)
    assert low > fresh - 0.02, (fresh, low)
    plain_at_tlp = at_tlp
    _, wilt_at_tlp, _, _ = _hang_and_dry(model, WILT)
    assert wilt_at_tlp < plain_at_tlp - 0.1
