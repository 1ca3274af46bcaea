"""The lamina's excess length: what a drying blade holds in compression, and the sub-grid
crinkle it would take up.

A dried lamina between stiff, barely shrinking veins is left compressed in places: the blade's
triangles, measured against the triangles their springs' rest lengths now make (the shrink
moves those), have a principal stretch below one (docs/drying/README.md, "Where the dried blade
keeps its strain").  A sheet as thin as a lamina cannot carry compression; it buckles and takes
the excess length up in crinkles whose wavelength (millimetres, the areoles and veinlets) is
below any mesh we simulate on.  Whatever their wavelength, a surface z = h(x, y) that takes up
an excess length Δ along a line has ½ ⟨(∂h/∂s)²⟩ = Δ, so its slopes are fixed by the excess
alone: an isotropic crinkle carrying the mean of the two principal directions' excess,
Δ = ½ (max(0, 1 − s₁) + max(0, 1 − s₂)), has an RMS slope √(2Δ) along every direction.  The
excess has directions too: K = Σ max(0, 1 − sₖ) uₖ uₖᵀ over the principal directions uₖ (carried
to the leaf's flat rest plane), ½ tr K = Δ.  A sheet compressed one way and not the other
wrinkles in parallel crests across the compression (tension-field wrinkles), with an RMS slope
√(2 max(0, 1 − s)) along it and none along the crests.  This module computes K per particle
(the renderer draws the slope tensor 2K over seeded fields, ``render.crinkle``); the mechanics
never see it.

While the drying path carries the mechanics (:mod:`leafsim.sim.path`), the leaf's own mesh
only takes the coarse mesh's positions through a smooth prolongation whose fine-scale error is
strain of its own (up to 25 % on a spring); the excess is then the coarse mesh's, prolonged
the same way (and zero on the own mesh's veins).  Imports no OpenGL."""

from __future__ import annotations


import numpy as np

from leafsim.base.errors import LeafsimError
from leafsim.sim.kernels.crinkle import lamina_compression as _kernel
from leafsim.sim.model import LAYER_T, Model, State


def triangle_springs(model: Model) -> np.ndarray:
    """(m, 3) int64: the springs along the sides a–b, b–c, c–a of each of ``model.blade_tri_T``
    (the first spring between the two particles: the triangulation's edge)."""
    ij = np.sort(np.asarray(model.spring_ij, np.int64), axis=1)
    n = np.int64(model.particle_count)
    key = ij[:, 0] * n + ij[:, 1]
    order = np.argsort(key, kind="stable")
    skey = key[order]
    tri = np.asarray(model.blade_tri_T, np.int64)
    out = np.empty(tri.shape, np.int64)
    for k, (u, v) in enumerate(((0, 1), (1, 2), (2, 0))):
        a, b = np.minimum(tri[:, u], tri[:, v]), np.maximum(tri[:, u], tri[:, v])
        want = a * n + b
        pos = np.searchsorted(skey, want)
        pos = np.minimum(pos, len(skey) - 1)
        if len(skey) == 0 or (skey[pos] != want).any():
            raise ValueError("crinkle: a blade triangle's side has no spring")
        out[:, k] = order[pos]
    return out


class _Mesh:
    """What one mesh needs for its compression tensors, made once: its blade triangles, their springs, the
    particles that get none (the main and lateral veins, rods that do not crinkle, and every
    particle off layer T).  Its arrays are only read, so one may serve several threads (the
    window's worker and its drawing thread)."""

    def __init__(self, model: Model):
        self.tri = np.ascontiguousarray(model.blade_tri_T, np.int64)
        self.springs = triangle_springs(model)
        order = np.asarray(model.particle_vein_order)
        self.zero = ((order >= 0) & (order <= 1)) | (np.asarray(model.particle_layer) != LAYER_T)
        self.flat = np.ascontiguousarray(np.asarray(model.particle_rest, np.float64)[:, :2])
        self.n = model.particle_count
        self.s = len(model.spring_ij)

    def compression(self, state: State) -> np.ndarray:
        out = np.empty((self.n, 3))
        q = np.ascontiguousarray(state.particle_q, np.float64)
        rest = np.ascontiguousarray(state.spring_rest, np.float64)
        if q.shape != (self.n, 3) or rest.shape != (self.s,):  # the compiled loop does not check
            raise ValueError(f"crinkle: a state of {q.shape} positions and {rest.shape} rest lengths for a model of "
                             f"{self.n} particles and {self.s} springs")
        _kernel(self.tri, self.springs, q, rest, self.flat, self.zero, out, np.empty(self.n))
        return out


