"""The rewritten XPBD kernels (issue 10) against the frozen pre-rewrite kernels
(``tests/helpers/pbd_reference.py``): same inputs → same outputs to round-off, for every projection,
the whole frame (ground, friction, self-contacts with the Verlet skin, un-inversion,
momentum-exact rigid-motion removal) and the helpers the speed-ups introduced."""

from __future__ import annotations

import math

import numpy as np
import pytest

from helpers import pbd_reference as ref
from helpers.reference_dynamics import RefDynamics
from leafsim.config.params import ParamSet
from leafsim.measure.models import folded_state as _folded
from leafsim.sim.effects import dynamics as effects
from leafsim.sim.effects.dynamics import Dynamics, projection_order
from leafsim.sim.kernels import blocked as kb
from leafsim.sim.kernels import contacts
from leafsim.sim.kernels import pbd as kp

EFFECTS = {e: True for e in ("gravity", "pbd", "bending", "ground", "self_collision", "shrink")}


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
            key = idx[perm[a:b]].max(axis=1)
            assert (np.diff(key) >= 0).all()


@pytest.mark.parametrize("kind", ["springs", "hinges", "volumes"])
def test_projection_passes_match_reference(tiny, kind):
    """One pass of each kind, new kernel in projection order vs the reference in colour order."""
    m, p = tiny, ParamSet()
    d = Dynamics(m)
    d.configure(p, EFFECTS)
    st = _folded(m)
    st.particle_q[:] += np.random.default_rng(2).normal(0, 0.05 * m.spacing, st.particle_q.shape)
    d.gather(st)
    hidx, hrest, halpha = d.hidx, d.hrest, d.halpha
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


@pytest.mark.slow
@pytest.mark.parametrize("scene", ["ground", "free", "hanging"])
def test_frame_matches_reference(tiny, scene):
    """Whole frames on a folded leaf in self-contact: positions, velocities and the reported
    iterations / contact hits / un-inversions agree with the pre-rewrite kernels."""
    m = tiny
    # the reference stops at the scaled substep: the rigid modes' real inertia (kernels.rigid,
    # tested in test_real_inertia.py) is not part of it
    p = ParamSet({"dynamics.scene": scene, "dynamics.iterations": 3, "dynamics.relaxation": 1.1,
                  "dynamics.rigid_inertia": False})
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
    """Contact lists searched and filtered at other moments and radii (a resumed run searches
    afresh; a wider skin keeps a larger superset for longer; a search skin narrower than the
    near list's reach searches every substep) project the touching pairs in the same
    canonical order: bit-identical frames."""
    m = tiny
    p = ParamSet({"dynamics.iterations": 3})
    runs = []
    for skin, near in ((0.5, 0.5), (2.0, 0.25), (3.0, 0.5), (6.0, 2.0)):
        monkeypatch.setattr(effects, "CONTACT_SKIN", skin)
        monkeypatch.setattr(effects, "CONTACT_NEAR_SKIN", near)
        d = Dynamics(m)
        d.configure(p, EFFECTS)
        st, hits, qs = _folded(m), 0, []
        for f in range(4):
            if skin == 2.0 and f == 2:
                d.cstate[1] = -1.0  # forget the list as a resumed run does
            d.apply(st)
            hits = max(hits, int(d.out[1]))
            qs.append((st.particle_q.copy(), st.particle_qd.copy()))
        runs.append((qs, hits, d.contact_searches, int(d.cstate[5])))
    qa, ha = runs[0][:2]
    assert ha > 0  # contacts exercised
    assert len({r[2] for r in runs}) > 1 and len({r[3] for r in runs}) > 1  # searched and filtered differently
    assert runs[0][2] == runs[0][3]  # a search skin inside the near reach: a search every time
    assert runs[2][2] < runs[2][3]  # the wide skin: fewer searches than filterings
    for qb, hb, _, _ in runs[1:]:
        assert hb == ha
        for (xa, va), (xb, vb) in zip(qa, qb):
            assert np.array_equal(xa, xb) and np.array_equal(va, vb)


