"""Switchable simulation stages.  Each holds only solver settings and cached matrices and calls
module-level numba kernels with every array passed explicitly.  A disabled stage is never
called (costs nothing) and leaves its part of the State untouched."""

from __future__ import annotations

import math
import time

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from .kernels import osmosis as ko
from .kernels import pbd as kp
from .kernels import shrink as ks
from .model import (
    KIND_VEIN, LAYER_T, LAYER_V, MASS_UNIT, SPRING_LINK, SPRING_SURFACE, SPRING_V, SPRING_VEIN, Model, State,
)

#: below this many particles the serial Gauss–Seidel kernel beats the coloured parallel one
#: (measured by ``leafsim bench``: equal at 5.4 k particles, parallel 1-2 % faster at 83 k on this
#: 2-core box; fork/join per colour dominates on small meshes)
PARALLEL_MIN_PARTICLES = 30000
#: large meshes re-time serial vs parallel projection every this many frames
PROBE_EVERY = 500
#: below this many unknowns the factor-once direct osmosis solve is used (measured: direct 1.2 ms vs
#: PCG 3.2 ms vs pyamg 14 ms at 5.4 k; 20 ms vs 106 ms vs 576 ms at 83 k; factor 0.03 s / 0.55 s)
DIRECT_MAX_UNKNOWNS = 300000
#: bilayer curvature gain κ = gain · Δε / h (prototype measured 1.3; Timoshenko equal layers 1.5)
BILAYER_GAIN = 1.3
#: largest rest angle a bending hinge may ask for [rad]: a curvature the mesh cannot resolve
#: (radius below a few edge lengths) is clamped instead of fighting the stretch constraints
HINGE_MAX_ANGLE = 0.35


class Osmosis:
    """Implicit conservative osmosis + evaporation (SPEC §6), both layers in one block-diagonal
    SPD system (diag(M) + Δt K) cⁿ⁺¹ = M cⁿ − loss, c = w / M."""

    def __init__(self, model: Model):
        self.model = model
        ij = model.spring_ij
        lay = model.spring_layer
        sel = lay < 2  # T–T and V–V springs; no flow through links (per layer, as Jeong)
        i, j = ij[sel, 0], ij[sel, 1]
        l = model.spring_rest0[sel]
        n = model.particle_count
        E = np.bincount(i, l, n) + np.bincount(j, l, n)
        tau = model.particle_tau
        M = model.particle_cytosol
        self.M = M.copy()
        # k_ij such that a uniform mesh diffuses c with D_eff = D · τ̄ (D in m²/s)
        kij = 16.0 * 0.5 * (tau[i] + tau[j]) / (l * (E[i] + E[j]))
        aij = kij * M[i] * M[j] / (M[i] + M[j])
        self.K = sp.coo_matrix((np.r_[-aij, -aij, aij, aij], (np.r_[i, j, i, j], np.r_[j, i, i, j])), shape=(n, n)).tocsr()
        self.K.sum_duplicates()
        self.key = None
        self.loss = np.zeros(n)
        self.rhs = np.zeros(n)
        self.c = np.zeros(n)
        self.last_iterations = 0

    def configure(self, params):
        D = params["osmosis.diffusion"]
        dt = params["dynamics.dt"]
        solver = params["osmosis.solver"]
        if solver == "auto":
            solver = "direct" if self.model.particle_count <= DIRECT_MAX_UNKNOWNS else "cg"
        self.solver = solver
        self.tol = params["osmosis.tolerance"]
        lay = self.model.particle_layer
        self.rate = np.where(lay == LAYER_V, params["osmosis.loss_top"], params["osmosis.loss_bottom"]).astype(float)
        # Evaporation acts per unit of leaf surface, and every particle stands for about the same
        # area, so each particle of a layer loses the same absolute amount: rate × Δt × the
        # layer's mean initial water (Jeong: w − w_loss Δt 1).  Light tissue at the margin and
        # between the veins therefore dries first relative to its content — the pattern that
        # drives margin-first shrinking and colour; diffusion (osmosis) works against it.
        w0 = self.model.particle_water0
        self.loss_ref = np.empty_like(w0, dtype=float)
        for layer in np.unique(lay):
            sel = lay == layer
            self.loss_ref[sel] = w0[sel].mean()
        self.dt = dt
        key = (D, dt, solver)
        if key != self.key:
            A = (sp.diags(self.M) + (dt * D) * self.K).tocsr()
            A.sort_indices()
            self.A = A
            self.diag = A.diagonal().copy()
            # minimum-degree ordering on A + Aᵀ with diagonal pivots (A is SPD): 40 % less fill
            # than COLAMD on these meshes (maple: 115 k vs 184 k nnz), solve 0.42 vs 0.63 ms
            self.lu = (splu(A.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                            options={"SymmetricMode": True}) if solver == "direct" else None)
            if self.lu is not None:  # CSR copies of the factors for the fused numba solve
                L = self.lu.L.tocsr()
                U = self.lu.U.tocsr()
                L.sort_indices()
                U.sort_indices()
                self.factors = (L.indptr.astype(np.int64), L.indices.astype(np.int64), L.data,
                                U.indptr.astype(np.int64), U.indices.astype(np.int64), U.data,
                                self.lu.perm_r.astype(np.int64), self.lu.perm_c.astype(np.int64))
            self.key = key

    def apply(self, state: State):
        m = self.model
        w = state.particle_water
        M = self.M
        if self.solver == "direct":  # rhs, triangular solves and w = max(c, 0) M in one numba call
            ko.direct_step(M, w, self.loss_ref, self.rate, self.dt, *self.factors, self.c, self.rhs, self.loss)
            self.last_iterations = 1
            return
        c = w / M
        ko.loss_rhs(M, c, self.loss_ref, self.rate, self.dt, self.rhs, self.loss)
        if self.solver == "direct":
            cn = self.lu.solve(self.rhs)
            self.last_iterations = 1
        else:
            cn = c - self.loss / M  # warm start: previous concentration minus the drop
            fn = ko.pcg if self.solver == "cg" else ko.jacobi
            self.last_iterations = fn(self.A.indptr, self.A.indices, self.A.data, self.diag, self.rhs, cn, self.tol, 2000)
        np.maximum(cn, 0.0, out=cn)  # round-off guard (M-matrix: exact solution is ≥ 0)
        np.multiply(cn, M, out=w)


