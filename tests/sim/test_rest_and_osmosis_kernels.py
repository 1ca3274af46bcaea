"""The shrink step's rest values against plain numpy formulas, and the osmosis step's stored
factors against scipy's solve: the compiled loops gather the triangles' shrink once and keep the
LU factors without their diagonals (leafsim.sim.effects.shrink / .osmosis)."""

import numpy as np
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