def test_contact_staleness_ignores_a_common_translation(tiny):
    """A leaf moved as a whole keeps its contact lists; one particle moved against the rest by
    more than the margin does not."""
    d = Dynamics(tiny)
    d.configure(ParamSet(), EFFECTS)
    T = d.T_idx
    q = tiny.state().particle_q.copy()
    qc = q[T].copy()
    limit = 0.1 * tiny.spacing
    assert not contacts.contacts_stale(q + np.array([5.0, -3.0, 2.0]) * limit, T, qc, limit)
    q2 = q.copy()
    q2[T[7]] += [0.0, 0.0, 2.1 * limit]  # its pairs may have closed by 2.1 × limit
    assert contacts.contacts_stale(q2, T, qc, limit)
    q2[T[7]] -= [0.0, 0.0, 0.2 * limit]
    assert not contacts.contacts_stale(q2, T, qc, limit)  # 1.9 × limit against the rest: still within 2 × limit
    assert contacts.contacts_stale(q, T, qc, 0.0)


def test_contact_list_grows_when_a_search_fills_it(tiny, monkeypatch):
    """A search that fills its list is searched again at the near reach (no contact of that
    substep is missed) and the list doubles before the next frame; a list too short even for
    the near pairs makes the frame run again from its start with a longer one.  Either way the
    frames are bit-identical to a run with room to spare."""
    m = tiny
    runs = {}
    grown = []
    real_grow, real_frame = Dynamics._grow_contact_lists, Dynamics._frame
    frames = []

    def grow(self):
        grown.append(len(self.pairs))
        real_grow(self)

    def frame(self, *a):
        frames.append(1)
        return real_frame(self, *a)

    monkeypatch.setattr(Dynamics, "_grow_contact_lists", grow)
    monkeypatch.setattr(Dynamics, "_frame", frame)
    near_max = 0  # set by the roomy run, which comes first
    for cap in ("roomy", "near fits", "nothing fits"):
        d = Dynamics(m)
        d.configure(ParamSet(), EFFECTS)
        if cap != "roomy":
            d.pairs = np.zeros((near_max + 1 if cap == "near fits" else 3, 2), np.int32)
            d.near = np.zeros_like(d.pairs)
        grown.clear()
        frames.clear()
        st, qs, most = _folded(m), [], 0
        for _ in range(8):
            d.apply(st)
            most = max(most, int(d.cstate[4]))
            qs.append((st.particle_q.copy(), st.particle_qd.copy()))
        if cap == "roomy":
            near_max = most  # (sampled at the frames' ends)
            assert int(d.cstate[1]) > 2 * (near_max + 1)  # the wide search needs more room than the near list
            assert not grown
        else:
            assert grown and all(b == 2 * a for a, b in zip(grown, grown[1:]))
            assert len(d.pairs) > int(d.cstate[1])  # room enough now
            # only a list too short for the near pairs runs a frame again
            assert (len(frames) > 8) == (cap == "nothing fits")
        runs[cap] = (qs, int(d.out[1]))
    qa, ha = runs["roomy"]
    assert ha > 0
    for cap in ("near fits", "nothing fits"):
        qb, hb = runs[cap]
        assert hb == ha
        for (xa, va), (xb, vb) in zip(qa, qb):
            assert np.array_equal(xa, xb) and np.array_equal(va, vb)


def test_residual_serial(tiny):
    st = tiny.state()
    st.particle_q[0, 2] += 0.01
    want = np.abs(np.linalg.norm(st.particle_q[tiny.spring_ij[:, 0]] - st.particle_q[tiny.spring_ij[:, 1]], axis=1)
                  - st.spring_rest) / st.spring_rest
    assert kp.residual(st.particle_q, tiny.spring_ij, st.spring_rest) == pytest.approx(want.max())
    assert not math.isnan(kp.residual(st.particle_q, tiny.spring_ij[:0], st.spring_rest[:0]))


def test_block_starts_stay_inside_colours(tiny):
    for cs in (tiny.hinge_colour_start, tiny.vol_colour_start, np.array([0, 0, 5, 5, 70]), np.array([0])):
        b = kb.block_starts(cs, 32)
        assert b[0] == cs[0] and b[-1] == cs[-1]
        assert (np.diff(b) > 0).all() and (np.diff(b) <= 32).all()
        assert set(cs.tolist()) <= set(b.tolist())  # every colour starts a block