class Shrink:
    """Rest lengths from the mass ratio (SPEC §7), σ per spring type and layer; also the
    bilayer rest angles of the hinges and the thickness rest values."""

    def __init__(self, model: Model):
        self.model = model

    def configure(self, params):
        t = self.model.spring_type
        sig = np.empty(len(t))
        sig[t == SPRING_SURFACE] = params["shrink.sigma_surface_bottom"]
        sig[t == SPRING_V] = params["shrink.sigma_surface_top"]
        sig[t == SPRING_VEIN] = params["shrink.sigma_vein"]
        sig[t == SPRING_LINK] = params["shrink.sigma_link"]
        self.sigma = sig
        self.alpha = params["shrink.alpha"]
        self.l_min = params["shrink.l_min"]
        self.bending = params["effects.bending"]

    def apply(self, state: State):
        m = self.model
        fn = ks.shrink_springs_par if m.particle_count >= PARALLEL_MIN_PARTICLES else ks.shrink_springs
        fn(m.spring_ij, m.spring_rest0, self.sigma, self.alpha, self.l_min,
                          m.particle_cytosol, state.particle_water, m.particle_mass0, state.spring_rest)
        ks.vol_targets(m.vol_springs, m.spring_rest0, state.spring_rest, m.vol_rest0, state.vol_rest)


