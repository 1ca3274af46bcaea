"""The pre-issue-10 ``Dynamics.apply`` driving the frozen reference kernels
(:mod:`helpers.pbd_reference`): the oracle of tests/test_kernels.py and the "before" of
scripts/bench_before_after.py."""

from __future__ import annotations

import numpy as np

from helpers import pbd_reference as ref


class RefDynamics:
    """The pre-rewrite ``Dynamics.apply`` on the reference kernels, settings from the new
    :class:`~leafsim.sim.effects.Dynamics` ``d`` (``par``: the coloured parallel projection)."""

    def __init__(self, m, d, params, par=False):
        self.par = par
        n = m.particle_count
        self.m, self.d = m, d
        self.q_old, self.invm, self.pen = np.zeros((n, 3)), np.zeros(n), np.zeros(n)
        self.change = np.zeros(max(m.spring_count, m.hinge_count, m.vol_count, 1))
        self.slam, self.hlam, self.vlam = np.zeros(m.spring_count), np.zeros(m.hinge_count), np.zeros(m.vol_count)
        self.hgt, self.qa, self.dint = np.zeros(m.vol_count), np.zeros((n, 3)), np.zeros((n, 3))
        self.halpha, self.out = np.zeros(m.hinge_count), np.zeros(3, np.int64)
        self.hgeom = 3.0 * m.hinge_edge_len ** 2 / np.maximum(m.hinge_area, 1e-30)
        self.hrod = params["material.vein_modulus"] * m.hinge_rod
        self.table, self.nxt = np.zeros_like(d.table), np.zeros_like(d.nxt)
        self.pairs = np.zeros((16 * len(d.T_idx) + 16, 2), np.int64)  # room to spare (this reference never grows it)

    def apply(self, st):
        m, d = self.m, self.d
        np.divide(1.0 / d.mscale, m.particle_cytosol + st.particle_water, out=self.invm)
        if d.scene == "hanging":
            self.invm[m.particle_pinned] = 0.0
        ref.hinge_compliance(m.hinge_idx, st.particle_water, m.particle_water0, d.kbend, d.kdry, self.hgeom, self.hrod,
                             1 / (d.h * d.h), self.halpha)
        shrunk = max(float(np.mean(st.spring_rest[d.T_springs] / m.spring_rest0[d.T_springs])), 0.1)
        radius = d.radius * shrunk
        ref.frame(st.particle_q, st.particle_qd, self.q_old, self.invm, d.g, d.h, d.substeps, d.keep, d.iters, d.tol,
                  self.par, m.spring_ij, st.spring_rest, d.salpha, self.slam, m.spring_colour_start,
                  m.hinge_idx, st.hinge_rest, self.halpha, self.hlam, m.hinge_colour_start,
                  m.vol_idx, st.vol_rest, self.vlam, m.vol_colour_start, d.pbd, d.ground, self.pen, self.change, d.mu,
                  d.self_coll, m.particle_rest, d.T_idx, 1.5 * radius, d.skip2, self.table, self.nxt, self.pairs, radius,
                  d.replace, self.hgt, m.thickness * shrunk, d.scene != "hanging", self.qa, self.dint, d.omega, self.out)
        return self.out
