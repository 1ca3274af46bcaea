"""The shrink step's rest values against plain numpy formulas, and the osmosis step's stored
factors against scipy's solve: the compiled loops gather the triangles' shrink once and keep the
LU factors without their diagonals (leafsim.sim.effects.shrink / .osmosis)."""

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from leafsim.config.params import ParamSet
from leafsim.sim.effects.osmosis import Osmosis
from leafsim.sim.effects.shrink import Shrink
from leafsim.sim.model import SPRING_LINK


def _dried(model, seed=3):
    st = model.state()
    rng = np.random.default_rng(seed)
    st.particle_water[:] *= rng.uniform(0.2, 1.0, model.particle_count)
    return st


def test_shrink_rest_values_match_their_formulas(tiny):
    """Links, top-surface springs and thickness volumes follow the in-plane shrink of the
    triangle under them (the mean rest / rest⁰ of its three bottom springs)."""
    m = tiny
    sh = Shrink(m)
    sh.configure(ParamSet())
    st = _dried(m)
    sh.apply(st)
    r = st.spring_rest / m.spring_rest0
    nT = sh.nT
    # each V particle's triangle: its three T springs' mean shrink
    tri_f = r[m.vol_springs].mean(axis=1)
    f_of_v = np.empty(m.particle_count)
    f_of_v[m.vol_idx[:, 0]] = tri_f
    np.testing.assert_allclose(st.vol_rest, m.vol_rest0 * tri_f ** 3, rtol=1e-14)
    links = np.flatnonzero(m.spring_type == SPRING_LINK)
    np.testing.assert_allclose(st.spring_rest[links], m.spring_rest0[links] * f_of_v[m.spring_ij[links, 0]], rtol=1e-14)
    assert (m.spring_ij[links, 0] >= nT).all()
    s = m.hinge_spring_V
    f6 = 0.5 * (f_of_v[m.spring_ij[s, 0]] + f_of_v[m.spring_ij[s, 1]])
    d = np.maximum(m.spring_rest0[s] - m.thickness * st.hinge_rest, 0.1 * m.spring_rest0[s])
    np.testing.assert_allclose(st.spring_rest[s], f6 * d, rtol=1e-14)
    assert (tri_f < 1.0).any() and np.isfinite(st.spring_rest).all()


def test_osmosis_factors_solve_the_system(tiny):
    """The stored factors (no diagonal entries, 32-bit indices, U's diagonal apart) solve the
    implicit step's matrix as scipy does."""
    osm = Osmosis(tiny)
    osm.configure(ParamSet())
    Lp, Li, Lx, Up, Ui, Ux, Ud, pr, pc = osm.factors
    n = tiny.particle_count
    assert Li.dtype == np.int32 and Ui.dtype == np.int32 and len(Lp) == len(Up) == n + 1
    rows_L = np.repeat(np.arange(n), np.diff(Lp))
    rows_U = np.repeat(np.arange(n), np.diff(Up))
    assert (Li < rows_L).all() and (Ui > rows_U).all() and (Ud > 0).all()
    st = _dried(tiny)
    w = st.particle_water.copy()
    osm.apply(st)
    rhs = w - osm.loss
    c = spla.spsolve(osm.A.tocsc(), rhs)
    np.testing.assert_allclose(st.particle_water, np.maximum(c, 0.0) * osm.M, rtol=1e-10, atol=1e-18)
    assert not np.array_equal(st.particle_water, w)


@pytest.fixture(scope="module")
def small():
    """The bench's maple-like blade at 0.02 L (3.5 k particles): large enough for a separator
    under 5 % of the unknowns."""
    from leafsim.measure.models import build_bench_model

    return build_bench_model(0.02)


def _split_osmosis(model):
    osm = Osmosis(model)
    osm.configure(ParamSet({"osmosis.solver": "halves"}))
    assert osm.split, "the leaf should cut into two halves and a separator"
    return osm