class Dynamics:
    """Gravity, XPBD constraints (distance, bending hinges, thickness), ground contact with
    friction, self-collision, damping and the Voronoi-layer handling (SPEC §8)."""

    def __init__(self, model: Model):
        self.model = model
        n = model.particle_count
        self.q_old = np.zeros((n, 3))
        self.invm = np.zeros(n)
        self.pen = np.zeros(n)
        self.change = np.zeros(max(model.spring_count, model.hinge_count, model.vol_count, 1))
        self.slam = np.zeros(model.spring_count)
        self.hlam = np.zeros(model.hinge_count)
        self.vlam = np.zeros(model.vol_count)
        self.hgt = np.zeros(model.vol_count)
        # hinge stiffness geometry factor 3|e|²/(A1+A2) (discrete shells)
        self.hgeom = 3.0 * model.hinge_edge_len ** 2 / np.maximum(model.hinge_area, 1e-30)
        self.halpha = np.zeros(model.hinge_count)
        # Veins stay straight along their length: a hinge whose two wing vertices are both on a
        # main or lateral vein bends that vein lengthwise, so it gets no bilayer curl target
        # (the blade still rolls across the veins). Without this a long narrow leaf (chestnut)
        # scrolls up from the tip into a lump.
        if model.hinge_count:
            on_vein = (model.particle_kind == KIND_VEIN) & (model.particle_vein_order <= 1)
            wings = model.hinge_idx[:, :2]
            self.hinge_curl = np.where(on_vein[wings[:, 0]] & on_vein[wings[:, 1]], 0.0, 1.0)
        else:
            self.hinge_curl = np.ones(0)
        T = np.flatnonzero(model.particle_layer == LAYER_T)
        self.T_idx = T.astype(np.int64)
        # power of two ≥ 2 × |T| buckets: the contact hash uses a bit mask, not a 64-bit modulo
        self.table = np.zeros(1 << max(2 * len(T) - 1, 1).bit_length(), np.int64)
        self.out = np.zeros(3, np.int64)
        self.nxt = np.zeros(len(T), np.int64)
        self.pairs = np.zeros((8 * len(T) + 16, 2), np.int64)
        self.empty_cs = np.zeros(1, np.int64)
        self.last_iterations = 0
        self.last_contacts = 0
        self.last_uninverted = 0
        self.parallel = n >= PARALLEL_MIN_PARTICLES
        # large meshes: serial and coloured-parallel projection give identical results (no two
        # constraints of one colour share a particle), so the faster one is picked by timing a
        # few frames of each, re-probed every PROBE_EVERY frames (on a shared, loaded box the
        # per-colour fork/joins can cost far more than they save)
        self.adaptive = n >= PARALLEL_MIN_PARTICLES
        self._frames = 0
        self._probe = {True: [], False: []}

    def configure(self, params, effects):
        m = self.model
        dt = params["dynamics.dt"]
        self.dt = dt
        self.substeps = params["dynamics.substeps"]
        self.h = dt / self.substeps
        self.g = -params["dynamics.gravity"] if effects["gravity"] else 0.0
        self.keep = (1.0 - params["dynamics.damping"]) ** (1.0 / self.substeps)
        self.iters = params["dynamics.iterations"]
        self.tol = params["dynamics.tolerance"] * m.length
        a = np.where(m.spring_type == SPRING_VEIN, params["dynamics.compliance_vein"], params["dynamics.compliance_surface"])
        self.salpha = a / (self.h * self.h)
        self.kbend = params["dynamics.bending"]
        self.kdry = params["dynamics.bending_drying"]
        self.plastic_rate = params["dynamics.plasticity"]
        self.replace = params["dynamics.voronoi"] == "replace"
        self.scene = params["dynamics.scene"]
        self.mu = params["dynamics.friction"]
        self.radius = params["dynamics.collision_radius"] * m.spacing
        self.skip2 = (params["dynamics.collision_skip"] * m.spacing) ** 2
        self.pbd = effects["pbd"]
        self.bending = effects["bending"] and m.hinge_count > 0 and self.kbend > 0
        self.ground = effects["ground"] and self.scene == "ground"
        self.self_coll = effects["self_collision"]
        self.shrink_on = effects["shrink"]
        self.sig_top = params["shrink.sigma_surface_top"]
        self.sig_bot = params["shrink.sigma_surface_bottom"]
        self.alpha_shrink = params["shrink.alpha"]
        self.l_min = params["shrink.l_min"]

    def _hinges(self, state):
        m = self.model
        w = state.particle_water
        w0 = m.particle_water0
        kp.hinge_compliance(m.hinge_idx, w, w0, self.kbend, self.kdry, self.hgeom, 1.0 / (self.h * self.h), self.halpha)
        if self.shrink_on:
            ks.hinge_targets(m.hinge_idx, m.hinge_spring_V, m.spring_ij, m.spring_rest0, self.sig_top, self.sig_bot,
                             self.alpha_shrink, self.l_min, m.particle_cytosol, state.particle_water, m.particle_water0,
                             m.particle_mass0, m.thickness, BILAYER_GAIN, min(self.plastic_rate * self.dt, 1.0),
                             state.hinge_plastic, state.hinge_rest)
            np.clip(state.hinge_rest, -HINGE_MAX_ANGLE, HINGE_MAX_ANGLE, out=state.hinge_rest)
            np.multiply(state.hinge_rest, self.hinge_curl, out=state.hinge_rest)

    def apply(self, state: State):
        m = self.model
        np.divide(1.0 / MASS_UNIT, m.particle_cytosol + state.particle_water, out=self.invm)
        if self.scene == "hanging":
            self.invm[m.particle_pinned] = 0.0
        if self.pbd and self.bending:
            self._hinges(state)
        k = self._frames % PROBE_EVERY
        self._frames += 1
        probing = self.adaptive and 1 <= k <= 4
        if probing:
            self.parallel = k % 2 == 1
            t0 = time.perf_counter()
        # the whole frame (all substeps and iterations) in one numba call
        hcs = m.hinge_colour_start if self.bending else self.empty_cs
        out = self.out
        out[:] = 0
        out[1] = self.last_contacts
        out[2] = self.last_uninverted
        kp.frame(state.particle_q, state.particle_qd, self.q_old, self.invm, self.g, self.h, self.substeps,
                 self.keep, self.iters, self.tol, self.parallel,
                 m.spring_ij, state.spring_rest, self.salpha, self.slam, m.spring_colour_start,
                 m.hinge_idx, state.hinge_rest, self.halpha, self.hlam, hcs,
                 m.vol_idx, state.vol_rest, self.vlam, m.vol_colour_start,
                 self.pbd, self.ground, self.pen, self.change, self.mu,
                 self.self_coll, m.particle_rest, self.T_idx, 1.5 * self.radius, self.skip2, self.table, self.nxt,
                 self.pairs, self.radius, self.replace, self.hgt, m.thickness, out)
        self.last_iterations = int(out[0])
        self.last_contacts = int(out[1])
        self.last_uninverted = int(out[2])
        if probing:
            self._probe[self.parallel].append(time.perf_counter() - t0)
            if k == 4:
                self.parallel = min(self._probe[True]) < min(self._probe[False])
                self._probe = {True: [], False: []}

    def _substep(self, state: State) -> int:
        """Reference (Python-driven) version of one substep of :func:`kernels.pbd.frame`."""
        m = self.model
        q, qd = state.particle_q, state.particle_qd
        h = self.h
        kp.predict(q, qd, self.q_old, self.invm, self.g, h)
        if self.replace:
            kp.voronoi_heights(self.q_old, m.vol_idx, self.hgt)
        it = 0
        if self.pbd:
            hidx = m.hinge_idx
            hcs = m.hinge_colour_start if self.bending else self.empty_cs
            self.slam[:] = 0.0
            self.hlam[:] = 0.0
            fn = kp.iteration_par if self.parallel else kp.iteration_ser
            ncont = 0
            if self.self_coll:
                # contact candidates once per substep (search 1.5 × radius), projected inside the
                # iteration loop like every other constraint (outside it they pump energy)
                ncont = kp.find_contacts(q, m.particle_rest, self.T_idx, 1.5 * self.radius, self.skip2,
                                         self.table, self.nxt, self.pairs)
            hits = 0
            while it < self.iters:
                it += 1
                ch = fn(q, self.invm, m.spring_ij, state.spring_rest, self.salpha, self.slam, m.spring_colour_start,
                        hidx, state.hinge_rest, self.halpha, self.hlam, hcs,
                        m.vol_idx, state.vol_rest, self.vlam, m.vol_colour_start, self.ground, self.pen, self.change)
                if ncont:
                    hits = kp.project_contacts(q, self.invm, self.pairs, ncont, self.radius)
                if ch < self.tol and hits == 0:
                    break
            self.last_contacts = hits
        if self.ground:
            low = q[:, 2] < 0
            if low.any():
                self.pen[low] = np.maximum(self.pen[low], -q[low, 2])
                q[low, 2] = 0.0
            kp.ground_friction(q, self.q_old, self.pen, self.mu)
        if self.pbd:
            # no layer inversion: momentum-conserving passes (vertices resting on the ground stay),
            # then a V-only pass for anything neighbours undid
            n_fix = 0
            for _ in range(3):
                k = kp.uninvert(q, self.invm, m.vol_idx, 0.25 * m.thickness, False, self.ground)
                n_fix += k
                if k == 0:
                    break
            if k:
                kp.uninvert(q, self.invm, m.vol_idx, 0.2 * m.thickness, True, self.ground)
            self.last_uninverted = n_fix
            if self.ground:
                np.maximum(q[:, 2], 0.0, out=q[:, 2])
        kp.update_velocity(q, self.q_old, qd, h, self.keep)
        if self.replace:
            kp.voronoi_replace(q, m.vol_idx, self.hgt, 0.25 * m.thickness)
            if self.ground:
                np.maximum(q[:, 2], 0.0, out=q[:, 2])
        return it


