"""Experiment: a coarse-space correction of the own mesh's XPBD after the drying path's hand-over.

XPBD's Gauss–Seidel sweeps remove short-wavelength error in a few frames and long-wavelength
error slowly; after the hand-over the leaf's own mesh creeps for hundreds of frames from the
coarse mesh's shape towards its own (docs/performance.md).  Here, every K own-mesh frames, the
leaf's positions take Newton steps of the static energy (leafsim.sim.equilibrium: the same
elastic model, gravity, ground, friction and self-contact) restricted to the span of the drying
path's prolongation P (coarse → own): minimise E(x + P δ) over δ, a Galerkin coarse-space
correction (the two-level idea of multigrid and MGPBD, on the energy), with a line search on E.
The XPBD frames in between smooth the short wavelengths.

``space=modes`` takes instead the span of the K softest vibration modes of the energy's Hessian
at the correction (H v = λ M v, the lowest λ by shift-invert Lanczos; recomputed every
``refresh`` corrections and between refreshes used as a Ritz basis with the current Hessian):
the soft, nearly isometric bending modes, along which a step does not strain the membrane,
where the prolongation's span does (a coarse mesh's bending interpolated onto the fine one
stretches it: membrane locking).

    python tools/coarse_correction.py run maple OUT.pkl [every=32] [newton=3] [handover=0.15]
    python tools/coarse_correction.py run maple OUT.pkl space=modes k=24 refresh=4
    python tools/own_phase_settings.py score REF.pkl OUT.pkl    # scored as that tool's runs
"""

from __future__ import annotations

import pickle
import sys
import time

import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spla

from leafsim.config.species import get_species
from leafsim.measure.accuracy import DRY_WATER, SETTLE
from leafsim.pipeline import build_leaf, leaf_shape
from leafsim.sim.effects.dynamics import Dynamics
from leafsim.sim.kernels import static as kst
from leafsim.sim.metrics import Probe
from leafsim.sim.run import Run


