"""The drying path on a coarser mesh (``dynamics.path``): the blade's mechanics runs on a
coarser mesh of the same leaf while most of the water leaves, and the leaf's own mesh takes
over for the rest (``dynamics.handover``).

Drying is quasi-static: the dried shape depends on the path only through where the lobes
buckle and set, which a coarser mesh follows, while the shape's detail needs the leaf's own
mesh only at the end (docs/performance.md, "Handing over earlier": with the last 15 % of the
water dried on the own mesh, maple's dried shape is as close to the converged reference as the
direct run's, for 2.5–3.3× less CPU).

During the path phase (the leaf's water fraction above the hand-over level) every frame:

1. osmosis and shrink run on the leaf's own mesh as always (its water, rest lengths and
   plastic angles stay its own, so nothing needs carrying over at the hand-over);
2. the coarse mesh takes the own mesh's relative water field (restricted by a fixed matrix),
   shrinks and steps its mechanics (its substeps and inertia scaling from ``--quality draft``);
3. the own mesh's positions and velocities are the coarse ones prolonged by a fixed matrix.

Both matrices are moving-least-squares affine fits over the 12 nearest particles of the other
mesh in the rest state (both layers, so the fit spans the thickness) of the same part, stalk or
blade: exact for any deformation affine on each part, so a rigid motion or a uniform shrink carries over unchanged.  Water only falls,
so the phase is a function of the state: a resumed run picks up where it was.

Example
-------
>>> model = build_leaf(sp, ParamSet({"dynamics.path": "draft"}), seed=0).model   # doctest: +SKIP
>>> model.path.particle_count < model.particle_count                                # doctest: +SKIP
True
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps
from scipy.spatial import cKDTree

from leafsim.config.presets import QUALITY
from leafsim.sim.kernels.transfer import prolong_pair
from leafsim.sim.model import Model, State

#: neighbours of each MLS fit
NEIGHBOURS = 12
#: the quality level whose mesh and solver settings a ``draft`` path uses
PATH_LEVELS = {"draft": "draft", "fine": "fine"}
#: the effects the path mesh runs (when the leaf's simulator runs them)
PATH_EFFECTS = ("shrink", "pbd", "gravity", "bending", "ground", "self_collision")


def _part(model: Model) -> np.ndarray:
    """Which part each particle belongs to: 1 the stalk, 0 the blade."""
    if model.particle_petiole is None:
        return np.zeros(model.particle_count, np.int8)
    return model.particle_petiole.astype(np.int8)


def transfer_matrix(src: Model, dst: Model, k: int = NEIGHBOURS) -> sps.csr_matrix:
    """(n_dst, n_src) matrix T with x_dst = T x_src: per ``dst`` particle the value at its rest
    position of the affine least-squares fit (Gaussian weights) over its k nearest ``src``
    particles of the same part (stalk or blade: a fit across the thin stalk where it meets the
    blade bent it with the blade, and a swinging maple's stalk springs then read 115 %
    stretched) in the rest state.  Rows sum to 1 and reproduce affine fields exactly."""
    ps, pd = _part(src), _part(dst)
    parts = [(np.flatnonzero(ps == v), np.flatnonzero(pd == v)) for v in (0, 1)]
    if any(len(d) and len(s) < 4 for s, d in parts):  # a part too small to fit: fit over everything
        return _fit(src.particle_rest, dst.particle_rest, k)
    out = sps.csr_matrix((dst.particle_count, src.particle_count))
    for s_idx, d_idx in parts:
        if not len(d_idx):
            continue
        sub = _fit(src.particle_rest[s_idx], dst.particle_rest[d_idx], k).tocoo()
        out = out + sps.csr_matrix((sub.data, (d_idx[sub.row], s_idx[sub.col])), shape=out.shape)
    return out.tocsr()


def _fit(Xs: np.ndarray, Xd: np.ndarray, k: int) -> sps.csr_matrix:
    """The affine least-squares transfer from points ``Xs`` to points ``Xd`` (see
    :func:`transfer_matrix`)."""
    k = min(k, len(Xs))
    d, idx = cKDTree(Xs).query(Xd, k=k)
    h = d[:, -1:] + 1e-12
    w = np.exp(-(d / (0.5 * h)) ** 2)                                   # (n, k)
    A = np.concatenate([np.ones((len(Xd), k, 1)), (Xs[idx] - Xd[:, None, :]) / h[:, :, None]], axis=2)  # (n, k, 4)
    AtW = np.transpose(A, (0, 2, 1)) * w[:, None, :]                    # (n, 4, k)
    M = AtW @ A + 1e-9 * np.eye(4)
    vals = np.linalg.solve(M, AtW)[:, 0, :]                             # first row: the value at Xd
    rows = np.repeat(np.arange(len(Xd)), k)
    return sps.csr_matrix((vals.ravel(), (rows, idx.ravel())), shape=(len(Xd), len(Xs)))


def path_params(params, level: str):
    """The parameters the path mesh runs with: the leaf's, with the mesh and solver settings of
    quality ``level`` but the leaf's own Δt (both meshes keep one clock), no osmosis (its water
    comes from the own mesh) and no colour.  The ``fine`` level's mesh dries as the default
    leaf does, on its own drying path (the draft mesh) handed over at the default level and
    finished as ``dynamics.finish`` says: ``dynamics.handover`` is the leaf's own mesh's."""
    from leafsim.config.params import PARAMS

    return params.with_overrides({**QUALITY[PATH_LEVELS[level]], "dynamics.dt": params["dynamics.dt"],
                                  "dynamics.handover": PARAMS["dynamics.handover"].default,
                                  "effects.osmosis": False, "effects.colour": False})


#: the solver settings the drying path stands in for: with any other (a user asking for real
#: inertia, more substeps or iterations) the leaf's own mesh carries the mechanics throughout
PATH_SOLVER_KEYS = ("dynamics.substeps", "dynamics.iterations", "dynamics.tolerance", "dynamics.mass_scaling",
                    "dynamics.substep_scaling", "dynamics.integrator")


def path_allowed(params) -> bool:
    """The drying path runs: ``dynamics.path`` is not ``own`` and the solver settings are the
    default quality's (the path replaces exactly those)."""
    from leafsim.config.params import PARAMS

    return params["dynamics.path"] != "own" and all(params[k] == PARAMS[k].default for k in PATH_SOLVER_KEYS)