def _degenerate_case(m, d, st):
    """A folded, perturbed leaf with some degenerate constraints: collapsed hinge wings and
    edges, flattened tetrahedra and pinned particles (zero inverse mass)."""
    rng = np.random.default_rng(5)
    q = st.particle_q + rng.normal(0, 0.05 * m.spacing, st.particle_q.shape)
    for e in rng.choice(m.hinge_count, 6, replace=False):
        i1, i2, i3, i4 = d.hidx[e]
        q[i1] = q[i3] if e % 2 else q[i4]  # a wing (or with e odd, its edge end) on the edge
    for t in rng.choice(m.vol_count, 4, replace=False):
        iv, ia, ib, ic = d.vidx[t]
        q[ib] = q[ia]
        if t % 2:
            q[ic] = q[ia]  # a triangle collapsed to a point: every gradient zero
    d.invm[rng.choice(m.particle_count, 10, replace=False)] = 0.0
    return q


@pytest.mark.parametrize("omega", [1.0, 1.3])
def test_blocked_kernels_bit_identical_to_one_at_a_time(tiny, omega):
    """The SIMD block kernels do every lane's arithmetic as the one-at-a-time kernels do:
    positions, multipliers and the reported change agree exactly, pass after pass, with
    degenerate hinges and volumes (zero steps through selects) and pinned particles."""
    m = tiny
    d = Dynamics(m)
    d.configure(ParamSet(), EFFECTS)
    st = _folded(m)
    d.gather(st)
    q0 = _degenerate_case(m, d, st)
    kb.pack_hinges(d.hidx, d.invm, d.hrest, d.halpha, d.hrec)  # the pinned particles' new weights
    kb.pack_volumes(d.vidx, d.invm, d.vrest, d.vrec)
    H, V = m.hinge_count, m.vol_count
    qa, qb, la, lb = q0.copy(), q0.copy(), np.zeros(H), np.zeros(H)
    for _ in range(4):
        big_a = kp.hinge_pass(qa, d.invm, d.hidx, d.hrest, d.halpha, la, omega, 0, H)
        big_b = kb.hinges_blocked(qb, d.hidx, d.hrec, lb, omega, d.hblocks, d.blockbuf)
        assert big_a == big_b > 0
        assert np.array_equal(qa, qb) and np.array_equal(la, lb)
    qa, qb = q0.copy(), q0.copy()
    for _ in range(4):
        big_a = kp.volume_pass(qa, d.invm, d.vidx, d.vrest, 0, V)
        big_b = kb.volumes_blocked(qb, d.vidx, d.vrec, d.vblocks, d.blockbuf)
        assert big_a == big_b > 0
        assert np.array_equal(qa, qb)
    assert np.isfinite(qa).all() and np.abs(qa - q0).max() > 0


def test_block_compute_loops_are_vectorised():
    """The point of the blocks: LLVM turns each compute loop into packed (SIMD) arithmetic.
    A branch or a second written array in the loop silently makes it scalar again."""
    import llvmlite.binding as llvm

    feats = llvm.get_host_cpu_features()
    if not feats.get("avx2", False):
        pytest.skip("no AVX2 on this CPU: the vectoriser may judge 2-wide SSE not worth it")
    from numba import njit

    sigs = {kb._hinge_block: "(float64[::1], float64[:, ::1], int64, float64, int64)",
            kb._volume_block: "(float64[::1], float64[:, ::1], int64, int64)"}
    for fn, sig in sigs.items():
        # a fresh compile: a kernel loaded from numba's cache has no assembly to inspect
        opts = {k: v for k, v in fn.targetoptions.items() if k not in ("cache", "nopython")}
        fresh = njit(sig, **opts)(fn.py_func)
        asm = fresh.inspect_asm(fresh.signatures[0])
        assert "sqrtpd" in asm and "divpd" in asm  # packed square roots and divisions