class CoarseCorrection:
    """Newton steps of the static energy in the span of P (n_f × n_c), for one model."""

    def __init__(self, model, params, effects, P, space="coarse", k=24, refresh=4):
        self.model = model
        self.space, self.k, self.refresh = space, k, refresh
        self.V = None
        self.calls = 0
        self.dyn = Dynamics(model)
        self.dyn.configure(params.with_overrides({"dynamics.integrator": "static"}), effects)
        self.eq = self.dyn.equilibrium
        self.P3 = sps.kron(P, sps.identity(3), format="csr")
        self.P3T = self.P3.T.tocsr()
        self.log = []

    def __call__(self, state, newton: int) -> None:
        eq, n = self.eq, self.model.particle_count
        t0 = time.perf_counter()
        rec, mass, weight, radius, kc = eq._setup(state)
        q = state.particle_q
        # friction: particles on the ground stick where they are, pressed by their weight
        eq.anchor = q[:, :2].copy()
        eq.normal = np.where(q[:, 2] <= eq.delta, mass * eq.g, 0.0)
        pairs = eq._contacts(q, radius)
        res0 = None
        for it in range(newton):
            Ee = kst.elastic(q, *rec, eq.smap, eq.hmap, eq.vmap, eq.grad, eq.data, True, True)
            Ex, gx, diag = eq._external(q, mass, True)
            grad = eq.grad + gx
            Ec = eq._contact_energy(q, pairs, radius, kc, grad)
            E = Ee + Ex + Ec
            res = float((np.sqrt((grad * grad).sum(1)) / weight).max())
            if res0 is None:
                res0 = res
            K = sps.bsr_matrix((eq.data, eq.indices, eq.indptr), shape=(3 * n, 3 * n)).tocsr()
            H = K + eq._hessian_extra(diag, pairs, q, kc)
            if self.space == "modes":
                step = self._modal_step(H, grad, mass, it == 0)
            else:
                A = (self.P3T @ H @ self.P3).tocsc()
                b = -(self.P3T @ grad.reshape(-1))
                d = A.diagonal()
                A = A + sps.diags(1e-8 * float(np.abs(d).mean()) + 1e-6 * np.abs(d), format="csc")
                lu = spla.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options=dict(SymmetricMode=True))
                step = (self.P3 @ lu.solve(b)).reshape(n, 3)
            slope = float((grad * step).sum())
            if not slope < 0.0:
                break
            alpha = eq._line_search(q, step, slope, E, (Ee, Ex, Ec), rec, mass, pairs, radius, kc)
            pairs = eq._contacts(q, radius)
        state.particle_qd[:] = 0.0
        self.calls += 1
        self.log.append((res0, it + 1, time.perf_counter() - t0))

    def _modal_step(self, H, grad, mass, first: bool):
        """The Newton step of the energy restricted to the span of the softest modes: with the
        Ritz values of the current Hessian in that span, |λ| floored at 1e-6 of the largest
        (a buckled state's negative curvature is stepped down, not up)."""
        n3 = H.shape[0]
        if first and (self.V is None or self.calls % self.refresh == 0):
            m3 = np.repeat(mass, 3)
            d = np.abs(H.diagonal())
            sigma = -1e-9 * float((d / m3).mean())
            _, self.V = spla.eigsh(H.tocsc(), k=self.k, M=sps.diags(m3, format="csc"), sigma=sigma, which="LM")
        V = self.V
        A = V.T @ (H @ V)
        A = 0.5 * (A + A.T)
        lam, U = np.linalg.eigh(A)
        lam = np.maximum(np.abs(lam), 1e-6 * float(np.abs(lam).max()))
        y = U @ ((U.T @ (V.T @ -grad.reshape(-1))) / lam)
        return (V @ y).reshape(n3 // 3, 3)


def run(species: str, out: str, args: list[str]) -> None:
    opts = {"every": 32, "newton": 3, "handover": None, "space": "coarse", "k": 24, "refresh": 4, "expand": None}
    for a in args:
        k, _, v = a.partition("=")
        opts[k] = float(v) if k == "handover" else v if k == "space" else int(v)
    if opts["expand"] is not None:  # the line search's longest step, × the Newton step (the solver's: 64)
        import leafsim.sim.equilibrium as equilibrium
        equilibrium.EXPAND = float(opts["expand"])
    sp = get_species(species)
    over = {"effects.colour": False}
    if opts["handover"] is not None:
        over["dynamics.handover"] = opts["handover"]
    base = sp.params.with_overrides(over)
    model = build_leaf(sp, base, 0).model
    probe = Probe(leaf_shape(sp, sp.params))
    r = Run(model, base, seed=0)
    corr = CoarseCorrection(model, base, r.sim.effects, r.sim._path.P, opts["space"], opts["k"], opts["refresh"])
    t0 = time.process_time()
    n, handover, cpu_path, own = 0, None, float("nan"), 0

    def frame():
        nonlocal n, handover, cpu_path, own
        r.step()
        n += 1
        if handover is None and not r.sim.on_path:
            handover, cpu_path = n, time.process_time() - t0
        if handover is not None:
            if own % opts["every"] == 0 and opts["every"] > 0:
                corr(r.state, opts["newton"])
            own += 1

    while model.water_fraction(r.state.particle_water) > DRY_WATER:
        frame()
    cpu_dry = time.process_time() - t0
    at_dry = probe.fields(model, r.state)
    dry_frames = n
    for _ in range(int(np.ceil(SETTLE * dry_frames)) - dry_frames):
        frame()
    end = probe.fields(model, r.state)
    cpu = time.process_time() - t0
    label = " ".join(args) or "every=32 newton=3"
    with open(out, "wb") as f:
        pickle.dump({"species": species, "level": "coarse correction " + label, "particles": model.particle_count,
                     "dry_frames": dry_frames, "handover": handover, "cpu_path": cpu_path, "cpu_dry": cpu_dry,
                     "cpu": cpu, "dry": at_dry, "end": end, "log": corr.log}, f)
    secs = sum(s for _, _, s in corr.log)
    print(f"{out}: hand-over at frame {handover} ({cpu_path:.1f} s CPU), 2 % water at frame {dry_frames} "
          f"({cpu_dry:.1f} s), end {cpu:.1f} s; {len(corr.log)} corrections, {secs:.1f} s wall in them, first residual "
          f"{corr.log[0][0]:.3g} × weight, last {corr.log[-1][0]:.3g}; end: margin lift {end['margin_lift']:.4f}, "
          f"3D {end['area_3d']:.4f}, top-down {end['area_top']:.4f}")


if __name__ == "__main__":
    a = sys.argv[1:]
    if len(a) >= 3 and a[0] == "run":
        run(a[1], a[2], a[3:])
    else:
        sys.exit("usage: python tools/coarse_correction.py run SPECIES OUT.pkl [every=N] [newton=N] [handover=W]")