#: an own-mesh frame of a static finish (dynamics.finish = static), in ms: a frame's osmosis,
#: shrink and colour, and an equilibrium solve shared by dynamics.static_every frames; against a
#: drying-path frame (measured on oak: 0.5, 340 and 1.7 ms; docs/performance.md, "A static finish")
FINISH_FRAME_MS, FINISH_SOLVE_MS, PATH_FRAME_MS = 0.5, 340.0, 1.7


def static_finish_cost(every: int) -> float:
    """How many drying-path frames an own-mesh frame of a static finish costs (progress bars)."""
    return (FINISH_FRAME_MS + FINISH_SOLVE_MS / max(int(every), 1)) / PATH_FRAME_MS
#: a hinge and a thickness volume cost this many springs (docs/performance.md: 2.4–2.7 and 1.9–2.6)
HINGE_COST, VOLUME_COST = 2.5, 2.0


def frame_cost(model: Model, params) -> float:
    """A dynamics frame's cost in spring projections: constraints × substeps × iterations (the
    dynamics are most of a frame's time on either mesh)."""
    from leafsim.sim.effects.dynamics import effective_substeps

    n = len(model.spring_ij) + HINGE_COST * len(model.hinge_idx) + VOLUME_COST * len(model.vol_idx)
    return float(n) * effective_substeps(params) * int(params["dynamics.iterations"])


def work_done(lost: float, lost_end: float, handover, ratio) -> float:
    """The share of a drying's work done once ``lost`` of the water is gone, of the work to
    ``lost_end``: frames come at about the same rate per unit of water lost all along, and
    each one costs ``ratio`` times more once the own mesh has taken over (below ``handover``
    of the water left; None = no drying path, the work is the water lost).  Nested paths
    (``dynamics.path = fine``) give sequences, the leaf's own mesh's first: ``handover[k]`` and
    ``ratio[k]`` are the k-th path's (a frame on the mesh above it costs ``ratio[k]`` of one on
    it), and the mesh that carries a frame is the first whose path has handed over."""
    lost, lost_end = max(lost, 0.0), max(lost_end, 1e-12)
    if handover is None:
        return min(lost / lost_end, 1.0)
    hs, rs = np.atleast_1d(np.asarray(handover, float)), np.atleast_1d(np.asarray(ratio, float))
    if rs.size != hs.size or (rs <= 0.0).any():
        return min(lost / lost_end, 1.0)
    # a frame's cost on mesh j (0 = own) against one on the coarsest: the ratios below it
    cost = np.append(np.cumprod(rs[::-1])[::-1], 1.0)

    def carrier(left: float) -> int:
        below = np.flatnonzero(left <= hs)
        return int(below[0]) if below.size else hs.size

    cuts = np.unique(np.clip(np.concatenate([[0.0], 1.0 - hs, [1.0]]), 0.0, 1.0))

    def work(x: float) -> float:
        total = 0.0
        for a, b in zip(cuts[:-1], cuts[1:]):
            if x <= a:
                break
            hi = min(x, b)
            total += (hi - a) * cost[carrier(1.0 - 0.5 * (a + hi))]
        return total

    return float(min(max(work(lost) / max(work(lost_end), 1e-12), 0.0), 1.0))


