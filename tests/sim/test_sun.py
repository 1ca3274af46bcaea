"""Sun et al.'s plant dynamics (``dynamics.integrator = sun``): the explicit integrator's forces
are the gradient of the blade's elastic energy, carry no net force or torque, find the same
static equilibrium as a fully converged XPBD solve, stop with a one-line error past their
stability limit, and its turgor force contracts a leaf that lost its turgor in proportion to
the pressure lost."""

import numpy as np
import pytest

from helpers.synthetic import ellipse_shape, synthetic_veins
from leafsim.base.errors import LeafsimError
from leafsim.blade.build import build_blade
from leafsim.config.params import ParamSet
from leafsim.sim.kernels.sun import forces, stiffness_bound
from leafsim.sim.simulator import Simulator

BASE = {"mesh.spacing": 0.05, "dynamics.dt": 0.005, "effects.colour": False, "effects.osmosis": False,
        "effects.shrink": False, "dynamics.integrator": "sun"}


@pytest.fixture(scope="module")
def model():
    s = ellipse_shape()
    return build_blade(s, synthetic_veins(s), ParamSet(BASE), seed=4)


def _elastic(model, params, water=1.0):
    sim = Simulator(model, ParamSet({**BASE, **params}), watchdog=False)
    st = sim.state()
    st.particle_water[:] = water * model.particle_water0
    d = sim._dynamics
    return sim, st, d, d.sun_elastic(st)


def _parts(el):
    ij, sk, sr, tf, hidx, hk, hr, vidx, vk, vr = el
    none = lambda a: a[:0]  # noqa: E731
    return {"springs": (ij, sk, sr, tf * 0, none(hidx), none(hk), none(hr), none(vidx), none(vk), none(vr)),
            "hinges": (none(ij), none(sk), none(sr), none(tf), hidx, hk, hr, none(vidx), none(vk), none(vr)),
            "volumes": (none(ij), none(sk), none(sr), none(tf), none(hidx), none(hk), none(hr), vidx, vk, vr)}


def test_forces_are_minus_the_energy_gradient(model):
    _, st, _, el = _elastic(model, {})
    rng = np.random.default_rng(1)
    q = st.particle_q + rng.normal(0.0, 2e-4 * model.length, st.particle_q.shape)
    v0 = np.zeros_like(q)
    for name, part in _parts(el).items():
        F = np.zeros_like(q)
        forces(q, v0, *part, 0.0, F)
        for _ in range(3):
            d = rng.normal(0.0, 1.0, q.shape)
            eps = 1e-9
            ep = forces(q + eps * d, v0, *part, 0.0, np.zeros_like(q))
            em = forces(q - eps * d, v0, *part, 0.0, np.zeros_like(q))
            fd = (ep - em) / (2 * eps)
            assert -(F * d).sum() == pytest.approx(fd, rel=1e-5), name


def test_internal_forces_carry_no_net_force_or_torque(model):
    _, st, _, el = _elastic(model, {"material.turgor_pressure": 6e5}, water=0.6)  # the turgor force on too
    rng = np.random.default_rng(2)
    q = st.particle_q + rng.normal(0.0, 1e-3 * model.length, st.particle_q.shape)
    v = rng.normal(0.0, 0.01, q.shape)  # and the damping
    F = np.zeros_like(q)
    forces(q, v, *el, 1e-5, F)
    scale = np.abs(F).sum()
    assert np.abs(F.sum(0)).max() < 1e-10 * scale
    assert np.abs(np.cross(q, F).sum(0)).max() < 1e-10 * scale * model.length


def test_stiffness_bound_is_an_upper_bound(model):
    """The Gershgorin bound that sets the step is above the true largest ω² (power iteration
    on M⁻¹K by finite differences of the forces) and not far above it."""
    _, st, d, el = _elastic(model, {})
    ij, sk, _, _, hidx, hk, _, vidx, vk, _ = el
    q = st.particle_q
    bound = stiffness_bound(q, d.invm, ij, sk, hidx, hk, vidx, vk, np.zeros(len(q)))
    v0 = np.zeros_like(q)
    x = np.random.default_rng(3).normal(0.0, 1.0, q.shape)
    lam = 0.0
    for _ in range(300):
        fp, fm = np.zeros_like(q), np.zeros_like(q)
        forces(q + 1e-9 * x, v0, *el, 0.0, fp)
        forces(q - 1e-9 * x, v0, *el, 0.0, fm)
        y = -(fp - fm) / 2e-9 * d.invm[:, None]
        lam = float((x * y).sum() / (x * x).sum())
        x = y / np.linalg.norm(y)
    assert lam < bound < 4.0 * lam, (lam, bound)


def test_a_hanging_leaf_swings_down_as_a_converged_xpbd_solve_moves_it():
    """The same energy, two solvers: Sun's explicit steps and XPBD iterated to convergence
    (200 substeps × 20 iterations) swing a stiff leaf, released flat with its base pinned, down
    along the same path (apex height every 10 frames within 0.4 % of L)."""
    s = ellipse_shape()
    common = {**BASE, "mesh.spacing": 0.08, "dynamics.scene": "hanging", "material.modulus": 5e7,
              "effects.self_collision": False}
    model = build_blade(s, synthetic_veins(s), ParamSet(common), seed=4)
    apex = int(np.argmax(model.particle_rest[:, 1]))
    paths = {}
    for name, over in (("sun", {}), ("xpbd", {"dynamics.integrator": "xpbd", "dynamics.substeps": 200,
                                               "dynamics.iterations": 20, "dynamics.tolerance": 1e-9})):
        sim = Simulator(model, ParamSet({**common, **over}))
        st = sim.state()
        path = []
        for f in range(80):
            sim.step(st)
            if f % 10 == 9:
                path.append(st.particle_q[apex, 2] / model.length)
        paths[name] = np.array(path)
    print(paths)
    assert paths["sun"][-1] < -0.09  # it swings down
    assert np.abs(paths["sun"] - paths["xpbd"]).max() < 0.004