#: particles the carrier test compares (a spread sample: the whole leaf cost 8 ms at 132 k)
CARRIER_SAMPLE = 512


def _prolongation(model: Model, cache: dict) -> tuple:
    """The drying path's fixed transfer coarse → ``model`` (:func:`leafsim.sim.path.transfer_matrix`),
    and its rows at a spread sample of the particles not held where they hang."""
    from leafsim.sim.path import transfer_matrix

    key = ("P", id(model.path))
    if key not in cache:
        P = transfer_matrix(model.path, model)
        free = np.flatnonzero(~np.asarray(model.particle_pinned, bool))
        rows = free[:: max(1, len(free) // CARRIER_SAMPLE)]
        cache[key] = (P, rows, P[rows])
    return cache[key]


def _carried(model: Model, state: State, transfer: tuple) -> bool:
    """The mesh under ``model`` carries its mechanics in ``state``: its positions are exactly
    the coarse mesh's prolonged (:meth:`leafsim.sim.path.DryingPath.step`; the particles held
    where they hang excepted; compared on a spread sample of them).  Read from the state
    itself, not from the parameters, so it holds whatever effects a Simulator runs, after a
    live change of the hand-over level, and on every level of nested paths."""
    P, rows, P_rows = transfer
    q = np.asarray(state.particle_q, np.float64)
    cq = np.asarray(state.path.particle_q, np.float64)
    if cq.shape != (P.shape[1], 3) or q.shape != (P.shape[0], 3):
        raise ValueError(f"crinkle: a state of {q.shape[0]} particles with a path state of {cq.shape[0]} against a "
                         f"transfer of shape {P.shape}")
    return bool(np.allclose(P_rows @ cq, q[rows], rtol=0.0, atol=1e-12))


def lamina_compression(model: Model, state: State, cache: dict | None = None) -> np.ndarray:
    """(n, 3) float64: each particle's compression tensor K over the flat rest plane (its xx,
    xy, yy entries; 0 on the main and lateral veins and off layer T), on the mesh that carries
    the mechanics now, prolonged to ``model``'s particles (entry by entry: the prolongation's
    weights may leave a tensor slightly indefinite, :func:`crinkle_slopes` clips it).  ``cache``
    (a dict the caller keeps per model) holds each mesh's triangles and the prolongations."""
    cache = {} if cache is None else cache
    key = ("mesh", id(model))
    if key not in cache:
        cache[key] = _Mesh(model)
    mesh = cache[key]
    if model.path is not None and state.path is not None:
        transfer = _prolongation(model, cache)
        if _carried(model, state, transfer):
            out = transfer[0] @ lamina_compression(model.path, state.path, cache)
            out[mesh.zero] = 0.0  # the own mesh's veins are rods, whatever the coarse mesh had there
            return out
    return mesh.compression(state)


def excess_of(compression: np.ndarray) -> np.ndarray:
    """(n,) the excess length Δ = ½ tr K (≥ 0) of compression tensors (n, 3)."""
    K = np.asarray(compression, np.float64)
    return np.maximum(0.5 * (K[:, 0] + K[:, 2]), 0.0)


def lamina_excess(model: Model, state: State, cache: dict | None = None) -> np.ndarray:
    """(n,) float64: each particle's excess length Δ (0 = no compression; 0 on the main and
    lateral veins and off layer T): ½ tr of :func:`lamina_compression`."""
    return excess_of(lamina_compression(model, state, cache))


def principal(tensors: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(larger eigenvalue, smaller eigenvalue, angle of the larger's direction in radians) of
    symmetric 2 × 2 tensors given as (n, 3) rows xx, xy, yy."""
    T = np.asarray(tensors, np.float64)
    half = 0.5 * (T[:, 0] + T[:, 2])
    dev = np.sqrt(0.25 * (T[:, 0] - T[:, 2]) ** 2 + T[:, 1] ** 2)
    return half + dev, half - dev, 0.5 * np.arctan2(2.0 * T[:, 1], T[:, 0] - T[:, 2])


def crinkle_slopes(compression: np.ndarray, gain: float = 1.0) -> np.ndarray:
    """(n, 3) float64: the crinkle's slope tensor S = gain² · 2K (xx, xy, yy; rad²), its
    eigenvalues clipped at 0: along a direction u the crinkle's mean squared slope is uᵀSu, so
    an isotropic excess Δ draws √(2Δ) along every direction and a one-way compression
    max(0, 1 − s) draws √(2 (1 − s)) across the crests and nothing along them."""
    big, small, ang = principal(compression)
    big, small = 2.0 * gain * gain * np.maximum(big, 0.0), 2.0 * gain * gain * np.maximum(small, 0.0)
    c, s = np.cos(ang), np.sin(ang)
    return np.stack([big * c * c + small * s * s, (big - small) * c * s, big * s * s + small * c * c], 1)


def crinkle_stats(model: Model, state: State) -> dict:
    """The lamina's excess length over the blade's layer-T particles off the main and lateral
    veins, weighted by their area: mean and p10 / p50 / p90 / p99 in per cent, the share over
    0.5 %, the RMS slope √(2Δ) of the crinkle it draws, in degrees, and how one-sided the
    compression is (:func:`one_way_share`; what docs/drying/README.md tabulates per species)."""
    K = lamina_compression(model, state)
    d = excess_of(K)
    order = np.asarray(model.particle_vein_order)
    lamina = model.blade_T & ~((order >= 0) & (order <= 1))
    w = np.asarray(model.particle_area, np.float64)[lamina]
    x = d[lamina]
    if not len(x) or w.sum() <= 0.0:
        raise LeafsimError("crinkle: the blade has no lamina off its veins to measure")
    srt = np.argsort(x, kind="stable")
    cw = np.cumsum(w[srt]) / w.sum()
    pct = [float(x[srt][min(int(np.searchsorted(cw, q / 100.0)), len(x) - 1)]) for q in (10, 50, 90, 99)]
    return {"crinkle_excess_pct": round(100.0 * float(np.average(x, weights=w)), 3),
            "crinkle_excess_p10_p50_p90_p99_pct": [round(100.0 * v, 3) for v in pct],
            "crinkle_share_above_half_percent": round(float(w[x > 0.005].sum() / w.sum()), 3),
            "crinkle_slope_rms_deg": round(float(np.degrees(np.sqrt(2.0 * np.average(x, weights=w)))), 2),
            "crinkle_one_way_share": one_way_share(K[lamina], w)}


def one_way_share(compression: np.ndarray, weights: np.ndarray) -> float:
    """How one-sided the compression is, 0..1: the excess-weighted mean of (k₁ − k₂) / (k₁ + k₂)
    over the tensors' eigenvalues (1: every bit of it one way, tension-field wrinkles; 0: the
    same both ways, an isotropic crinkle)."""
    big, small, _ = principal(compression)
    big, small = np.maximum(big, 0.0), np.maximum(small, 0.0)
    tot = big + small
    wt = np.asarray(weights, np.float64) * tot
    if wt.sum() <= 0.0:
        return 0.0
    return round(float(np.sum(wt * (big - small) / np.where(tot > 0.0, tot, 1.0)) / wt.sum()), 3)
