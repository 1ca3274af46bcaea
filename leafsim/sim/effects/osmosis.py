"""The osmosis effect [Jeong eq. 2.7–2.9, in its conservative symmetric form]: water flows
between neighbours by finite-volume conductances and evaporates per unit area from both
surfaces; one implicit step per call, on a matrix factored once."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from leafsim.sim.environment import Weather
from leafsim.sim.kernels import osmosis as ko
from leafsim.sim.model import (
    LAYER_T,
    LAYER_V,
    Model,
    State,
)

#: below this many unknowns the factor-once direct osmosis solve is used (measured: direct 1.2 ms vs
#: PCG 3.2 ms vs pyamg 14 ms at 5.4 k; 20 ms vs 106 ms vs 576 ms at 83 k; factor 0.03 s / 0.55 s)
DIRECT_MAX_UNKNOWNS = 300000


def _csr_factors(A: sp.csr_matrix) -> tuple:
    """The LU factors of the SPD matrix ``A`` as arrays for the fused numba solve
    (:func:`.kernels.osmosis.direct_step`): minimum-degree ordering on A + Aᵀ with diagonal
    pivots (A is SPD), 40 % less fill than COLAMD on these meshes (maple: 115 k vs 184 k nnz),
    solve 0.42 vs 0.63 ms.  Each factor is kept as CSR rows without their diagonal, with 32-bit
    column indices: the solve reads every entry once per step, and without the per-entry test
    for the diagonal and with 12 instead of 16 bytes an entry it ran 1.15–1.23 × faster on a
    132 k-particle leaf (bit-identical).  L's diagonal is SuperLU's unit one (checked), U's is
    kept apart.  SuperLU's own object is not kept: it held as many bytes again (245 MB for a
    132 k-particle leaf, 1.9 kB a particle)."""
    lu = splu(A.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    perm = (lu.perm_r.astype(np.int64), lu.perm_c.astype(np.int64))
    L = lu.L.tocsr()
    U = lu.U.tocsr()
    del lu
    n = A.shape[0]
    if n >= 2**31:
        raise ValueError(f"osmosis: {n} unknowns do not fit the solve's 32-bit indices")
    out = []
    for F, lower in ((L, True), (U, False)):
        F.sort_indices()
        p, ix = F.indptr.astype(np.int64), F.indices
        dpos = p[1:] - 1 if lower else p[:-1]  # sorted rows: L's diagonal ends a row, U's starts it
        if (np.diff(p) < 1).any() or (ix[dpos] != np.arange(n)).any():
            raise ValueError("osmosis: a factor lacks a diagonal entry")
        keep = np.ones(len(ix), bool)
        keep[dpos] = False
        out.append((p - np.arange(n + 1), ix[keep].astype(np.int32), F.data[keep], F.data[dpos].copy()))
    (Lp, Li, Lx, Ld), (Up, Ui, Ux, Ud) = out
    if (Ld != 1.0).any():
        raise ValueError("osmosis: SuperLU's L factor is not unit lower triangular")
    return Lp, Li, Lx, Up, Ui, Ux, Ud, *perm


def edge_factor(model: Model, beta: float, length: float) -> np.ndarray:
    """(n,) relative evaporation: 1 + β √(ℓ / (d + ℓ)) for a particle at rest distance d from
    the margin (a laminar boundary layer's transfer coefficient falls like x^(−1/2) from the
    edge the air first meets; averaged over wind directions every edge is one), normalised so
    the blade's mean evaporation per area stays the declared E."""
    d = model.particle_margin_distance
    f = 1.0 + beta * np.sqrt(length / (d + length)) if length > 0 else np.ones(len(d))
    A = model.particle_area
    out = np.empty_like(f)
    for layer in (LAYER_T, LAYER_V):
        sel = model.particle_layer == layer
        out[sel] = f[sel] / (np.dot(A[sel], f[sel]) / max(A[sel].sum(), 1e-300))
    return out


def patch_factor(model: Model, amplitude: float) -> np.ndarray:
    """(n,) relative evaporation of patchy hydraulic failure: exp(a · f) for the model's seeded
    patch field f (``Model.particle_patch``, zero mean, unit spread; a = ``osmosis.patchiness``),
    normalised per layer like :func:`edge_factor`; ones when a = 0 or the model has no field."""
    f = model.particle_patch
    if not amplitude or f is None:
        return np.ones(model.particle_count)
    g = np.exp(float(amplitude) * np.asarray(f, float))
    lay, A = model.particle_layer.astype(np.int64), model.particle_area
    mean = np.bincount(lay, A * g, minlength=2) / np.maximum(np.bincount(lay, A, minlength=2), 1e-300)
    return g / mean[lay]


