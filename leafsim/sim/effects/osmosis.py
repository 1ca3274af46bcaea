"""The osmosis effect [Jeong eq. 2.7–2.9, in its conservative symmetric form]: water flows
between neighbours by finite-volume conductances and evaporates per unit area from both
surfaces; one implicit step per call, on a matrix factored once."""

from __future__ import annotations

import time
from collections import deque

import numba
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


def _mmd_order(A: sp.csr_matrix, ids: np.ndarray) -> np.ndarray:
    """``ids`` in the minimum-degree order of their own block of ``A`` (SuperLU's, as below)."""
    if len(ids) < 2:
        return ids
    lu = splu(A[ids][:, ids].tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
              options={"SymmetricMode": True})
    return ids[np.argsort(lu.perm_c)]


def _dissection(A: sp.csr_matrix, xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """One level of nested dissection of the SPD matrix ``A`` whose unknowns sit at ``xyz``:
    split at the median along x or along y, whichever cut couples fewer unknowns; the separator
    is every unknown of the first side coupled to the second.  Returns (order, bounds): the
    unknowns as [first half, second half, separator], each in its own minimum-degree order, and
    bounds [0, b₁, b₂] where the second half and the separator start.  None when neither cut
    is balanced (a half under a quarter of the unknowns) with a separator under 5 % of them
    (leaves under about a thousand particles).
    On a 132 k-particle maple the factors hold 13 % more entries than one minimum-degree order
    of the whole (11.8 M against 10.4 M; 20 % more cut along the leaf's length, stalk included,
    where the separator has 656 unknowns instead of 487)."""
    n = A.shape[0]
    C = A.tocoo()
    off = C.row != C.col
    r, c = C.row[off], C.col[off]
    best = None
    for axis in (0, 1):  # of the balanced cuts, the one with the smaller separator
        x = xyz[:, axis]
        first = x <= np.median(x)
        sep = np.zeros(n, bool)
        sep[r[first[r] & ~first[c]]] = True
        a, b, s = np.flatnonzero(first & ~sep), np.flatnonzero(~first), np.flatnonzero(sep)
        if min(len(a), len(b)) >= n // 4 and len(s) <= n // 20 and (best is None or len(s) < len(best[2])):
            best = (a, b, s)
    if best is None:
        return None
    a, b, s = best
    order = np.concatenate([_mmd_order(A, a), _mmd_order(A, b), _mmd_order(A, s)])
    return order, np.array([0, len(a), len(a) + len(b)], np.int64)


def _strip(F: sp.csr_matrix, n: int, lower: bool) -> tuple:
    """A triangular factor as CSR rows without their diagonal, 32-bit column indices: (row
    pointers, columns, values, diagonal)."""
    F.sort_indices()
    p, ix = F.indptr.astype(np.int64), F.indices
    dpos = p[1:] - 1 if lower else p[:-1]  # sorted rows: L's diagonal ends a row, U's starts it
    if (np.diff(p) < 1).any() or (ix[dpos] != np.arange(n)).any():
        raise ValueError("osmosis: a factor lacks a diagonal entry")
    keep = np.ones(len(ix), bool)
    keep[dpos] = False
    return p - np.arange(n + 1), ix[keep].astype(np.int32), F.data[keep], F.data[dpos].copy()


def _csr_factors(A: sp.csr_matrix, order: np.ndarray | None = None) -> tuple:
    """The LU factors of the SPD matrix ``A`` as arrays for the fused numba solve
    (:func:`.kernels.osmosis.direct_step`): minimum-degree ordering on A + Aᵀ with diagonal
    pivots (A is SPD), 40 % less fill than COLAMD on these meshes (maple: 115 k vs 184 k nnz),
    solve 0.42 vs 0.63 ms.  Each factor is kept as CSR rows without their diagonal, with 32-bit
    column indices: the solve reads every entry once per step, and without the per-entry test
    for the diagonal and with 12 instead of 16 bytes an entry it ran 1.15–1.23 × faster on a
    132 k-particle leaf (bit-identical).  L's diagonal is SuperLU's unit one (checked), U's is
    kept apart.  SuperLU's own object is not kept: it held as many bytes again (245 MB for a
    132 k-particle leaf, 1.9 kB a particle).

    With ``order`` (the unknowns in the order to eliminate them, :func:`_dissection`) the matrix
    is factored in that order as it stands; the row and column permutations returned then map a
    particle to its place in ``order``."""
    n = A.shape[0]
    if n >= 2**31:
        raise ValueError(f"osmosis: {n} unknowns do not fit the solve's 32-bit indices")
    if order is None:
        lu = splu(A.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        perm = (lu.perm_r.astype(np.int64), lu.perm_c.astype(np.int64))
    else:
        lu = splu(A[order][:, order].tocsc(), permc_spec="NATURAL", diag_pivot_thresh=0.0,
                  options={"SymmetricMode": True})
        inv = np.argsort(order).astype(np.int64)
        perm = (lu.perm_r.astype(np.int64)[inv], lu.perm_c.astype(np.int64)[inv])
    L = lu.L.tocsr()
    U = lu.U.tocsr()
    del lu
    (Lp, Li, Lx, Ld), (Up, Ui, Ux, Ud) = _strip(L, n, True), _strip(U, n, False)
    if (Ld != 1.0).any():
        raise ValueError("osmosis: SuperLU's L factor is not unit lower triangular")
    return Lp, Li, Lx, Up, Ui, Ux, Ud, *perm


def _split_factors(A: sp.csr_matrix, cut: tuple[np.ndarray, np.ndarray] | None) -> tuple | None:
    """The factors of :func:`_csr_factors` in the order ``cut`` of :func:`_dissection`, with what the
    two-thread solve (:func:`.kernels.osmosis.direct_step_split`) needs: (Lp, Li, Lx, Up, Ui,
    Ux, Ud, perm, bounds, cuts).  None when the cut is lopsided, or when SuperLU moved a row
    or the factors couple the two halves (neither happens with diagonal pivots on an SPD
    matrix; checked, not assumed)."""
    if cut is None:
        return None
    order, bounds = cut
    Lp, Li, Lx, Up, Ui, Ux, Ud, pr, pc = _csr_factors(A, order)
    if (pr != pc).any() or (pr != np.argsort(order)).any():  # SuperLU kept the order
        return None
    n, b1, b2 = A.shape[0], int(bounds[1]), int(bounds[2])

    def part(rows):  # 0, 1: the halves, 2: the separator
        return np.where(rows < b1, 0, np.where(rows < b2, 1, 2))

    for p, ix, upper in ((Lp, Li, False), (Up, Ui, True)):
        rp, cp = part(np.repeat(np.arange(n), np.diff(p))), part(ix)
        ok = (cp == rp) | ((cp == 2) if upper else (rp == 2))  # U reaches up into the separator, L down from it
        if not ok.all():
            return None
    cuts = np.empty((3, n - b2), np.int64)
    for r in range(b2, n):
        row = Li[Lp[r]:Lp[r + 1]]
        cuts[:, r - b2] = Lp[r] + np.searchsorted(row, [0, b1, b2])
    return Lp, Li, Lx, Up, Ui, Ux, Ud, pr, bounds, cuts


class _Threads:
    """How many threads the two-half solve runs on, chosen by its own timings: two on a quiet
    machine (a 132 k-particle solve 20.1 → 11.5–13 ms), one when the other core is busy (there
    two threads took 24–33 ms a solve against 22–23 ms for one, and their spinning slowed the
    next stage too).  Each count is timed three times at the start and the faster kept; the
    other is then tried once every ``interval`` solves (16 at first, doubling up to 256 while
    it keeps losing, and at once when the kept count's median of its last five solves grows
    above the other's), and taken as soon as a try beats that median, so a load that goes is
    followed within 16–256 solves and one that comes within a few.  The count never changes a result: the halves' sums are the same either way (tested
    bit-identical)."""

    FIRST = 16
    LONGEST = 256
    KEEP = 5

    def __init__(self):
        self.seconds = {1: deque(maxlen=self.KEEP), 2: deque(maxlen=self.KEEP)}
        self.calls = 0
        self.current = 0  # 0 until both counts have been timed
        self.interval = self.FIRST
        self.next_try = 0
        self.trying = False

    def pick(self, most: int) -> int:
        if most < 2:
            return 1
        self.calls += 1
        if not self.current:
            for k in (2, 1):
                if len(self.seconds[k]) < 3:
                    return k
            self.current = 1 if np.median(self.seconds[1]) < np.median(self.seconds[2]) else 2
            self.next_try = self.calls + self.interval
        kept, other = self.seconds[self.current], self.seconds[3 - self.current]
        # due, or the kept count has grown slower than the other's last timings (a load came)
        self.trying = self.calls >= self.next_try or np.median(kept) > np.median(other)
        return 3 - self.current if self.trying else self.current

    def record(self, k: int, seconds: float):
        if self.current and self.trying:
            self.trying = False
            if seconds < np.median(self.seconds[self.current]):
                self.current, self.interval = k, self.FIRST
                self.seconds[k].clear()
            else:
                self.interval = min(2 * self.interval, self.LONGEST)
            self.next_try = self.calls + self.interval
        self.seconds[k].append(seconds)


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
        self.split = False
        self._cuts = {}  # osmosis.through_thickness -> _dissection's cut (or None)
        self.threads = _Threads()
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
            self.factors, self.split = None, False
            if solver == "halves":  # falls back to the serial factor when the cut is lopsided
                if through not in self._cuts:  # the cut depends on the pattern only: a new Δt or D keeps it
                    self._cuts[through] = _dissection(A, self.model.particle_rest)
                self.factors = _split_factors(A, self._cuts[through])
                self.split = self.factors is not None
                if self.split:
                    self.acc = np.zeros((2, A.shape[0] - int(self.factors[8][2])))
            if solver in ("direct", "halves") and not self.split:
                self.factors = _csr_factors(A)
            self.key = key

    def apply(self, state: State):
        w = state.particle_water
        M = self.M
        if self.weather is not None:
            self.weather.rates(w, out=self.rate)
        if self.split:  # the same, its halves on two threads (or one, :class:`_Threads`)
            most = numba.get_num_threads()
            k = self.threads.pick(most)
            numba.set_num_threads(k)
            try:
                t0 = time.perf_counter()
                ko.direct_step_split(M, w, self.loss_ref, self.rate, self.dt, *self.factors, self.c, self.rhs,
                                     self.loss, self.acc)
                self.threads.record(k, time.perf_counter() - t0)
            finally:
                numba.set_num_threads(most)
            self.last_iterations = 1
            return
        if self.factors is not None:  # rhs, triangular solves and w = max(c, 0) M in one numba call
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