class Colour:
    """Pigment aging (SPEC §9): chlorophyll, carotenoids, anthocyanins and browning per
    particle, driven by the season clock and the local relative water.  The pigments live in
    ``State.pigments`` (made by :meth:`init`), so a state snapshot carries its colour."""

    def __init__(self, model: Model):
        self.model = model
        self.w_rel = np.zeros(model.particle_count, np.float32)
        self.inv_w0 = 1.0 / np.maximum(model.particle_water0, 1e-300)

    def configure(self, params):
        self.params = params

    def init(self, state: State, seed: int) -> State:
        """``state`` with summer pigments (aged to the clock's start, ``colour.season``)."""
        from dataclasses import replace

        from .colour import init_pigments

        m = self.model
        state = replace(state, pigments=init_pigments(m.particle_count, self.params, seed=seed,
                                                      rest_relative_mass=m.particle_mass0))
        self.apply(state, 0.0)
        return state

    def apply(self, state: State, dt: float) -> None:
        from .colour import age_at, step_pigments

        np.multiply(state.particle_water, self.inv_w0, out=self.w_rel, casting="unsafe")
        np.clip(self.w_rel, 0.0, 1.0, out=self.w_rel)
        step_pigments(state.pigments, self.w_rel, age_at(state.time, self.params), dt, self.params)