def test_split_osmosis_factors_keep_the_halves_apart(small):
    """One level of nested dissection: two halves that share no entry in L or U, a separator
    ordered last, and a permutation that visits every particle once."""
    osm = _split_osmosis(small)
    Lp, Li, Lx, Up, Ui, Ux, Ud, perm, bounds, cuts = osm.factors
    n = small.particle_count
    _, b1, b2 = (int(b) for b in bounds)
    assert 0 < b1 < b2 < n and min(b1, b2 - b1) >= n // 4 and n - b2 <= n // 20
    assert np.array_equal(np.sort(perm), np.arange(n))
    part = lambda ix: np.where(ix < b1, 0, np.where(ix < b2, 1, 2))  # noqa: E731
    rL, rU = part(np.repeat(np.arange(n), np.diff(Lp))), part(np.repeat(np.arange(n), np.diff(Up)))
    assert ((part(Li) == rL) | (rL == 2)).all() and ((part(Ui) == rU) | (part(Ui) == 2)).all()
    assert (part(Li)[rL == 0] == 0).all() and (part(Ui)[rU == 2] == 2).all()
    for r in range(n - b2):  # the separator rows' cuts split their columns by half
        cols = Li[Lp[b2 + r]:Lp[b2 + r + 1]]
        k = cuts[:, r] - Lp[b2 + r]
        assert (cols[:k[1]] < b1).all() and ((cols[k[1]:k[2]] >= b1) & (cols[k[1]:k[2]] < b2)).all()
        assert (cols[k[2]:] >= b2).all()


def test_split_osmosis_solves_the_system_on_one_thread_or_two(small):
    """The two-half solve gives scipy's solution, conserves water as the serial one does, and
    returns the same bits on one thread as on two (the thread count is chosen by timing and
    must never change a result)."""
    import numba

    osm = _split_osmosis(small)
    ref = Osmosis(small)
    ref.configure(ParamSet())
    assert not ref.split
    st, st_ref = _dried(small), _dried(small)
    w = st.particle_water.copy()
    most = numba.get_num_threads()
    outs = []
    for k in sorted({1, min(2, most)}):
        s = _dried(small)
        osm.threads.pick = lambda m, k=k: k  # force the count
        for _ in range(5):
            osm.apply(s)
        outs.append(s.particle_water.copy())
        assert numba.get_num_threads() == most  # restored after each solve
    for o in outs[1:]:
        assert np.array_equal(o, outs[0])
    osm.threads.pick = lambda m: 1
    osm.apply(st)
    c = spla.spsolve(osm.A.tocsc(), w - osm.loss)
    np.testing.assert_allclose(st.particle_water, np.maximum(c, 0.0) * osm.M, rtol=1e-10, atol=1e-18)
    for _ in range(5):
        ref.apply(st_ref)
    np.testing.assert_allclose(outs[0], st_ref.particle_water, rtol=1e-12, atol=1e-18)
    lost = w.sum() - outs[0].sum()
    assert lost > 0 and abs(lost - (w.sum() - st_ref.particle_water.sum())) <= 1e-12 * w.sum()


def test_thread_count_follows_the_faster_timing():
    """Two threads are timed three times, then one; the faster count is kept and the other
    tried at growing intervals (16, 32, ... 256 solves) while it loses, and taken at once when
    a try wins; with one thread available nothing is tried."""
    from leafsim.sim.effects.osmosis import _Threads

    t = _Threads()
    assert t.pick(1) == 1

    def drive(t, calls, ms):
        picks = []
        for _ in range(calls):
            k = t.pick(2)
            picks.append(k)
            t.record(k, ms[k])
        return picks

    busy = {1: 0.022, 2: 0.030}  # the other core busy: one thread faster
    quiet = {1: 0.022, 2: 0.012}
    picks = drive(t, 1200, busy)
    assert picks[:6] == [2, 2, 2, 1, 1, 1]
    tries = [i + 1 for i, k in enumerate(picks) if k == 2][3:]  # calls (1-based) that tried two
    gaps = np.diff([7] + tries)  # the 7th call keeps the faster count
    assert list(gaps[:5]) == [16, 32, 64, 128, 256] and (gaps[5:] == 256).all()
    picks = drive(t, 600, quiet)  # the load goes: taken at the next try, then kept
    first = picks.index(2)
    assert first < 256 and picks[first:first + 16] == [2] * 16
    picks = drive(t, 100, busy)  # it comes back: the kept count's own timings show it
    assert picks[-50:].count(2) <= 1


