"""The spring race: ten distance-projection passes over the same springs by every contender —
ours (production), the float32 ceiling, two parallel variants, a numpy Jacobi baseline and the
optional peers (warp, Taichi) — all to the same residual."""

from __future__ import annotations

import numpy as np

from leafsim.config.params import ParamSet
from leafsim.measure.models import EFFECTS, PASSES, bench_params
from leafsim.measure.timing import interleaved, load_average, summary
from leafsim.sim.model import Model


# ----------------------------------------------------------------------------- spring race
class SpringProblem:
    """The race's job on one model: perturbed positions (2 % of the spacing) of the rest leaf,
    the fresh leaf's inverse masses and the default compliances, springs in production order."""

    def __init__(self, model: Model, params: ParamSet | None = None):
        from leafsim.sim.effects.dynamics import Dynamics
        from leafsim.sim.kernels import pbd as kp

        params = params or bench_params(model)
        self.model = model
        d = Dynamics(model)
        d.configure(params, EFFECTS)
        st = model.state()
        d.gather(st)
        self.ij = d.sij
        self.rec = d.srec.copy()
        self.rest = self.rec[:, 0].copy()
        self.cs = model.spring_colour_start
        rng = np.random.default_rng(0)
        self.q0 = st.particle_q + rng.normal(0, 0.02 * model.spacing, st.particle_q.shape)
        self.residual0 = float(kp.residual(self.q0, self.ij, self.rest))

    def residual(self, q) -> float:
        from leafsim.sim.kernels import pbd as kp

        return float(kp.residual(np.ascontiguousarray(q, np.float64), self.ij, self.rest))


class _Kernel:
    """A numba contender: positions/lambdas of ``dtype`` reset from the problem; ``fn(q, lam)``."""

    def __init__(self, prob: SpringProblem, fn, dtype=np.float64):
        self.q0 = prob.q0.astype(dtype)
        self.q = self.q0.copy()
        self.lam = np.zeros(len(prob.ij), dtype)
        self.fn = fn

    def reset(self):
        self.q[:] = self.q0
        self.lam[:] = 0.0

    def run(self, npass=PASSES):
        self.fn(self.q, self.lam)

    def positions(self):
        return self.q.astype(np.float64)


class _NumpyJacobi:
    """Vectorised numpy: Jacobi passes with bincount gathers, relaxation 1.5 / degree."""

    def __init__(self, prob: SpringProblem):
        self.prob = prob
        n = len(prob.q0)
        self.i, self.j = prob.ij[:, 0].astype(np.int64), prob.ij[:, 1].astype(np.int64)
        self.deg = np.maximum(np.bincount(np.r_[self.i, self.j], minlength=n), 1).astype(float)
        self.q = prob.q0.copy()

    def reset(self):
        self.q[:] = self.prob.q0

    def run(self, npass=PASSES):
        r, i, j, q, n = self.prob.rec, self.i, self.j, self.q, len(self.q)
        for _ in range(npass):
            d = q[i] - q[j]
            ln = np.sqrt((d * d).sum(1))
            f = ((r[:, 0] - ln) * r[:, 2] / np.maximum(ln, 1e-12))[:, None] * d
            for k in range(3):
                q[:, k] += 1.5 * (np.bincount(i, f[:, k] * r[:, 3], n) - np.bincount(j, f[:, k] * r[:, 4], n)) / self.deg

    def positions(self):
        return self.q


def spring_contenders(prob: SpringProblem, peers: bool = True, numpy: bool = True, parallel: bool = True) -> dict:
    """name → contender (reset(), run(), positions()).  The first is ours (production)."""
    from leafsim.measure import contenders as kc
    from leafsim.sim.kernels import pbd as kp

    ij, rec, cs = prob.ij, prob.rec, prob.cs
    ij32, rec32 = ij.astype(np.int32), rec.astype(np.float32)
    perm, bs = kc.block_order(ij, prob.model.particle_rest)
    bij, brec = np.ascontiguousarray(ij[perm]), np.ascontiguousarray(rec[perm])
    out = {
        "ours (f64, serial)": _Kernel(prob, lambda q, lam: kp.springs_passes(q, ij, rec, lam, PASSES, 0.0)),
        "ceiling (f32, serial)": _Kernel(prob, lambda q, lam: kp.springs_passes(q, ij32, rec32, lam, PASSES, 0.0),
                                         np.float32),
    }
    if parallel:
        out["coloured parallel (before)"] = _Kernel(prob, lambda q, lam: kc.coloured_passes(q, ij, rec, lam, cs, 2, PASSES))
        out["2-block parallel"] = _Kernel(prob, lambda q, lam: kc.block_passes(q, bij, brec, lam, bs, PASSES))
    if numpy:
        out["numpy Jacobi"] = _NumpyJacobi(prob)
    if peers:
        from leafsim.measure.peers import available

        for name, Peer in available().items():
            out[name] = _PeerAdapter(Peer(prob.q0, ij, rec, cs))
    return out


class _PeerAdapter:
    def __init__(self, peer):
        self.peer = peer
        self.reset = peer.reset
        self.positions = peer.positions

    def run(self, npass=PASSES):
        self.peer.run(npass)


def spring_race(model: Model, rounds: int = 30, peers: bool = True, numpy: bool = True, parallel: bool = True) -> list[dict]:
    """Race every contender on ``model``'s springs; rows with median/p90 ms, ratio to ours,
    ns per spring, the residual after the passes and the largest distance of its positions
    from ours (in mesh spacings)."""
    prob = SpringProblem(model)
    cons = spring_contenders(prob, peers, numpy, parallel)
    load = load_average()
    times = interleaved({k: (c.reset, c.run) for k, c in cons.items()}, rounds)
    ours = next(iter(cons))
    for c in cons.values():
        c.reset()
        c.run()
    q_ours = cons[ours].positions()
    rows = []
    for k, c in cons.items():
        q = c.positions()
        rows.append({"contender": k, **summary(times[k]), "residual0": prob.residual0, "residual": prob.residual(q),
                     "agree": float(np.abs(q - q_ours).max() / model.spacing),
                     "ns_per_spring": float(np.median(times[k])) * 1e6 / PASSES / model.spring_count})
    base = rows[0]["median_ms"]
    for r in rows:
        r["ratio"] = r["median_ms"] / base
        r["load"] = load
    return rows
