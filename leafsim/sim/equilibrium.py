"""Static equilibrium of the blade (``dynamics.integrator = static``): drying as what it
physically is, a sequence of equilibria.

Water leaves a leaf over hours while elastic waves cross it in milliseconds, so at every
moment of the drying the blade rests where its energy is least, starting from where it was.
:class:`Equilibrium` finds that shape with a projected Newton method:

    E(x) = E_elastic(x) + Σ m_i g z_i + E_ground(x) + E_friction(x) + E_contact(x)

* E_elastic: the blade's elastic energy, the same model the XPBD loop projects and Sun's
  integrator differentiates (membrane and vein springs, discrete-shell hinges with the bilayer
  rest angles, thickness volumes; :mod:`.kernels.static`);
* gravity with the real mass (cytosol + water) and g, so no mass scaling enters;
* the ground z ≥ 0 as a stiff penalty below it (:func:`ground_penalty`, C²), k_g = the leaf's weight over
  ``PENETRATION`` × the blade's thickness (one particle carrying it all sinks 1.5 × that far);
* Coulomb friction, lagged (as in incremental contact mechanics): a particle that pressed on
  the ground with force N at the last equilibrium resists sliding from where it was with the
  smoothed work μ N f(|u|), f(u) = u² / 2ε below ε, u − ε/2 above (ε = ``STICK`` × the mesh
  spacing), i.e. it sticks until the tangential force reaches μ N and then slides;
* self-contact: layer-T particles closer than the contact radius r that are not sheet
  neighbours repel with the ground's C² penalty on the overlap r − d.

Each Newton step solves H Δ = −∇E with H the exact Hessian (springs analytically, the
hinges' and volumes' residual terms by differences of their exact gradients; ground and friction
exact; self-contact Gauss–Newton) by a sparse symmetric LU factorisation, plus a tiny Levenberg
term that fixes the rigid in-plane motion nothing else holds.  Where H is indefinite
(the factorisation's pivots say so) a Levenberg–Marquardt term grows until it is not; a line
search on E (along an arc for the step's rigid part, :meth:`Equilibrium._path`) makes every
step descend.  The solve
stops when the largest force left on any particle is below ``tolerance`` × that particle's
weight.  Pinned particles (the hanging scene) do not move.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spla
from scipy.spatial import cKDTree

from leafsim.base.errors import LeafsimError
from leafsim.sim.kernels import static as kst
from leafsim.sim.model import LAYER_T, Model, State

#: the ground's penalty: the whole leaf's weight on one particle sinks it 1.5 × this share of the
#: blade's thickness (a curled leaf rests on a few particles)
PENETRATION = 0.01
#: self-contact pairs are searched this much (× the radius) beyond the contact radius
CONTACT_SKIN = 1.0
#: self-contact's penalty is cubic over this share of the contact radius (C², as the ground's)
CONTACT_SMOOTH = 0.1
#: friction's stick zone ε, × the mesh spacing
STICK = 1e-3
#: Levenberg term, × the mean diagonal of the Hessian
LEVENBERG = 1e-9
#: Armijo constant of the line search
ARMIJO = 1e-4
#: the smallest Levenberg–Marquardt damping, × the Hessian's diagonal (below it: none), and the
#: largest (beyond it the state has no descent direction: an error)
LAM_MIN = 1e-4
LAM_MAX = 1e12
#: the longest multiple of a Newton step the line search tries when the energy keeps falling
EXPAND = 64.0
#: relative rounding of the energy below which the line search takes the full step
NOISE = 1e-12
#: a Newton step reuses the last factorisation as the preconditioner of conjugate gradients
#: while they reach this relative residual within REUSE_CG iterations
REUSE_RTOL = 1e-3
REUSE_CG = 8


@dataclass
class SolveInfo:
    """One equilibrium solve: Newton iterations, the residual (largest force / weight) before
    and after, the energy, contacts and the seconds it took."""

    iterations: int
    residual0: float
    residual: float
    energy: float
    ground: int
    contacts: int
    seconds: float
    converged: bool


def ground_penalty(p, k, delta):
    """The ground's energy, force and stiffness at penetration ``p`` ≥ 0 with stiffness ``k``:
    cubic k p³ / 6δ up to δ, then quadratic k (p²/2 − δp/2 + δ²/6), so the energy is twice
    continuously differentiable (a kinked stiffness at first touch made a leaf that rolls
    over its contacts creep in tiny Newton steps)."""
    cubic = p < delta
    e = np.where(cubic, k * p ** 3 / (6.0 * delta), k * (0.5 * p * p - 0.5 * delta * p + delta * delta / 6.0))
    f = np.where(cubic, k * p * p / (2.0 * delta), k * (p - 0.5 * delta))
    s = np.where(cubic, k * p / delta, k)
    return e, f, s


class Equilibrium:
    """The static-equilibrium solver of one model (see the module doc); ``dynamics`` is the
    model's :class:`~leafsim.sim.effects.dynamics.Dynamics`, configured, whose elastic records
    (:meth:`~leafsim.sim.effects.dynamics.Dynamics.sun_elastic`) it shares."""

    def __init__(self, model: Model, dynamics):
        self.model = model
        self.dyn = dynamics
        n = model.particle_count
        self.n = n
        ij = model.spring_ij.astype(np.int64)
        hidx = model.hinge_idx.astype(np.int64)
        vidx = model.vol_idx.astype(np.int64)
        self.indptr, self.indices, self.smap, self.hmap, self.vmap = kst.block_pattern(n, ij, hidx, vidx)
        self.data = np.zeros((len(self.indices), 3, 3))
        self.grad = np.zeros((n, 3))
        self.T = np.flatnonzero(model.particle_layer == LAYER_T)
        self.anchor = model.particle_rest[:, :2].copy()
        self.normal = np.zeros(n)  # the ground's normal force on each particle at the last equilibrium [N]
        self.last = None
        self.lu = None
        self.reuse = False
        self.factorisations = 0
        self.damped = 0  # Levenberg–Marquardt raises of the damping (the Hessian was indefinite)
        self.history = []  # the last two equilibria: (time, positions)
        self.predicted = 0  # solves started from the secant prediction
        self.predictor = True
        self.log = []  # per solve: (Newton iterations, factorisations, seconds, residual)

    def reset(self) -> None:
        """Forget the friction anchors, normal forces and the predictor's history (another leaf,
        a reset, a rewind, a change of scene or integrator)."""
        self.history = []
        self.normal = np.zeros(self.n)
        self.anchor = self.model.particle_rest[:, :2].copy()
        self._fric = None

    def carry(self) -> dict:
        """What one solve hands the next (the ground's normal forces and friction anchors of
        the last equilibrium, the predictor's last two equilibria): a checkpoint keeps it so a
        resumed run solves exactly as one never interrupted."""
        k = len(self.history)
        return {"normal": self.normal.copy(), "anchor": self.anchor.copy(),
                "history_time": np.array([t for t, _ in self.history], float),
                "history_q": np.array([q for _, q in self.history]).reshape(k, self.n, 3)}

    def restore(self, carry: dict) -> None:
        """Take back what :meth:`carry` gave (arrays checked by the caller)."""
        self.normal = np.array(carry["normal"], float)
        self.anchor = np.array(carry["anchor"], float)
        self.history = [(float(t), np.array(q, float)) for t, q in zip(carry["history_time"], carry["history_q"])]
        self._fric = None

    def configure(self, params) -> None:
        m = self.model
        self.g = float(params["dynamics.gravity"]) if self.dyn.g != 0.0 else 0.0
        self.ground = self.dyn.ground
        self.mu = float(params["dynamics.friction"])
        self.tol = float(params["dynamics.static_tolerance"])
        self.max_iter = int(params["dynamics.static_iterations"])
        self.eps = STICK * m.spacing
        self.self_coll = self.dyn.self_coll and self.dyn.pbd
        self.free = np.ones(self.n, bool)
        if params["dynamics.scene"] == "hanging":
            self.free[m.particle_pinned] = False

    # ------------------------------------------------------------------ energy terms
    def _records(self, state: State) -> tuple:
        ij, sk, srest, tf, hidx, hk, hrest, vidx, vk, vrest = self.dyn.sun_elastic(state)
        if len(tf) and np.any(tf):
            # Sun's turgor force f along a spring is the gradient of −f |d|: a rest length ℓ + f/k
            srest = srest + np.where(sk > 0.0, tf / np.where(sk > 0.0, sk, 1.0), 0.0)
        return ij, sk, srest, hidx, hk, hrest, vidx, vk, vrest

    def _contacts(self, q: np.ndarray, radius: float) -> np.ndarray:
        """Layer-T pairs closer than (1 + ``CONTACT_SKIN``) × ``radius`` that are not sheet
        neighbours at rest (the penalty acts on those closer than ``radius``)."""
        if not self.self_coll or radius <= 0.0:
            return np.zeros((0, 2), np.int64)
        T = self.T
        # with a skin: the line search (and its longer steps) sees the pairs it may close
        pairs = cKDTree(q[T]).query_pairs((1.0 + CONTACT_SKIN) * radius, output_type="ndarray")
        if not len(pairs):
            return np.zeros((0, 2), np.int64)
        a, b = T[pairs[:, 0]], T[pairs[:, 1]]
        rest = self.model.particle_rest
        far = ((rest[a] - rest[b]) ** 2).sum(1) > self.dyn.skip2
        return np.stack([a[far], b[far]], 1)

    def _external(self, q, mass, want_h):
        """Gravity, ground, friction: energy, gradient (n, 3) and the Hessian's diagonal (3n,)."""
        n = self.n
        if want_h:
            self._fric = None
        grad = np.zeros((n, 3))
        diag = np.zeros((n, 3))
        w = mass * self.g
        E = float((w * q[:, 2]).sum())
        grad[:, 2] += w
        if self.ground:
            below = q[:, 2] < 0.0
            e, f, k = ground_penalty(-q[below, 2], self.kg[below], self.delta)
            E += float(e.sum())
            grad[below, 2] -= f
            diag[below, 2] += k
            if self.mu > 0.0:
                act = np.flatnonzero(self.normal > 0.0)
                if len(act):
                    u = q[act, :2] - self.anchor[act]
                    r = np.sqrt((u * u).sum(1))
                    c = self.mu * self.normal[act]
                    eps = self.eps
                    stick = r < eps
                    E += float(np.where(stick, 0.5 * c * r * r / eps, c * (r - 0.5 * eps)).sum())
                    s = np.where(stick, c / eps, c / np.maximum(r, 1e-300))
                    grad[act, :2] += s[:, None] * u
                    if want_h:
                        # stick: c/ε I; slide: c/|u| (I − ûûᵀ): the block's diagonal, the rest below
                        self._fric = (act, u, r, c, stick)
        return E, grad, diag

    def _hessian_extra(self, diag, pairs, q, kc):
        """The sparse matrix of ground, friction (2 × 2 in-plane blocks) and contacts."""
        n3 = 3 * self.n
        rows, cols, vals = [np.arange(n3)], [np.arange(n3)], [diag.reshape(-1)]
        if self.ground and self.mu > 0.0 and getattr(self, "_fric", None) is not None:
            act, u, r, c, stick = self._fric
            uh = u / np.maximum(r, 1e-300)[:, None]
            for a in range(2):
                for b in range(2):
                    ident = 1.0 if a == b else 0.0
                    v = np.where(stick, c / self.eps * ident, c / np.maximum(r, 1e-300) * (ident - uh[:, a] * uh[:, b]))
                    rows.append(3 * act + a); cols.append(3 * act + b); vals.append(v)
            self._fric = None
        if len(pairs):
            a, b = pairs[:, 0], pairs[:, 1]
            d = q[a] - q[b]
            dist = np.sqrt((d * d).sum(1))
            nrm = d / np.maximum(dist, 1e-300)[:, None]
            _, _, ks = ground_penalty(np.maximum(self.radius - dist, 0.0), kc, CONTACT_SMOOTH * self.radius)
            for r_ in range(3):
                for c_ in range(3):
                    v = ks * nrm[:, r_] * nrm[:, c_]
                    for (i, j, sgn) in ((a, a, 1.0), (b, b, 1.0), (a, b, -1.0), (b, a, -1.0)):
                        rows.append(3 * i + r_); cols.append(3 * j + c_); vals.append(sgn * v)
        return sps.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n3, n3))

    def _contact_energy(self, q, pairs, radius, kc, grad=None):
        """Self-contact energy (the C² penalty of :func:`ground_penalty` on the overlap r − d)
        and its gradient added to ``grad``."""
        if not len(pairs):
            return 0.0
        a, b = pairs[:, 0], pairs[:, 1]
        d = q[a] - q[b]
        dist = np.sqrt((d * d).sum(1))
        e, f, _ = ground_penalty(np.maximum(radius - dist, 0.0), kc, CONTACT_SMOOTH * radius)
        if grad is not None:
            g = (-f / np.maximum(dist, 1e-300))[:, None] * d
            np.add.at(grad, a, g)
            np.add.at(grad, b, -g)
        return float(e.sum())

    def energy(self, q, rec, mass, pairs, radius, kc) -> float:
        E = kst.elastic_energy(q, *rec)
        return E + self._external(q, mass, False)[0] + self._contact_energy(q, pairs, radius, kc)

    # ------------------------------------------------------------------ the solve
    def _factor(self, A):
        try:
            # symmetric mode: the pivots stay on the diagonal (H is symmetric; their signs are its
            # inertia), 4× less fill than the unsymmetric default
            self.lu = spla.splu(A.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                                options=dict(SymmetricMode=True))
        except RuntimeError as exc:  # singular: nothing holds some motion
            raise LeafsimError(f"dynamics.integrator = static: the stiffness matrix is singular ({exc}): "
                               "expected a blade held by its springs") from None
        self.factored = A.shape
        self.factorisations += 1

    def _path(self, x0, step, mass):
        """The line search's path x(α): the step's rigid part as an exact rotation about the
        centre of mass (plus its translation), its deformation linearly.  A linear step rotates
        by stretching (a point moves along the tangent, not the arc), so a leaf rolling over its
        contacts, whose Newton model sees no stretch, advanced by tiny steps; along the arc it
        rolls in a few.  Pinned particles stay put (then the path is the linear one)."""
        if not self.free.all() or len(x0) < 3:
            return lambda a: x0 + a * step
        w = mass / mass.sum()
        c = w @ x0
        r = x0 - c
        t = w @ step
        d = step - t
        L = (w[:, None] * np.cross(r, d)).sum(0)
        I = np.eye(3) * float((w * (r * r).sum(1)).sum()) - (w[:, None] * r).T @ r
        try:
            om = np.linalg.solve(I, L)
        except np.linalg.LinAlgError:
            return lambda a: x0 + a * step
        rest = d - np.cross(om, r)  # the deformation part of the step

        def along(a):
            v = a * om
            th = float(np.linalg.norm(v))
            if th < 1e-12:
                return x0 + a * step
            k = v / th
            K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
            R = np.eye(3) + math.sin(th) * K + (1.0 - math.cos(th)) * (K @ K)
            return c + r @ R.T + a * (t + rest)

        return along

    def _predict(self, state, rec, mass, radius, kc) -> None:
        """Start from the secant prediction of the last two equilibria (the drying's path,
        extrapolated linearly in time) when its energy is lower than where the leaf is."""
        if len(self.history) < 2 or not self.predictor:
            return
        (t0, x0), (t1, x1) = self.history
        if state.time <= t1 or t1 <= t0 or x1.shape != state.particle_q.shape:
            return
        q = state.particle_q
        guess = q + (state.time - t1) / (t1 - t0) * (x1 - x0)
        guess[~self.free] = q[~self.free]
        here = self.energy(q, rec, mass, self._contacts(q, radius), radius, kc)
        if self.energy(guess, rec, mass, self._contacts(guess, radius), radius, kc) < here:
            q[:] = guess
            self.predicted += 1

    def _linear_solve(self, A, b):
        """A Δ = b: within one solve, conjugate gradients preconditioned by the solve's last
        factorisation when that was definite (the Hessian changes little between Newton steps)
        while they converge in ``REUSE_CG`` iterations, else a fresh factorisation.  Returns
        (Δ, whether A is taken as positive definite: a fresh factorisation's pivots all
        positive, or CG converged on a definite preconditioner with the same damping)."""
        if getattr(self, "lu", None) is not None and self.factored == A.shape and self.reuse:
            M = spla.LinearOperator(A.shape, self.lu.solve)
            x, info = spla.cg(A, b, rtol=REUSE_RTOL, maxiter=REUSE_CG, M=M)
            if info == 0 and float(x @ b) > 0.0:
                return x, True
        self._factor(A)
        # symmetric permutation, diagonal pivots: A = P L U Pᵀ with U = D Lᵀ, so the signs
        # of U's diagonal are A's inertia (Sylvester)
        definite = bool((self.lu.U.diagonal() > 0.0).all())
        self.reuse = definite  # only a definite factorisation preconditions the next steps
        return self.lu.solve(b), definite

    def _setup(self, state: State):
        """The solve's constants: the elastic records, masses and weights, the ground's and the
        self-contact's stiffness and the contact radius of the shrunk tissue."""
        m = self.model
        rec = self._records(state)
        mass = m.particle_cytosol + state.particle_water
        weight = np.maximum(mass * max(self.g, 1e-3), 1e-300)
        self.delta = PENETRATION * m.thickness
        # the whole leaf's weight on one particle sinks it 1.5 δ (a curled leaf rests on a few)
        self.kg = np.full(self.n, float(weight.sum()) / self.delta)
        shrunk = max(float(np.mean(state.spring_rest[self.dyn.T_springs] / m.spring_rest0[self.dyn.T_springs])), 0.1)
        self.radius = radius = self.dyn.radius * shrunk
        kc = float(np.median(rec[1]))  # contact stiffness: a typical membrane spring's
        return rec, mass, weight, radius, kc

    def _direction(self, H, b, grad, state: State, lam: float):
        """The Newton step (n, 3) from H Δ = b, with the Levenberg–Marquardt damping ``lam``
        raised until the factorisation is definite and the step descends; returns (step,
        slope ∇E·step, the damping used)."""
        free3 = np.repeat(self.free, 3)
        if not self.free.all():
            H = H[free3][:, free3]
            b = b[free3]
        dH = H.diagonal()
        scale = np.maximum(np.abs(dH), 1e-6 * float(np.abs(dH).mean()))
        lev = LEVENBERG * float(np.abs(dH).mean())
        while True:
            A = H + sps.diags(lam * scale + lev, format="csr")
            dx, definite = self._linear_solve(A, b)
            step = np.zeros(3 * self.n)
            step[free3 if not self.free.all() else slice(None)] = dx
            step = step.reshape(self.n, 3)
            slope = float((grad * step).sum())
            if definite and slope < 0.0:
                return step, slope, lam
            # indefinite (the leaf is past a buckling point or tipping over): Levenberg–
            # Marquardt, more of the diagonal until the factorisation is definite and the
            # step descends
            lam = max(10.0 * lam, LAM_MIN)
            self.reuse = False
            self.damped += 1
            if lam > LAM_MAX:
                raise LeafsimError(f"dynamics.integrator = static: no descent direction at frame {state.frame} "
                                   f"(the energy or its derivatives are not finite?): expected a finite state")

    def _line_search(self, q, step, slope, E, parts, rec, mass, pairs, radius, kc) -> float:
        """Move ``q`` along the step's path (:meth:`_path`): backtracking to the Armijo
        condition, or on beyond the full step while the energy keeps falling; returns α."""
        alpha = 1.0
        along = self._path(q.copy(), step, mass)
        # below the energy's rounding (a few ulp of its largest part) a decrease cannot be
        # seen: there the full step is taken (the quadratic model is exact at that scale)
        tiny = -slope < NOISE * sum(abs(x) for x in parts)
        while True:
            q[:] = along(alpha)
            if tiny or self.energy(q, rec, mass, pairs, radius, kc) <= E + ARMIJO * alpha * slope or alpha < 1e-8:
                break
            alpha *= 0.5
        if alpha == 1.0 and not tiny:
            # the model underestimated the step (a soft mode the Hessian does not see, e.g. a
            # leaf rolling over its contacts): go on along it while the energy keeps falling
            e1 = self.energy(q, rec, mass, pairs, radius, kc)
            while alpha < EXPAND:
                q[:] = along(2.0 * alpha)
                e2 = self.energy(q, rec, mass, pairs, radius, kc)
                if e2 >= e1:
                    q[:] = along(alpha)
                    break
                alpha *= 2.0
                e1 = e2
        return alpha

    def _settle(self, state: State) -> None:
        """After a solve: velocities zero, the predictor's history, and the ground's normal
        forces and friction anchors for the next solve."""
        q = state.particle_q
        state.particle_qd[:] = 0.0
        self.history = (self.history + [(state.time, q.copy())])[-2:]
        if self.ground:
            self.normal = np.zeros(self.n)
            below = q[:, 2] < 0.0
            self.normal[below] = ground_penalty(-q[below, 2], self.kg[below], self.delta)[1]
            press = self.normal > 0.0
            self.anchor[press] = q[press, :2]

    def solve(self, state: State) -> SolveInfo:
        """Move ``state``'s particles to the equilibrium nearest where they are (velocities
        zero); update the friction anchors and normal forces for the next solve."""
        t0 = time.perf_counter()
        f0 = self.factorisations
        q = state.particle_q
        if self.history and (state.time <= self.history[-1][0] or self.history[-1][1].shape != q.shape):
            # another leaf, a reset or a rewind: friction and the predictor start afresh
            self.reset()
            self.anchor[:] = q[:, :2]
        rec, mass, weight, radius, kc = self._setup(state)
        res0 = res = math.inf
        it = 0
        # a solve's first step factorises afresh (the rest state moved since the last solve and
        # the old factorisation preconditions it poorly: measured, most such CG attempts failed)
        self.reuse = False
        self._predict(state, rec, mass, radius, kc)
        pairs = self._contacts(q, radius)
        self.trace = []
        lam = 0.0
        while True:
            Ee = kst.elastic(q, *rec, self.smap, self.hmap, self.vmap, self.grad, self.data, True, False)
            Ex, gx, diag = self._external(q, mass, True)
            grad = self.grad + gx
            Ec = self._contact_energy(q, pairs, radius, kc, grad)
            E = Ee + Ex + Ec
            gf = np.where(self.free[:, None], grad, 0.0)
            res = float((np.sqrt((gf * gf).sum(1)) / weight).max())
            if not math.isfinite(res):
                raise LeafsimError(f"dynamics.integrator = static: the forces are not finite at frame {state.frame} "
                                   "(positions or material values): expected a finite state")
            if it == 0:
                res0 = res
            if res <= self.tol or it >= self.max_iter:
                break
            K = sps.bsr_matrix((self.data, self.indices, self.indptr), shape=(3 * self.n, 3 * self.n)).tocsr()
            H = K + self._hessian_extra(diag, pairs, q, kc)
            step, slope, lam = self._direction(H, -grad.reshape(-1), grad, state, lam)
            alpha = self._line_search(q, step, slope, E, (Ee, Ex, Ec), rec, mass, pairs, radius, kc)
            # a full step: trust the Hessian more; a cut one: less
            lam = lam / 3.0 if alpha >= 1.0 else max(4.0 * lam, LAM_MIN)
            if lam < LAM_MIN:
                lam = 0.0
            it += 1
            self.trace.append((res, alpha, E))
            pairs = self._contacts(q, radius)
        self._settle(state)
        self.last = SolveInfo(it, res0, res, E, int((q[:, 2] < 0.0).sum()) if self.ground else 0, len(pairs), time.perf_counter() - t0,
                              res <= self.tol)
        self.log.append((it, self.factorisations - f0, self.last.seconds, res))
        return self.last
