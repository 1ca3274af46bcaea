"""The rewritten XPBD kernels (issue 10) against the frozen pre-rewrite kernels
(``tests/_pbd_reference.py``): same inputs → same outputs to round-off, for every projection,
the whole frame (ground, friction, self-contacts with the Verlet skin, un-inversion,
momentum-exact rigid-motion removal) and the helpers the speed-ups introduced."""

from __future__ import annotations

import math

import numpy as np
import pytest

import _pbd_reference as ref
from _reference_dynamics import RefDynamics
from leafsim.bench import build_bench_model, folded_state as _folded
from leafsim.params import ParamSet
from leafsim.sim import effects
from leafsim.sim.effects import Dynamics, projection_order
from leafsim.sim.kernels import pbd as kp

EFFECTS = {e: True for e in ("gravity", "pbd", "bending", "ground", "self_collision", "shrink")}


@pytest.fixture(scope="module")
def tiny():
    return build_bench_model("tiny")


def test_atan2_matches_libm():
    rng = np.random.default_rng(0)
    y, x = rng.normal(size=4000), rng.normal(size=4000)
    y[:8] = [0.0, 0.0, 1.0, -1.0, 1e-300, -1e-12, 3.0, -2.0]
    x[:8] = [1.0, -1.0, 0.0, 0.0, 1.0, -1.0, 3.0, -2.0]
    for scale in (1.0, 1e-6, 1e6):
        got = np.array([kp.atan2_(a * scale, b) for a, b in zip(y, x)])
        want = np.arctan2(y * scale, x)
        assert np.abs(got - want).max() < 1e-15


def test_projection_order_keeps_colours(tiny):
    for idx, cs in ((tiny.spring_ij, tiny.spring_colour_start), (tiny.hinge_idx, tiny.hinge_colour_start),
                    (tiny.vol_idx, tiny.vol_colour_start)):
        perm = projection_order(idx, cs)
        assert sorted(perm) == list(range(len(idx)))
        for a, b in zip(cs[:-1], cs[1:]):
            assert set(perm[a:b]) == set(range(a, b))  # the same constraints in every colour
            key = idx[perm[a:b]].min(axis=1)
            assert (np.diff(key) >= 0).all()


@pytest.mark.parametrize("kind", ["springs", "hinges", "volumes"])
def test_projection_passes_match_reference(tiny, kind):
    """One pass of each kind, new kernel in projection order vs the reference in colour order."""
    m, p = tiny, ParamSet()
    d = Dynamics(m)
    d.configure(p, EFFECTS)
    st = _folded(m)
    st.particle_q[:] += np.random.default_rng(2).normal(0, 0.05 * m.spacing, st.particle_q.shape)
    hidx, hrest, halpha, hlam = d.gather(st)
    q_new, q_ref = st.particle_q.copy(), st.particle_q.copy()
    empty = np.zeros(1, np.int64)
    cs = {"springs": (m.spring_colour_start, empty, empty), "hinges": (empty, m.hinge_colour_start, empty),
          "volumes": (empty, empty, m.vol_colour_start)}[kind]
    halpha_model = np.empty_like(halpha)
    halpha_model[d.hperm] = halpha
    big_ref = ref.iteration_ser(q_ref, d.invm, m.spring_ij, st.spring_rest, d.salpha, np.zeros(m.spring_count), cs[0],
                                m.hinge_idx, st.hinge_rest, halpha_model, np.zeros(m.hinge_count), cs[1], 1.2,
                                m.vol_idx, st.vol_rest, np.zeros(m.vol_count), cs[2], np.zeros(1))
    if kind == "springs":
        big = kp.spring_pass(q_new, d.sij, d.srec, np.zeros(m.spring_count), 0, m.spring_count)
    elif kind == "hinges":
        big = kp.hinge_pass(q_new, d.invm, hidx, hrest, halpha, np.zeros(m.hinge_count), 1.2, 0, m.hinge_count)
    else:
        big = kp.volume_pass(q_new, d.invm, d.vidx, d.vrest, 0, m.vol_count)
    assert np.abs(q_new - st.particle_q).max() > 1e-6 * m.spacing  # the pass did something
    assert np.abs(q_new - q_ref).max() < 1e-12 * m.length
    assert big == pytest.approx(big_ref, rel=1e-9)


@pytest.mark.parametrize("scene", ["ground", "free", "hanging"])
def test_frame_matches_reference(tiny, scene):
    """Whole frames on a folded leaf in self-contact: positions, velocities and the reported
    iterations / contact hits / un-inversions agree with the pre-rewrite kernels."""
    m = tiny
    p = ParamSet({"dynamics.scene": scene, "dynamics.iterations": 3, "dynamics.relaxation": 1.1})
    d = Dynamics(m)
    d.configure(p, EFFECTS)
    r = RefDynamics(m, d, p)
    a, b = _folded(m), _folded(m)
    hits = 0
    for _ in range(3):
        out_ref = r.apply(a).copy()
        d.apply(b)
        assert list(d.out) == list(out_ref)
        assert np.abs(a.particle_q - b.particle_q).max() < 1e-9 * m.length
        assert np.abs(a.particle_qd - b.particle_qd).max() < 1e-6
        hits = max(hits, out_ref[1])
    assert hits > 0  # self-contacts were exercised


def test_contact_skin_skips_searches_at_rest(tiny):
    """A leaf at rest on the ground is searched for contacts once, not every substep."""
    d = Dynamics(tiny)
    d.configure(ParamSet(), EFFECTS)
    st = tiny.state()
    for _ in range(5):
        d.apply(st)
    assert d.contact_searches < d.substeps


def test_contact_list_history_does_not_change_results(tiny, monkeypatch):
    """Contact lists searched at other moments and radii (a resumed run searches afresh; a
    wider skin keeps a larger superset for longer) project the touching pairs in the same
    canonical order: bit-identical frames."""
    m = tiny
    p = ParamSet({"dynamics.iterations": 3})
    runs = []
    for skin in (0.5, 2.0):
        monkeypatch.setattr(effects, "CONTACT_SKIN", skin)
        d = Dynamics(m)
        d.configure(p, EFFECTS)
        st, hits, qs = _folded(m), 0, []
        for f in range(4):
            if skin > 1 and f == 2:
                d.cstate[1] = -1.0  # forget the list as a resumed run does
            d.apply(st)
            hits = max(hits, int(d.out[1]))
            qs.append((st.particle_q.copy(), st.particle_qd.copy()))
        runs.append((qs, hits, d.contact_searches))
    (qa, ha, sa), (qb, hb, sb) = runs
    assert ha > 0 and ha == hb and sa != sb  # contacts exercised, lists searched differently
    for (xa, va), (xb, vb) in zip(qa, qb):
        assert np.array_equal(xa, xb) and np.array_equal(va, vb)


def test_residual_serial(tiny):
    st = tiny.state()
    st.particle_q[0, 2] += 0.01
    want = np.abs(np.linalg.norm(st.particle_q[tiny.spring_ij[:, 0]] - st.particle_q[tiny.spring_ij[:, 1]], axis=1)
                  - st.spring_rest) / st.spring_rest
    assert kp.residual(st.particle_q, tiny.spring_ij, st.spring_rest) == pytest.approx(want.max())
    assert not math.isnan(kp.residual(st.particle_q, tiny.spring_ij[:0], st.spring_rest[:0]))
