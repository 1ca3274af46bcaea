"""Vertex Block Descent (Chen et al., SIGGRAPH 2024) against XPBD on one implicit step of the
drying blade: sweeps to a relative error, by mesh and step size (the solver issue's VBD
candidate, measured on the problem both solvers solve).

The problem: one backward-Euler step of the blade's elastic model from a mid-drying state,

    x* = argmin Φ(x),  Φ(x) = Σ m̃_i / (2h²) |x_i − y_i|² + E(x),  y = x₀ + h v₀ + h² g̃,

E the membrane and vein springs, the discrete-shell hinges (bilayer rest angles, dry
stiffening, veins) and the thickness volumes with the stiffness the simulator gives them
(``Dynamics.sun_elastic``: the same records the static solver and Sun's integrator use), m̃ the
particle masses × ``dynamics.mass_scaling`` and g̃ = g ÷ that factor (the production scaling).
The rest values, stiffnesses and masses (water) are those of FRAMES_AHEAD frames after the state (the drying's shrink over
that many frames, so the step has a real increment to take up, not only gravity).  The ground
and self-contact are left out of the problem: both solvers would treat them the same way, and
the question here is how each converges on the blade's own stiffness.

* reference x*: Newton on Φ with the exact Hessian (``kernels.static.elastic``; a Levenberg
  shift when its step does not descend), to a step below 10⁻¹³ m; the largest force left is
  printed (× a particle's weight);
* VBD: Gauss–Seidel over the particles, each taking the Newton step of Φ in its own three
  coordinates (springs' exact block with the compressed transverse part clamped at 0, hinges'
  and volumes' Gauss–Newton blocks k ∇C ∇Cᵀ), optionally with Chebyshev acceleration ρ;
* XPBD: Gauss–Seidel over the constraints (springs, hinges, volumes in model order) with
  compliance α̃ = 1 / (k h²) and multipliers from 0, the same records.  Unlike the
  simulator's XPBD, whose thickness volumes are hard constraints with a step limiter, the
  volumes here are compliant like the other constraints, so that both solvers solve Φ.

Both start from y.  Printed per (mesh, h): the error after 2 sweeps (the default's iteration
budget per substep) and after 6, sweeps to reach ‖x − x*‖_M / ‖y − x*‖_M below
1e-1, 1e-2 and 1e-3 (— = not within the cap) and the median wall ms of one sweep.

    .venv/bin/python tools/vbd_probe.py [--species oak] [--meshes 0.028,0.0199,0.0141] [--cap 3000]
        [--steps substep,fixed40,frame] [--rho 0.9] [--global-solves]

``--global-solves`` adds Newton on Φ with the Gauss–Newton Hessian solved by AMG-preconditioned
CG (MGPBD's global solve, in primal form) and by a sparse LU: Newton iterations and wall ms to
each level.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spla
from numba import njit

from leafsim.base.errors import LeafsimError
from leafsim.config.species import get_species
from leafsim.pipeline import build_leaf
from leafsim.sim.effects.dynamics import effective_substeps
from leafsim.sim.kernels import static as kst
from leafsim.sim.run import Run

WATER = 0.6
FRAMES_AHEAD = 32
LEVELS = (1e-1, 1e-2, 1e-3)


@njit(cache=True, nogil=True, error_model="numpy")
def _solve3(H, f, out):
    """out ← H⁻¹ f for a symmetric positive definite 3 × 3 H (Cholesky)."""
    l00 = math.sqrt(H[0, 0])
    l10 = H[1, 0] / l00
    l20 = H[2, 0] / l00
    l11 = math.sqrt(max(H[1, 1] - l10 * l10, 1e-300))
    l21 = (H[2, 1] - l20 * l10) / l11
    l22 = math.sqrt(max(H[2, 2] - l20 * l20 - l21 * l21, 1e-300))
    z0 = f[0] / l00
    z1 = (f[1] - l10 * z0) / l11
    z2 = (f[2] - l20 * z0 - l21 * z1) / l22
    out[2] = z2 / l22
    out[1] = (z1 - l21 * out[2]) / l11
    out[0] = (z0 - l10 * out[1] - l20 * out[2]) / l00


@njit(cache=True, nogil=True, error_model="numpy")
def vbd_sweep(x, y, mh2, ij, sk, srest, hidx, hk, hrest, vidx, vk, vrest, sptr, slist, hptr, hlist, vptr, vlist):
    """One VBD sweep over the particles in index order; returns the largest move."""
    H = np.empty((3, 3))
    f = np.empty(3)
    d3 = np.empty(3)
    x4 = np.empty((4, 3))
    u = np.empty((4, 3))
    big = 0.0
    for i in range(x.shape[0]):
        for c in range(3):
            f[c] = -mh2[i] * (x[i, c] - y[i, c])
            for r in range(3):
                H[r, c] = mh2[i] if r == c else 0.0
        for k in range(sptr[i], sptr[i + 1]):
            s = slist[k] >> 1
            sign = 1.0 if (slist[k] & 1) == 0 else -1.0
            a = ij[s, 0]
            b = ij[s, 1]
            dx = x[a, 0] - x[b, 0]; dy = x[a, 1] - x[b, 1]; dz = x[a, 2] - x[b, 2]
            L = math.sqrt(dx * dx + dy * dy + dz * dz)
            if L < 1e-15:
                continue
            n0 = dx / L; n1 = dy / L; n2 = dz / L
            kk = sk[s]
            fc = kk * (L - srest[s]) * sign
            f[0] -= fc * n0; f[1] -= fc * n1; f[2] -= fc * n2
            t = 1.0 - srest[s] / L
            if t < 0.0:
                t = 0.0
            nn = (n0, n1, n2)
            for r in range(3):
                for c in range(3):
                    H[r, c] += kk * ((1.0 - t) * nn[r] * nn[c] + (t if r == c else 0.0))
        for k in range(hptr[i], hptr[i + 1]):
            e = hlist[k] >> 2
            p = hlist[k] & 3
            for q in range(4):
                for c in range(3):
                    x4[q, c] = x[hidx[e, q], c]
            th = kst._hinge_grad(x4, u)
            if math.isnan(th):
                continue
            C = kst._wrap(th - hrest[e])
            kk = hk[e]
            for r in range(3):
                f[r] -= kk * C * u[p, r]
                for c in range(3):
                    H[r, c] += kk * u[p, r] * u[p, c]
        for k in range(vptr[i], vptr[i + 1]):
            e = vlist[k] >> 2
            p = vlist[k] & 3
            for q in range(4):
                for c in range(3):
                    x4[q, c] = x[vidx[e, q], c]
            C = kst._vol_grad(x4, u) - vrest[e]
            kk = vk[e]
            for r in range(3):
                f[r] -= kk * C * u[p, r]
                for c in range(3):
                    H[r, c] += kk * u[p, r] * u[p, c]
        _solve3(H, f, d3)
        m = 0.0
        for c in range(3):
            x[i, c] += d3[c]
            m += d3[c] * d3[c]
        if m > big:
            big = m
    return math.sqrt(big)


@njit(cache=True, nogil=True, error_model="numpy")
def xpbd_sweep(x, invm, h2, ij, sk, srest, ls, hidx, hk, hrest, lh, vidx, vk, vrest, lv):
    """One XPBD sweep: springs, hinges, volumes in model order, compliance 1 / (k h²);
    returns the largest move of a constraint projection."""
    x4 = np.empty((4, 3))
    u = np.empty((4, 3))
    big = 0.0
    for s in range(ij.shape[0]):
        a = ij[s, 0]
        b = ij[s, 1]
        dx = x[a, 0] - x[b, 0]; dy = x[a, 1] - x[b, 1]; dz = x[a, 2] - x[b, 2]
        L = math.sqrt(dx * dx + dy * dy + dz * dz)
        if L < 1e-15:
            continue
        at = 1.0 / (sk[s] * h2)
        w = invm[a] + invm[b]
        dl = (-(L - srest[s]) - at * ls[s]) / (w + at)
        ls[s] += dl
        g0 = dx / L * dl; g1 = dy / L * dl; g2 = dz / L * dl
        x[a, 0] += invm[a] * g0; x[a, 1] += invm[a] * g1; x[a, 2] += invm[a] * g2
        x[b, 0] -= invm[b] * g0; x[b, 1] -= invm[b] * g1; x[b, 2] -= invm[b] * g2
        mv = abs(dl) * max(invm[a], invm[b])
        if mv > big:
            big = mv
    for e in range(hidx.shape[0]):
        for q in range(4):
            for c in range(3):
                x4[q, c] = x[hidx[e, q], c]
        th = kst._hinge_grad(x4, u)
        if math.isnan(th):
            continue
        C = kst._wrap(th - hrest[e])
        at = 1.0 / (hk[e] * h2)
        w = 0.0
        for q in range(4):
            w += invm[hidx[e, q]] * (u[q, 0] ** 2 + u[q, 1] ** 2 + u[q, 2] ** 2)
        dl = (-C - at * lh[e]) / (w + at)
        lh[e] += dl
        for q in range(4):
            iq = hidx[e, q]
            for c in range(3):
                d = invm[iq] * dl * u[q, c]
                x[iq, c] += d
                if abs(d) > big:
                    big = abs(d)
    for e in range(vidx.shape[0]):
        for q in range(4):
            for c in range(3):
                x4[q, c] = x[vidx[e, q], c]
        C = kst._vol_grad(x4, u) - vrest[e]
        at = 1.0 / (vk[e] * h2)
        w = 0.0
        for q in range(4):
            w += invm[vidx[e, q]] * (u[q, 0] ** 2 + u[q, 1] ** 2 + u[q, 2] ** 2)
        dl = (-C - at * lv[e]) / (w + at)
        lv[e] += dl
        for q in range(4):
            iq = vidx[e, q]
            for c in range(3):
                d = invm[iq] * dl * u[q, c]
                x[iq, c] += d
                if abs(d) > big:
                    big = abs(d)
    return big


def _adjacency(n, idx, shift):
    """CSR of (element << shift | slot) per particle for elements ``idx`` (e, k)."""
    e, k = idx.shape
    owner = idx.reshape(-1).astype(np.int64)
    code = (np.repeat(np.arange(e, dtype=np.int64), k) << shift) | np.tile(np.arange(k, dtype=np.int64), e)
    order = np.argsort(owner, kind="stable")
    ptr = np.zeros(n + 1, np.int64)
    np.add.at(ptr, owner + 1, 1)
    return np.cumsum(ptr), code[order]


class Problem:
    """One step problem (module doc) of ``species`` on mesh ``spacing``."""

    def __init__(self, species: str, spacing: float, h_kind: str):
        sp = get_species(species)
        base = {"mesh.spacing": spacing, "dynamics.path": "own", "dynamics.scene": "ground"}
        p = sp.params.with_overrides(base)
        _, _, model = build_leaf(sp, p, 0)
        run = Run(model, p, seed=0, name=species)
        for _ in run.frames(until=lambda st: model.water_fraction(st.particle_water) <= WATER):
            pass
        a = run.state.copy()
        for _ in range(FRAMES_AHEAD):
            run.step()
        b = run.state
        dyn = run.sim._dynamics
        E, Ev, th = p["material.modulus"], p["material.vein_modulus"], model.thickness
        dyn._configure_sun(p, E * 0.5 * th * model.spring_weight + Ev * model.spring_rod, E)
        rec = dyn.sun_elastic(b)
        ij, sk, srest, _, hidx, hk, hrest, vidx, vk, vrest = (np.array(r) for r in rec)
        self.ij, self.hidx, self.vidx = ij.astype(np.int64), hidx.astype(np.int64), vidx.astype(np.int64)
        self.sk, self.srest, self.hk, self.hrest, self.vk, self.vrest = sk, srest, hk, hrest, vk, vrest
        n = model.particle_count
        self.n = n
        M = p["dynamics.mass_scaling"]
        self.mass = (model.particle_cytosol + b.particle_water) * M
        # the production substep (∝ r², dynamics.substep_scaling), a fixed 1/40 of a frame, or a frame
        steps = {"substep": effective_substeps(p), "fixed40": 40, "frame": 1}[h_kind]
        self.h = p["dynamics.dt"] / steps
        g = np.array([0.0, 0.0, -p["dynamics.gravity"] / M])
        self.g = p["dynamics.gravity"] / M
        self.y = a.particle_q + self.h * a.particle_qd + self.h * self.h * g
        self.mh2 = self.mass / self.h ** 2
        self.sptr, self.slist = _adjacency(n, self.ij, 1)
        self.hptr, self.hlist = _adjacency(n, self.hidx, 2)
        self.vptr, self.vlist = _adjacency(n, self.vidx, 2)
        self.L = model.length
        self.substeps = effective_substeps(p)
        self.ref = self._newton()
        self.scale = self._mnorm(self.y - self.ref)

    def _mnorm(self, d):
        return math.sqrt(float(np.sum(self.mass[:, None] * d * d)))

    def phi(self, x):
        e = kst.elastic_energy(x, self.ij, self.sk, self.srest, self.hidx, self.hk, self.hrest, self.vidx, self.vk,
                               self.vrest)
        return e + 0.5 * float(np.sum(self.mh2[:, None] * (x - self.y) ** 2))

    def _pattern(self):
        """The block-sparse Hessian's pattern (indptr, indices, the records' maps), its blocks and
        the gradient to fill, and each particle's diagonal block."""
        n = self.n
        indptr, indices, smap, hmap, vmap = kst.block_pattern(n, self.ij, self.hidx, self.vidx)
        diag = np.array([np.searchsorted(indices[indptr[i]:indptr[i + 1]], i) + indptr[i] for i in range(n)])
        return indptr, indices, smap, hmap, vmap, np.zeros((len(indices), 3, 3)), np.zeros((n, 3)), diag

    def _newton(self):
        n = self.n
        indptr, indices, smap, hmap, vmap, data, grad, diag = self._pattern()
        x = self.y.copy()
        for it in range(60):
            kst.elastic(x, self.ij, self.sk, self.srest, self.hidx, self.hk, self.hrest, self.vidx, self.vk,
                        self.vrest, smap, hmap, vmap, grad, data, True, False)
            g = grad + self.mh2[:, None] * (x - self.y)
            for c in range(3):
                data[diag, c, c] += self.mh2
            K = sps.bsr_matrix((data, indices, indptr), shape=(3 * n, 3 * n)).tocsc()
            lam = 0.0
            f0 = self.phi(x)
            while True:
                A = K if lam == 0.0 else K + lam * sps.diags(np.repeat(self.mh2, 3))
                d = -spla.spsolve(A, g.reshape(-1)).reshape(n, 3)
                if float(np.sum(d * g)) < 0.0:
                    break
                lam = 1.0 if lam == 0.0 else lam * 10.0
            t = 1.0
            while self.phi(x + t * d) > f0 + 1e-4 * t * float(np.sum(d * g)) and t > 1e-8:
                t *= 0.5
            x = x + t * d
            step = t * float(np.abs(d).max())
            if step < 1e-13:
                break
        self.newton_iterations = it + 1
        # the largest force left on a particle, × its (scaled) weight: the reference's own accuracy
        kst.elastic(x, self.ij, self.sk, self.srest, self.hidx, self.hk, self.hrest, self.vidx, self.vk, self.vrest,
                    smap, hmap, vmap, grad, data, False, False)
        force = np.linalg.norm(grad + self.mh2[:, None] * (x - self.y), axis=1)
        self.residual = float(np.max(force / (self.mass * self.g)))
        return x

    def run_global(self, amg: bool, cap: int = 60):
        """Newton on Φ with the Gauss–Newton (positive semi-definite) Hessian, each linear solve by
        conjugate gradients preconditioned with smoothed-aggregation AMG (pyamg; rigid-body modes as
        the near null space) to a relative residual of 10⁻², or by a sparse LU (``amg`` False): the
        primal form of a global XPBD solve (MGPBD solves the same linearisation in λ).  Returns
        (Newton iterations to each level, wall s to each level, CG iterations in all, error)."""
        import pyamg

        n = self.n
        indptr, indices, smap, hmap, vmap, data, grad, diag = self._pattern()
        x = self.y.copy()
        hits, secs, cg = {}, {}, 0
        t0 = time.perf_counter()
        for it in range(1, cap + 1):
            kst.elastic(x, self.ij, self.sk, self.srest, self.hidx, self.hk, self.hrest, self.vidx, self.vk,
                        self.vrest, smap, hmap, vmap, grad, data, True, True)
            g = grad + self.mh2[:, None] * (x - self.y)
            for c in range(3):
                data[diag, c, c] += self.mh2
            A = sps.bsr_matrix((data, indices, indptr), shape=(3 * n, 3 * n)).tocsr()
            if amg:
                B = np.zeros((3 * n, 6))
                for c in range(3):
                    B[c::3, c] = 1.0
                # rotations about the three axes: ω × x
                B[1::3, 3], B[2::3, 3] = -x[:, 2], x[:, 1]
                B[0::3, 4], B[2::3, 4] = x[:, 2], -x[:, 0]
                B[0::3, 5], B[1::3, 5] = -x[:, 1], x[:, 0]
                ml = pyamg.smoothed_aggregation_solver(A, B=B, symmetry="symmetric", max_coarse=300)
                count = []
                d = -ml.solve(g.reshape(-1), tol=1e-2, accel="cg", maxiter=200,
                              callback=lambda _r: count.append(1)).reshape(n, 3)
                cg += len(count)
            else:
                d = -spla.spsolve(A.tocsc(), g.reshape(-1)).reshape(n, 3)
            f0 = self.phi(x)
            slope = float(np.sum(d * g))
            t = 1.0
            while self.phi(x + t * d) > f0 + 1e-4 * t * slope and t > 1e-8:
                t *= 0.5
            x = x + t * d
            e = self.error(x)
            for lv in LEVELS:
                if lv not in hits and e < lv:
                    hits[lv] = it
                    secs[lv] = time.perf_counter() - t0
            if e < LEVELS[-1]:
                break
        return hits, secs, cg, e

    def error(self, x):
        return self._mnorm(x - self.ref) / self.scale

    def _sweeps(self, sweep, x, cap):
        """``sweep(k, x)`` (the k-th sweep, in place) until the error is below the last level or
        ``cap`` sweeps: the sweeps to each level, the errors after 2, 6, 300 and 1000 sweeps, the
        median ms of a sweep and the last error."""
        hits, times = {}, []
        for k in range(1, cap + 1):
            t0 = time.perf_counter()
            sweep(k, x)
            times.append(time.perf_counter() - t0)
            e = self.error(x)
            if k in (2, 6, 300, 1000):
                hits[k] = e
            if not math.isfinite(e) or e > 1e6:
                hits["diverged"] = k
                break
            for lv in LEVELS:
                if lv not in hits and e < lv:
                    hits[lv] = k
            if e < LEVELS[-1]:
                break
        hits["last"] = k
        return hits, float(np.median(times)) * 1e3, e

    def run_vbd(self, cap, rho=0.0):
        x = self.y.copy()
        prev2, prev1, omega = x.copy(), x.copy(), [1.0]

        def sweep(k, x):
            vbd_sweep(x, self.y, self.mh2, self.ij, self.sk, self.srest, self.hidx, self.hk, self.hrest, self.vidx,
                      self.vk, self.vrest, self.sptr, self.slist, self.hptr, self.hlist, self.vptr, self.vlist)
            if rho > 0.0:
                # Chebyshev semi-iteration (Wang 2015, as VBD's paper applies it), from the 2nd sweep
                w = 1.0 if k == 1 else 2.0 / (2.0 - rho * rho) if k == 2 else 4.0 / (4.0 - rho * rho * omega[0])
                omega[0] = w
                if k >= 2:
                    x[:] = w * (x - prev2) + prev2
                prev2[:] = prev1
                prev1[:] = x

        return self._sweeps(sweep, x, cap)

    def run_xpbd(self, cap):
        invm = 1.0 / self.mass
        ls, lh, lv = np.zeros(len(self.sk)), np.zeros(len(self.hk)), np.zeros(len(self.vk))
        return self._sweeps(lambda k, x: xpbd_sweep(x, invm, self.h * self.h, self.ij, self.sk, self.srest, ls,
                                                    self.hidx, self.hk, self.hrest, lh, self.vidx, self.vk,
                                                    self.vrest, lv), self.y.copy(), cap)