def _uninvert_exact(q, invm, vidx, hmin, vonly, ground, dint):
    """The un-inversion pass as it was before its early skip (plain Python floats: IEEE
    doubles, no contraction, the kernel's FASTMATH arithmetic)."""
    moved = 0
    for iv, ia, ib, ic in vidx.tolist():
        b = [q[ib, k] - q[ia, k] for k in range(3)]
        c = [q[ic, k] - q[ia, k] for k in range(3)]
        n = [b[1] * c[2] - b[2] * c[1], b[2] * c[0] - b[0] * c[2], b[0] * c[1] - b[1] * c[0]]
        nl = math.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
        if nl < 1e-14:
            continue
        n = [x / nl for x in n]
        d = [q[iv, k] - (q[ia, k] + q[ib, k] + q[ic, k]) / 3.0 for k in range(3)]
        h = d[0] * n[0] + d[1] * n[1] + d[2] * n[2]
        if h < hmin:
            w = [0.0 if vonly or (ground and n[2] > 0.0 and q[j, 2] <= 1e-12) else invm[j] for j in (ia, ib, ic)]
            W = invm[iv] + (w[0] + w[1] + w[2]) / 9.0
            if W <= 0.0:
                continue
            dl = (hmin - h) / W
            f = invm[iv] * dl
            for k in range(3):
                q[iv, k] += f * n[k]
                dint[iv, k] += f * n[k]
            for j, wj in zip((ia, ib, ic), w):
                g = -wj * dl / 3.0
                for k in range(3):
                    q[j, k] += g * n[k]
                    dint[j, k] += g * n[k]
            moved += 1
    return moved


def test_uninvert_early_skip_changes_no_bit():
    """The skip without a square root takes exactly the pairs the exact height test skips:
    V particles at heights spread around hmin, down to a few ulps of it, inverted, degenerate
    triangles and pinned particles give the same positions, displacements and count to the bit."""
    rng = np.random.default_rng(3)
    n_pairs, hmin = 600, 5e-5
    q = rng.normal(scale=2e-3, size=(4 * n_pairs, 3))
    vidx = np.arange(4 * n_pairs, dtype=np.int64).reshape(n_pairs, 4)[:, [3, 0, 1, 2]].copy()
    invm = rng.uniform(0.5, 2.0, 4 * n_pairs)
    invm[rng.random(4 * n_pairs) < 0.05] = 0.0
    for t, (iv, ia, ib, ic) in enumerate(vidx):
        a, b, c = q[ia], q[ib], q[ic]
        nrm = np.cross(b - a, c - a)
        nrm /= np.linalg.norm(nrm)
        kind = t % 6
        h = {0: hmin * (1 + rng.uniform(-1e-15, 1e-15)), 1: hmin * (1 + 1e-7 * rng.normal()),
             2: rng.uniform(-3, 3) * hmin, 3: hmin * (1 + 1e-6 * rng.uniform(0.5, 2.0)), 4: rng.uniform(1, 100) * hmin,
             5: -rng.uniform(0, 2) * hmin}[kind]
        q[iv] = (a + b + c) / 3.0 + h * nrm
    q[vidx[::50, 2]] = q[vidx[::50, 1]]  # degenerate triangles
    q[rng.random(len(q)) < 0.1, 2] = 0.0  # on the ground
    for vonly, ground, hm in ((False, True, hmin), (True, False, 0.8 * hmin), (False, False, hmin), (False, True, 0.0)):
        qa, qb = q.copy(), q.copy()
        da, db = np.zeros_like(q), np.zeros_like(q)
        ka = kp.uninvert(qa, invm, vidx, hm, vonly, ground, da)
        kb_ = _uninvert_exact(qb, invm, vidx, hm, vonly, ground, db)
        assert ka == kb_ and ka > 0
        assert np.array_equal(qa, qb) and np.array_equal(da, db)


def _settle_full_passes(q, invm, vidx, thick, ground, dint):
    """The frame's un-inversion as it was: every pass looks at every pair."""
    n_fix, k = 0, 0
    for _ in range(3):
        k = kp.uninvert(q, invm, vidx, 0.25 * thick, False, ground, dint)
        n_fix += k
        if k == 0:
            break
    if k:
        kp.uninvert(q, invm, vidx, 0.2 * thick, True, ground, dint)
    return n_fix


