"""The static-equilibrium solver (``dynamics.integrator = static``): its gradient is the
energy's, its Hessian the gradient's derivative (and positive semi-definite where projected),
a solve balances every force to its tolerance (the pin carries the leaf's weight), it finds the
shape a fully converged dynamic solve comes to rest in, it dries a leaf on the ground with
every invariant kept and the same shape for smaller increments, and it refuses a leaf that
cannot rest."""

import numpy as np
import pytest

from helpers.synthetic import ellipse_shape, synthetic_veins
from leafsim.base.errors import LeafsimError
from leafsim.blade.build import build_blade
from leafsim.config.params import ParamSet
from leafsim.sim.kernels import static as kst
from leafsim.sim.kernels.sun import forces
from leafsim.sim.simulator import Simulator

BASE = {"mesh.spacing": 0.05, "effects.colour": False, "dynamics.integrator": "static"}


@pytest.fixture(scope="module")
def model():
    s = ellipse_shape()
    return build_blade(s, synthetic_veins(s), ParamSet(BASE), seed=4)


def _dried(model, water=0.6, frames=1):
    """A simulator and a state whose rest shape has dried to ``water`` (shrink and bilayer
    curl set), positions perturbed off the rest so every term is strained."""
    sim = Simulator(model, ParamSet({**BASE, "effects.osmosis": False}), watchdog=False)
    st = sim.state()
    rng = np.random.default_rng(3)
    st.particle_water[:] = model.particle_water0 * np.clip(water + rng.normal(0, 0.1, model.particle_count), 0.05, 1.0)
    for _ in range(frames):
        sim._shrink.apply(st)
    st.particle_q[:] += rng.normal(0.0, 3e-4 * model.length, st.particle_q.shape)
    eq = sim._dynamics.equilibrium
    return sim, st, eq, eq._records(st)


def test_the_gradient_is_the_energys_and_the_energy_suns(model):
    sim, st, eq, rec = _dried(model)
    q = st.particle_q
    g = np.zeros_like(q)
    E = kst.elastic(q, *rec, eq.smap, eq.hmap, eq.vmap, g, eq.data, False)
    assert E == pytest.approx(kst.elastic_energy(q, *rec), rel=1e-12)
    ij, sk, sr, hidx, hk, hr, vidx, vk, vr = rec
    F = np.zeros_like(q)
    e_sun = forces(q, np.zeros_like(q), ij, sk, sr, np.zeros(len(sk)), hidx, hk, hr, vidx, vk, vr, 0.0, F)
    assert E == pytest.approx(e_sun, rel=1e-12)
    np.testing.assert_allclose(g, -F, rtol=1e-9, atol=1e-12 * np.abs(F).max())
    rng = np.random.default_rng(0)
    for _ in range(3):
        d = rng.normal(0.0, 1.0, q.shape)
        eps = 1e-9
        fd = (kst.elastic_energy(q + eps * d, *rec) - kst.elastic_energy(q - eps * d, *rec)) / (2 * eps)
        assert (g * d).sum() == pytest.approx(fd, rel=1e-5)


def _hessian(eq, q, rec, spd):
    import scipy.sparse as sps

    g = np.zeros_like(q)
    kst.elastic(q, *rec, eq.smap, eq.hmap, eq.vmap, g, eq.data, True, spd)
    n = len(q)
    return sps.bsr_matrix((eq.data.copy(), eq.indices, eq.indptr), shape=(3 * n, 3 * n)).toarray(), g


def test_the_full_hessian_is_the_gradients_derivative_and_the_projected_one_is_psd(model):
    sim, st, eq, rec = _dried(model)
    q = st.particle_q
    H, g = _hessian(eq, q, rec, spd=False)
    assert np.abs(H - H.T).max() <= 1e-6 * np.abs(H).max()
    rng = np.random.default_rng(5)
    for _ in range(3):
        d = rng.normal(0.0, 1.0, q.shape)
        eps = 1e-7 * model.length
        gp = np.zeros_like(q)
        gm = np.zeros_like(q)
        kst.elastic(q + eps * d, *rec, eq.smap, eq.hmap, eq.vmap, gp, eq.data, False)
        kst.elastic(q - eps * d, *rec, eq.smap, eq.hmap, eq.vmap, gm, eq.data, False)
        fd = ((gp - gm) / (2 * eps)).reshape(-1)
        hd = H @ d.reshape(-1)
        assert np.linalg.norm(hd - fd) <= 1e-4 * np.linalg.norm(fd)
    P, _ = _hessian(eq, q, rec, spd=True)
    lam = np.linalg.eigvalsh(0.5 * (P + P.T))
    assert lam.min() >= -1e-9 * lam.max()


def _hanging():
    s = ellipse_shape()
    common = {**BASE, "mesh.spacing": 0.08, "dynamics.scene": "hanging", "material.modulus": 5e7,
              "effects.self_collision": False, "effects.osmosis": False, "effects.shrink": False}
    model = build_blade(s, synthetic_veins(s), ParamSet(common), seed=4)
    sim = Simulator(model, ParamSet(common))
    st = sim.state()
    sim.step(st)
    return model, common, sim, st, int(np.argmax(model.particle_rest[:, 1]))