def _history(hits, e):
    """The error after 300, 1000 sweeps and at the last sweep (a plateau shows here)."""
    parts = [f"{hits[k]:.2e} ({k})" for k in (300, 1000) if k in hits and hits.get("last", 0) > k]
    return " → ".join(parts + [f"{e:.2e} ({hits.get('last', '?')})"])


def _cells(hits):
    two = " / ".join(f"{hits[k]:.3f}" if k in hits else "—" for k in (2, 6))
    if "diverged" in hits:
        return [two, f"diverged at {hits['diverged']}"] + [""] * (len(LEVELS) - 1)
    return [two] + [str(hits.get(lv, "—")) for lv in LEVELS]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--species", default="oak")
    ap.add_argument("--meshes", default="0.028,0.0199,0.0141")
    ap.add_argument("--steps", default="substep,fixed40,frame", help="comma-separated: substep, fixed40, frame")
    ap.add_argument("--cap", type=int, default=3000)
    ap.add_argument("--rho", default="0.9")
    ap.add_argument("--global-solves", action="store_true", help="also Newton with AMG-PCG and with a sparse LU")
    a = ap.parse_args()
    bad = set(a.steps.split(",")) - {"substep", "fixed40", "frame"}
    if bad:
        ap.error(f"--steps: unknown {', '.join(sorted(bad))} (expected substep, fixed40, frame)")
    print("| mesh (× L) | particles | h | solver | error after 2 / 6 sweeps | sweeps to 1e-1 | 1e-2 | 1e-3 | error after "
          "300 → 1000 → the last sweep | ms / sweep |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for kind in a.steps.split(","):
        for s in (float(v) for v in a.meshes.split(",")):
            t0 = time.perf_counter()
            pr = Problem(a.species, s, kind)
            h = f"{pr.h * 1e6:.0f} µs" + {"substep": f" (1/{pr.substeps} frame)", "fixed40": " (1/40 frame)",
                                          "frame": " (a frame)"}[kind]
            rows = [("XPBD", pr.run_xpbd(a.cap)), ("VBD", pr.run_vbd(a.cap))]
            for r in (float(v) for v in a.rho.split(",") if float(v) > 0):
                rows.append((f"VBD + Chebyshev ρ {r:g}", pr.run_vbd(a.cap, r)))
            for name, (hits, ms, e) in rows:
                print(f"| {s:g} | {pr.n} | {h} | {name} | " + " | ".join(_cells(hits)) + f" | {_history(hits, e)} | "
                      f"{ms:.2f} |", flush=True)
            if a.global_solves:
                for name, amg in (("Newton, AMG-PCG", True), ("Newton, sparse LU", False)):
                    hits, secs, cg, e = pr.run_global(amg)
                    cells = [f"{hits[lv]} ({secs[lv] * 1e3:.0f} ms)" if lv in hits else "—" for lv in LEVELS]
                    print(f"| {s:g} | {pr.n} | {h} | {name}: Newton iterations (wall ms) | — | " + " | ".join(cells)
                          + f" | {e:.2e} | {cg} CG iterations |", flush=True)
            print(f"<!-- {s:g} {kind}: Newton reference in {pr.newton_iterations} iterations, largest force left "
                  f"{pr.residual:.1e} × a particle's weight, "
                  f"|y − x*|_M / √M = {pr.scale / math.sqrt(pr.mass.sum()) * 1e6:.2f} µm, "
                  f"{time.perf_counter() - t0:.0f} s -->", flush=True)


if __name__ == "__main__":
    try:
        main()
    except LeafsimError as err:  # an unknown species or an out-of-range mesh: one line, not a traceback
        raise SystemExit(f"vbd_probe: {err}")