def test_split_osmosis_conserves_water_without_loss(small):
    """No evaporation, water across the thickness: the two-half solve conserves the total to
    round-off over 300 steps and evens out the concentration, as the serial one does."""
    p = ParamSet({"osmosis.solver": "halves", "osmosis.evaporation_top": 0.0, "osmosis.evaporation_bottom": 0.0,
                  "osmosis.diffusion": 1e-2, "osmosis.through_thickness": True})
    osm = Osmosis(small)
    osm.configure(p)
    assert osm.split
    st = small.state()
    st.particle_water[:] *= np.random.default_rng(0).uniform(0.2, 1.8, small.particle_count)
    tot0, c0 = st.particle_water.sum(), (st.particle_water / osm.M).std()
    for _ in range(300):
        osm.apply(st)
        assert st.particle_water.min() >= 0.0
    assert st.particle_water.sum() == pytest.approx(tot0, rel=1e-12)
    assert (st.particle_water / osm.M).std() < 0.5 * c0


def test_split_osmosis_falls_back_where_no_cut_pays(tiny, small):
    """A leaf too small to cut (the tiny blade's separators are over 5 % of its unknowns) gets
    the plain factored solve; a leaf flat along x (every particle at one x) is cut along y
    instead of giving up (the x cut put everything on one side)."""
    from leafsim.sim.effects.osmosis import _dissection

    osm = Osmosis(tiny)
    osm.configure(ParamSet({"osmosis.solver": "halves"}))
    assert not osm.split and len(osm.factors) == 9  # the serial factors
    st = _dried(tiny)
    w = st.particle_water.copy()
    osm.apply(st)
    c = spla.spsolve(osm.A.tocsc(), w - osm.loss)
    np.testing.assert_allclose(st.particle_water, np.maximum(c, 0.0) * osm.M, rtol=1e-10, atol=1e-18)
    ref = Osmosis(small)
    ref.configure(ParamSet())
    xyz = small.particle_rest.copy()
    xyz[:, 0] = 0.0
    cut = _dissection(ref.A, xyz)
    assert cut is not None
    order, bounds = cut
    assert np.array_equal(np.sort(order), np.arange(small.particle_count))
    y_first = xyz[order[:bounds[1]], 1].max()
    assert (xyz[order[bounds[1]:bounds[2]], 1] > y_first).all()  # the halves lie on either side along y


def test_split_osmosis_keeps_its_cut_when_a_live_slider_moves(small):
    """A new diffusion or Δt refactors the matrix in the same order (the cut depends on the
    pattern only: at 132 k its orderings cost 1.5 s a slider move), and the factors solve the new
    matrix; water across the thickness is another pattern, another cut."""
    osm = _split_osmosis(small)
    cut = osm._cuts[True]  # water crosses the thickness by default
    osm.configure(ParamSet({"osmosis.solver": "halves", "osmosis.diffusion": 3e-3}))
    assert osm.split and osm._cuts[True] is cut
    st = _dried(small)
    w = st.particle_water.copy()
    osm.apply(st)
    c = spla.spsolve(osm.A.tocsc(), w - osm.loss)
    np.testing.assert_allclose(st.particle_water, np.maximum(c, 0.0) * osm.M, rtol=1e-10, atol=1e-18)
    osm.configure(ParamSet({"osmosis.solver": "halves", "osmosis.through_thickness": False}))
    assert set(osm._cuts) == {False, True} and osm.split