@pytest.mark.parametrize("ground", [False, True])
def test_settle_looking_only_at_moved_pairs_changes_no_bit(tiny, ground):
    """settle's later passes look only at pairs with a particle moved since their last look:
    on a leaf's own pairs (which share particles, so one correction can push a neighbour
    under), with V particles squeezed to and through their triangles, it gives the full passes'
    positions, displacements and count to the bit, and it did need more than one pass."""
    m = tiny
    rng = np.random.default_rng(5)
    st = _folded(m)
    q0 = st.particle_q + rng.normal(0, 0.02 * m.thickness, st.particle_q.shape)
    vidx = m.vol_idx
    a, b, c = q0[vidx[:, 1]], q0[vidx[:, 2]], q0[vidx[:, 3]]
    nrm = np.cross(b - a, c - a)
    nrm /= np.linalg.norm(nrm, axis=1)[:, None]
    u = rng.random(len(vidx))
    squeeze = u < 0.3
    h = rng.uniform(-0.3, 0.3, len(vidx)) * m.thickness
    edge = u > 0.6  # just above the minimum height: a neighbour's correction can push them under
    h[edge] = 0.25 * m.thickness * (1.0 + rng.uniform(0.0, 1e-4, edge.sum()))
    q0[vidx[squeeze | edge, 0]] = ((a + b + c) / 3.0 + h[:, None] * nrm)[squeeze | edge]
    if ground:
        q0[:, 2] -= np.percentile(q0[:, 2], 10)
    invm = np.where(m.particle_pinned, 0.0, 1.0 / m.particle_mass0)
    qa, qb = q0.copy(), q0.copy()
    da, db = np.zeros_like(q0), np.zeros_like(q0)
    out = np.zeros(3, np.int64)
    kp.settle(qa, invm, vidx, m.thickness, ground, da, out, np.empty(len(q0), np.int64))
    want = _settle_full_passes(qb, invm, vidx, m.thickness, ground, db)
    assert out[2] == want and want > squeeze.sum()  # later passes corrected pairs too
    assert np.array_equal(qa, qb) and np.array_equal(da, db)


@pytest.mark.parametrize("vonly,hm", [(False, 1.0), (True, 0.8)])
def test_uninvert_since_looks_at_a_pair_only_if_a_particle_moved_since_its_last_look(vonly, hm):
    """One pass of :func:`uninvert_since` (the momentum-conserving one and settle's last,
    V-only one at a lower height): pairs whose particles were stamped at or after their last
    look (``since`` + t) are treated exactly as :func:`uninvert` treats them, the others are
    left alone even when below the height, and each pair corrected stamps its particles with
    ``now`` + t."""
    rng = np.random.default_rng(8)
    n_pairs, hmin = 300, 5e-5 * hm
    q = rng.normal(scale=2e-3, size=(4 * n_pairs, 3))
    vidx = np.arange(4 * n_pairs, dtype=np.int64).reshape(n_pairs, 4)[:, [3, 0, 1, 2]].copy()
    invm = rng.uniform(0.5, 2.0, 4 * n_pairs)
    for iv, ia, ib, ic in vidx:  # every V particle below the height (each pair on its own particles)
        a, b, c = q[ia], q[ib], q[ic]
        nrm = np.cross(b - a, c - a)
        q[iv] = (a + b + c) / 3.0 + rng.uniform(-1.0, 0.9) * hmin * nrm / np.linalg.norm(nrm)
    m, since, now = n_pairs, 5 * n_pairs, 6 * n_pairs
    stamp = np.full(len(q), -1, np.int64)
    looked = rng.random(n_pairs) < 0.5
    t = np.flatnonzero(looked)
    which = rng.integers(0, 4, len(t))  # one particle of each such pair, moved at or after its last look
    stamp[vidx[t, which]] = since + t + rng.integers(0, m, len(t))
    stamp[vidx[t[::3], which[::3]]] = since + t[::3]  # exactly at its last look (its own correction)
    qa, qb = q.copy(), q.copy()
    da, db = np.zeros_like(q), np.zeros_like(q)
    k = kp.uninvert_since(qa, invm, vidx, hmin, vonly, False, da, stamp, now, since)
    want = kp.uninvert(qb, invm, vidx[looked], hmin, vonly, False, db)
    assert k == want == looked.sum() and np.array_equal(qa, qb) and np.array_equal(da, db)
    assert np.array_equal(stamp[vidx[t]], np.repeat((now + t)[:, None], 4, axis=1))
    untouched = vidx[~looked].ravel()
    assert np.array_equal(qa[untouched], q[untouched]) and (stamp[untouched] == -1).all()
