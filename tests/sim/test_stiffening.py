"""Dry stiffening of stretching (``material.stiffening_stretch``): the dried lamina's membrane
springs stiffen with its bending, the veins' rod share does not; 0 keeps stretching as fresh."""

import numpy as np
import pytest

from helpers.synthetic import ellipse_shape, synthetic_veins
from leafsim.blade.build import build_blade
from leafsim.config.params import ParamSet
from leafsim.sim.kernels.pbd import spring_stiffness
from leafsim.sim.model import SPRING_SURFACE, SPRING_VEIN
from leafsim.sim.simulator import Simulator

BASE = {"mesh.spacing": 0.06, "effects.colour": False, "material.dry_stiffening": 20.0}


def test_spring_stiffness_kernel():
    ij = np.array([[0, 1], [1, 2], [2, 3]])
    w0 = np.array([2.0, 2.0, 2.0, 2.0])
    klam, krod = np.array([1.0, 1.0, 0.0]), np.array([0.0, 5.0, 5.0])
    out = np.zeros(3)
    spring_stiffness(ij, w0.copy(), w0, klam, krod, 20.0, 1.0, out)
    assert np.allclose(out, klam + krod)  # fresh
    spring_stiffness(ij, np.zeros(4), w0, klam, krod, 20.0, 1.0, out)
    assert np.allclose(out, 21.0 * klam + krod)  # dry: the lamina × 21, the rod share as fresh
    spring_stiffness(ij, 0.5 * w0, w0, klam, krod, 20.0, 2.0, out)
    assert np.allclose(out, klam * (1.0 + 20.0 * 0.25) + krod)  # half dry at p = 2


@pytest.fixture(scope="module")
def model():
    s = ellipse_shape()
    return build_blade(s, synthetic_veins(s), ParamSet(BASE), seed=2)


@pytest.mark.parametrize("share", [0.0, 0.5, 1.0])
def test_dried_lamina_springs_stiffen_by_the_share(model, share):
    p = ParamSet({**BASE, "material.stiffening_stretch": share, "dynamics.path": "own"})
    sim = Simulator(model, p)
    dyn = sim._dynamics
    st = sim.state()
    dyn.gather(st)
    fresh = dyn.salpha.copy()
    st.particle_water[:] = 0.0
    dyn.gather(st)
    dried = dyn.salpha.copy()
    lam = (model.spring_type == SPRING_SURFACE) & (model.spring_rod == 0)
    assert lam.sum() > 100
    # compliance ÷ (1 + share · k_dry) on the lamina's springs
    assert np.allclose(fresh[lam] / dried[lam], 1.0 + share * 20.0, rtol=1e-12)
    # every spring: k_lam (1 + share · k_dry) + k_rod over k_lam + k_rod (the rod share as fresh)
    klam, krod = dyn.klam, dyn.krod
    assert np.allclose(fresh / dried, (klam * (1.0 + share * 20.0) + krod) / (klam + krod), rtol=1e-12)
    vein = model.spring_type == SPRING_VEIN
    assert vein.sum() > 10 and (krod[vein] > 0.0).all()  # the veins' springs carry a rod share
    # ... which is not negligible, so a stiffening rod share would show on them
    if share > 0.0:
        assert (fresh[vein] / dried[vein] < 1.0 + share * 20.0 - 0.1).all()
    if share == 0.0:
        assert np.array_equal(fresh, dried)