def test_the_step_stays_inside_the_damped_midpoint_rules_stability_region(model):
    """The midpoint rule with Rayleigh damping ζ at the bound is stable up to ω h = Y(ζ) (every
    slower mode, less damped, included); the step count never asks for more, whatever
    dynamics.sun_courant says, and a pinned particle stays put even if it was moving."""
    from leafsim.sim.kernels.sun import stable_courant

    assert stable_courant(0.0) == 0.0
    assert stable_courant(0.3) == pytest.approx(1.645, abs=0.01)
    assert stable_courant(0.5) == pytest.approx(2.0, abs=0.01)
    for zeta in (0.1, 0.3):  # just inside Y: no mode grows; just outside: one does
        Y = stable_courant(zeta)
        for y_top, grows in ((Y, False), (Y + 0.03, True)):
            y = np.linspace(1e-3, 1.0, 2000) * y_top
            zy = zeta * y / y_top
            z = y * (-zy + 1j * np.sqrt(1 - zy * zy))
            assert (np.abs(1 + z + z * z / 2).max() > 1 + 1e-12) == grows
    sim = Simulator(model, ParamSet({**BASE, "dynamics.sun_courant": 2.0, "dynamics.scene": "hanging"}))
    st = sim.state()
    st.particle_qd[:] = 0.05  # a moving leaf, then pinned
    pinned = model.particle_pinned
    assert pinned.any()
    sim.step(st)
    d = sim._dynamics
    assert d.sun_limit == pytest.approx(stable_courant(0.3))
    assert np.array_equal(st.particle_q[pinned], model.particle_rest[pinned])
    assert np.abs(st.particle_qd[pinned]).max() == 0.0


def test_a_state_that_is_not_finite_gives_a_one_line_error(model):
    sim = Simulator(model, ParamSet(BASE), watchdog=False)
    st = sim.state()
    st.particle_q[3, 2] = np.nan
    with pytest.raises(LeafsimError, match=r"dynamics\.integrator = sun") as e:
        sim.step(st)
    assert "\n" not in str(e.value)


def _area_T(model, q):
    t = model.tri_T
    a = np.cross(q[t[:, 1]] - q[t[:, 0]], q[t[:, 2]] - q[t[:, 0]])
    return 0.5 * np.linalg.norm(a, axis=1).sum()


def test_turgor_force_contracts_the_leaf_in_proportion_to_the_pressure_lost(model):
    """A leaf below its turgor-loss point, free and weightless: the cells pull their neighbours
    in with a ΔP (Sun's F_p); the area lost grows linearly with P, at about twice the linear
    strain (2/3) P / E of a spring network whose faces carry the pressure."""
    shrink = {}
    for P in (3e5, 6e5):
        sim = Simulator(model, ParamSet({**BASE, "dynamics.scene": "free", "effects.gravity": False,
                                         "effects.self_collision": False, "dynamics.damping": 200.0,
                                         "material.turgor_pressure": P}), watchdog=False)  # a sudden load
        st = sim.state()
        st.particle_water[:] = 0.6 * model.particle_water0  # below the turgor-loss point (0.85)
        for _ in range(60):
            sim.step(st)
        assert np.isfinite(st.particle_q).all()
        shrink[P] = 1.0 - _area_T(model, st.particle_q) / _area_T(model, model.particle_rest)
    print(shrink)
    assert shrink[6e5] == pytest.approx(2.0 * shrink[3e5], rel=0.1)
    E = ParamSet()["material.modulus"]
    assert 0.5 < shrink[6e5] / (2 * (2 / 3) * 6e5 / E) < 2.0


@pytest.mark.slow
def test_sun_swings_a_maple_from_its_stalk_at_real_speed_like_xpbd():
    """Selective mass scaling in Sun's integrator (the pinned mode: rotations about the stalk's
    tip, driven by gravity's and the stalk's moment): released level, a coarse maple's centre
    of mass drops as XPBD drops it (within 0.01 L over 100 frames, 0.4 L below the pin by
    frame 60); scaled as a whole it has dropped under 0.01 L by then."""
    from leafsim.config.species import load_library
    from leafsim.pipeline import build_leaf

    sp = load_library()["maple"]
    base = {"mesh.spacing": 0.04, "dynamics.scene": "hanging", "dynamics.path": "own", "effects.osmosis": False,
            "effects.shrink": False, "effects.colour": False}
    paths = {}
    for name, over in (("sun", {"dynamics.integrator": "sun"}), ("xpbd", {}),
                       ("xpbd whole", {"dynamics.rigid_inertia": False})):
        p = sp.params.with_overrides({**base, **over})
        m = build_leaf(sp, p, seed=0).model
        sim = Simulator(m, p)
        st = sim.state()
        w = m.particle_cytosol + st.particle_water
        z = []
        for _ in range(100):
            sim.step(st)
            z.append(float(w @ st.particle_q[:, 2] / w.sum() - st.particle_q[m.particle_pinned, 2].mean()) / m.length)
        paths[name] = np.array(z)
    print({k: v[::20].round(3) for k, v in paths.items()})
    assert paths["xpbd"][59] < -0.35 and paths["xpbd whole"][59] > -0.01
    assert np.abs(paths["sun"] - paths["xpbd"]).max() < 0.01