def test_a_hanging_leaf_is_balanced_and_its_pin_carries_its_weight():
    model, _, sim, st, apex = _hanging()
    eq = sim._dynamics.equilibrium
    assert eq.last.converged and eq.last.residual <= eq.tol
    rec = eq._records(st)
    g = np.zeros_like(st.particle_q)
    kst.elastic(st.particle_q, *rec, eq.smap, eq.hmap, eq.vmap, g, eq.data, False)
    pin = model.particle_pinned
    weight = ((model.particle_cytosol + st.particle_water)[~pin] * 9.81).sum()
    assert g[pin].sum(0)[2] == pytest.approx(weight, rel=1e-3)
    assert np.abs(g[pin].sum(0)[:2]).max() <= 1e-3 * weight
    assert st.particle_q[apex, 2] / model.length < -0.2  # it hangs down


@pytest.mark.slow
def test_a_hanging_leaf_rests_where_a_converged_dynamic_solve_comes_to_rest():
    """XPBD iterated to convergence (200 substeps × 20 iterations) and left to come to rest
    (2000 frames) lands on the static solve's shape: 0.0002 L RMS apart, apex 0.2285 against
    0.2282 L below the pin (measured)."""
    model, common, _, st, apex = _hanging()
    xp = Simulator(model, ParamSet({**common, "dynamics.integrator": "xpbd", "dynamics.substeps": 200,
                                    "dynamics.iterations": 20, "dynamics.tolerance": 1e-9}))
    sx = xp.state()
    for _ in range(2000):
        xp.step(sx)
    assert np.abs(sx.particle_qd).max() < 1e-3  # at rest
    assert sx.particle_q[apex, 2] / model.length == pytest.approx(st.particle_q[apex, 2] / model.length, abs=0.002)
    assert np.sqrt(((sx.particle_q - st.particle_q) ** 2).sum(1).mean()) / model.length < 0.001


def test_drying_on_the_ground_keeps_every_invariant_and_converges_in_the_increment(model):
    """A fast-drying leaf on the ground, solved every 2 and every 8 frames: the solves
    converged, no NaN, water ≥ 0, no
    speed; nothing sinks more than 1.5 % of the thickness; the two increments land within 1 % of L of each other."""
    common = {**BASE, "osmosis.evaporation_top": 10 * ParamSet()["osmosis.evaporation_top"],
              "osmosis.evaporation_bottom": 10 * ParamSet()["osmosis.evaporation_bottom"]}
    ends = {}
    for every in (2, 8):
        sim = Simulator(model, ParamSet({**common, "dynamics.static_every": every}))
        st = sim.state()
        for _ in range(240):
            sim.step(st)
        eq = sim._dynamics.equilibrium
        log = np.array(eq.log)
        assert len(log) == 240 // every
        # the solves converge, but where the leaf buckles off the ground into its curl (a long,
        # curved path) some stop at the iteration cap and the next ones go on from there
        assert (log[:, 3] <= eq.tol).mean() >= 0.85 and log[-10:, 3].max() <= eq.tol, log[:, 3]
        assert np.isfinite(st.particle_q).all() and (st.particle_water >= 0).all()
        assert st.particle_q[:, 2].min() >= -0.015 * model.thickness  # 1.5 δ with the whole weight on one particle
        assert not st.particle_qd.any()
        assert model.water_fraction(st.particle_water) < 0.6  # it dried
        ends[every] = st.particle_q.copy()
    z = ends[8][:, 2].max() / model.length
    assert z > 0.01  # it curled off the ground
    assert np.sqrt(((ends[2] - ends[8]) ** 2).sum(1).mean()) / model.length < 0.01


def test_a_free_leaf_is_refused_with_a_one_line_error(model):
    with pytest.raises(LeafsimError, match="nothing holds up has no equilibrium") as e:
        Simulator(model, ParamSet({**BASE, "dynamics.scene": "free"}))
    assert "\n" not in str(e.value)


def test_ground_and_friction_gradients_and_hessian_are_exact(model):
    """The external terms (gravity, the C² ground, lagged friction in stick and in slip) against
    differences of their energy and gradient."""
    sim, st, eq, rec = _dried(model)
    rng = np.random.default_rng(7)
    q = st.particle_q.copy()
    q[:, 2] = rng.uniform(-2.0, 1.0, len(q)) * eq.dyn.model.thickness * 0.02  # some in the ground, some not
    mass = model.particle_cytosol + st.particle_water
    eq.delta = 0.01 * model.thickness
    eq.kg = np.full(len(q), float((mass * 9.81).sum()) / eq.delta)
    eq.normal = np.where(rng.random(len(q)) < 0.5, rng.uniform(0.0, 1e-4, len(q)), 0.0)
    eq.anchor = q[:, :2] + rng.normal(0.0, 2.0 * eq.eps, (len(q), 2))  # both stick and slip
    E0, g, diag = eq._external(q, mass, True)
    H = eq._hessian_extra(diag, np.zeros((0, 2), np.int64), q, 0.0).toarray()
    for _ in range(3):
        d = rng.normal(0.0, 1.0, q.shape)
        h = 1e-3 * eq.eps
        ep = eq._external(q + h * d, mass, False)[0]
        em = eq._external(q - h * d, mass, False)[0]
        assert (g * d).sum() == pytest.approx((ep - em) / (2 * h), rel=1e-5)
        gp = eq._external(q + h * d, mass, False)[1]
        gm = eq._external(q - h * d, mass, False)[1]
        fd = ((gp - gm) / (2 * h)).reshape(-1)
        assert np.linalg.norm(H @ d.reshape(-1) - fd) <= 1e-4 * np.linalg.norm(fd)