class DryingPath:
    """Steps the coarse mesh of ``model.path`` for a Simulator of ``model``.

    Parameters
    ----------
    model : Model with ``path`` set; params : the leaf's ParamSet; sim : a Simulator of
    ``model.path`` with :func:`path_params` and ``effects``, the :data:`PATH_EFFECTS` the leaf
    runs (a live change of them makes a new one).
    """

    def __init__(self, model: Model, params, sim, effects: tuple = (), static_finish: bool = False):
        self.model, self.coarse = model, model.path
        self.effects = tuple(effects)
        self.P = transfer_matrix(self.coarse, model)        # coarse → own (positions, velocities)
        # its CSR arrays as the compiled prolongation takes them (one signature, compiled by the warm-up)
        self._P = (self.P.indptr.astype(np.int64), self.P.indices.astype(np.int64), self.P.data.astype(np.float64))
        self.R = transfer_matrix(model, self.coarse)        # own → coarse (relative water)
        self.sim = sim
        self._configure(params, static_finish)

    def _configure(self, params, static_finish: bool = False) -> None:
        self.handover = float(params["dynamics.handover"])
        #: how many times a frame on the own mesh costs one on the coarse mesh (progress bars);
        #: a static finish's is against a draft-path frame whatever the coarse mesh (``per_draft``)
        self.per_draft = bool(static_finish)
        if static_finish:  # equilibria every few frames after the hand-over (dynamics.finish)
            self.cost_ratio = static_finish_cost(params["dynamics.static_every"])
        else:
            self.cost_ratio = frame_cost(self.model, params) / max(frame_cost(self.coarse, self.sim.params), 1.0)
        # hanging from the petiole: the own mesh's pinned particles stay exactly where they are
        hanging = params["dynamics.scene"] == "hanging" and self.model.particle_pinned.any()
        self.pinned = np.flatnonzero(self.model.particle_pinned) if hanging else None

    def set_params(self, params, coarse_params, static_finish: bool = False) -> None:
        self.sim.set_params(coarse_params)
        self._configure(params, static_finish)

    def active(self, state: State) -> bool:
        """The coarse mesh carries the mechanics: the leaf still holds more than the hand-over
        share of its water."""
        return state.path is not None and self.model.water_fraction(state.particle_water) > self.handover

    def sync(self, state: State) -> None:
        """Put the coarse mesh where the own mesh is (used when the path phase starts again,
        after a live change of the hand-over level)."""
        cs = state.path
        cs.particle_q[:] = self.R @ state.particle_q
        cs.particle_qd[:] = self.R @ state.particle_qd
        self.sim.sync_path(cs)  # and the path mesh's own path mesh (dynamics.path = fine)

    def step(self, state: State) -> dict:
        """One frame of the coarse mechanics; the own mesh takes its positions and velocities."""
        cs = state.path
        rel = self.R @ (state.particle_water / np.maximum(self.model.particle_water0, 1e-300))
        np.multiply(np.clip(rel, 0.0, 1.0), self.coarse.particle_water0, out=cs.particle_water)
        ms = self.sim.step(cs)
        if cs.particle_q.shape[0] != self.P.shape[1] or state.particle_q.shape[0] != self.P.shape[0]:
            raise ValueError(f"drying path: coarse {cs.particle_q.shape[0]} and own {state.particle_q.shape[0]} particles "
                             f"against a transfer of shape {self.P.shape}")  # the compiled loop does not check
        prolong_pair(*self._P, cs.particle_q, cs.particle_qd, state.particle_q, state.particle_qd)
        if self.pinned is not None:
            state.particle_q[self.pinned] = self.model.particle_rest[self.pinned]
            state.particle_qd[self.pinned] = 0.0
        return ms