class Osmosis:
    """Implicit conservative osmosis + evaporation (SPEC §6), both layers in one SPD system
    (diag(M) + Δt D K) cⁿ⁺¹ = M cⁿ − loss, c = w / M (water per dry mass).

    K is a finite-volume Laplacian: the conductance between two neighbours of one layer is
    τ̄ × (dry mass per area, harmonic mean) × face / distance, so M dc/dt = D Σ a_ij (c_j − c_i)
    is ∂(ρc)/∂t = ∇·(D τ ρ ∇c) on any mesh (a [kg/m²], D a [kg/s]).  With
    ``osmosis.through_thickness`` the links also carry water between the layers: a third of
    their triangle's area over the distance h/2 of the half-layers' centres, with the
    volumetric density ρ/(h/2): a = τ̄ ρ · 4A/(3h²).  Jeong kept the layers separate."""

    def __init__(self, model: Model):
        self.model = model
        n = model.particle_count
        self.M = model.particle_cytosol.copy()
        self.K_plane = self._conductance(model, model.spring_layer < 2)
        self.K_link = self._conductance(model, model.spring_layer == 2)
        self.key = None
        self.loss = np.zeros(n)
        self.rhs = np.zeros(n)
        self.c = np.zeros(n)
        self.last_iterations = 0

    @staticmethod
    def _conductance(model: Model, sel: np.ndarray):
        ij = model.spring_ij[sel]
        i, j = ij[:, 0], ij[:, 1]
        n = model.particle_count
        tau, M = model.particle_tau, model.particle_cytosol
        rho = M / np.maximum(model.particle_area, 1e-300)
        hm = 2.0 * rho[i] * rho[j] / np.maximum(rho[i] + rho[j], 1e-300)
        lay = model.particle_layer
        # in-plane springs: face / distance; links: 4 A_tri / (3 h²) (A_tri = area of the V end)
        v = np.where(lay[i] == LAYER_V, i, j)
        geo = np.where(model.spring_layer[sel] == 2, 4.0 * model.particle_area[v] / (3.0 * model.thickness ** 2),
                       model.spring_face[sel] / np.maximum(model.spring_rest0[sel], 1e-300))
        a = 0.5 * (tau[i] + tau[j]) * hm * geo
        K = sp.coo_matrix((np.r_[-a, -a, a, a], (np.r_[i, j, i, j], np.r_[j, i, i, j])), shape=(n, n)).tocsr()
        K.sum_duplicates()
        return K

    def configure(self, params, dt: float | None = None):
        """``dt``: the time one solve covers (default Δt; k Δt when solved every k-th frame)."""
        D = params["osmosis.diffusion"]
        through = params["osmosis.through_thickness"]
        dt = params["dynamics.dt"] if dt is None else dt
        solver = params["osmosis.solver"]
        if solver == "auto":
            solver = "direct" if self.model.particle_count <= DIRECT_MAX_UNKNOWNS else "cg"
        self.solver = solver
        self.tol = params["osmosis.tolerance"]
        lay = self.model.particle_layer
        self.rate = np.where(lay == LAYER_V, params["osmosis.evaporation_top"], params["osmosis.evaporation_bottom"]).astype(float)
        # Evaporation acts per unit of leaf surface: a particle loses E × Δt × the area it
        # stands for (Jeong: w − w_loss Δt 1), more near the margin where the air's boundary
        # layer is thin (edge_factor).  Light tissue and the margin therefore dry first relative
        # to their content — the pattern that drives margin-first shrinking and colour;
        # diffusion (osmosis) and the veins' water work against it.
        edge = edge_factor(self.model, params["osmosis.edge_evaporation"], params["osmosis.edge_length"])
        self.weather = None
        if params["environment.drive"] == "weather":
            # the rates follow the weather and the tissue's water (environment.py); the margin's
            # thinner boundary layer raises the air's conductance there, not the leaf's
            self.weather = Weather(self.model, params, edge)
            self.loss_ref = self.model.particle_area.copy()
        else:
            self.loss_ref = self.model.particle_area * edge
        self.loss_ref *= patch_factor(self.model, params["osmosis.patchiness"])
        self.dt = dt
        key = (D, dt, solver, through)
        if key != self.key:
            self.K = self.K_plane + self.K_link if through else self.K_plane
            A = (sp.diags(self.M) + (dt * D) * self.K).tocsr()
            A.sort_indices()
            self.A = A
            self.diag = A.diagonal().copy()
            self.factors = _csr_factors(A) if solver == "direct" else None
            self.key = key

    def apply(self, state: State):
        w = state.particle_water
        M = self.M
        if self.weather is not None:
            self.weather.rates(w, out=self.rate)
        if self.solver == "direct":  # rhs, triangular solves and w = max(c, 0) M in one numba call
            ko.direct_step(M, w, self.loss_ref, self.rate, self.dt, *self.factors, self.c, self.rhs, self.loss)
            self.last_iterations = 1
            return
        c = w / M
        ko.loss_rhs(M, c, self.loss_ref, self.rate, self.dt, self.rhs, self.loss)
        cn = c - self.loss / M  # warm start: previous concentration minus the drop
        fn = ko.pcg if self.solver == "cg" else ko.jacobi
        self.last_iterations = fn(self.A.indptr, self.A.indices, self.A.data, self.diag, self.rhs, cn, self.tol, 2000)
        np.maximum(cn, 0.0, out=cn)  # round-off guard (M-matrix: exact solution is ≥ 0)
        np.multiply(cn, M, out=w)
