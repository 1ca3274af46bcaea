"""The local vein direction at every bending hinge, for the anisotropic bilayer curl.

A drying lamina does not shrink the same in every direction: the veins and the cells and
fibres aligned with them hold their length, the tissue between them gives way across them.
So the bilayer's curl is strongest *across* the veins — the blade rolls about axes that run
along its main and lateral veins — and weak along them.  A palmate lobe then cups about its
own main vein instead of the whole leaf rolling into one tube (docs/method.md §6).

The direction field is the orientation tensor of the ``NEIGHBOURS`` main and lateral vein
segments nearest a point (the veins resampled at ``SEGMENT`` × the leaf length), weighted by
segment length × vein width × a Gaussian of the distance whose width is the distance to the
nearest such vein plus ``BLEND`` × the leaf length: it follows the nearest vein closely and
blends smoothly where two veins meet.  Every length in it is a length of the leaf, not of
the mesh, so the field converges under refinement (tests/test_veinframe.py).  Its principal
direction is t and its coherence c = (λ₁ − λ₂) / (λ₁ + λ₂) ∈ [0, 1] (0 where the veins nearby
disagree).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from leafsim.sim.model import Model

#: veins that steer the curl: main (0) and lateral (1), the orders that are stiff rods
FIELD_MAX_ORDER = 1
#: the vein chains are resampled into segments of this length × leaf length (≈ 1.2 mm on a
#: 12 cm leaf), so the field sees the same segments whatever the mesh spacing
SEGMENT = 0.01
#: segments considered per point (the nearest; 64 × 0.01 L of vein)
NEIGHBOURS = 64
#: blend length of the field, × leaf length (≈ 5 mm on a 12 cm leaf)
BLEND = 0.04
#: points per block of the neighbour query (bounds the temporary arrays: 16 k × 64)
CHUNK = 16384


def _resample(p: np.ndarray, w: np.ndarray, step: float):
    """Points and widths along polyline ``p`` at arc-length spacing ≈ ``step`` (ends kept)."""
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    if arc[-1] <= 0.0:
        return p[:1], w[:1]
    s = np.linspace(0.0, arc[-1], max(int(np.ceil(arc[-1] / step)), 1) + 1)
    return np.column_stack([np.interp(s, arc, p[:, 0]), np.interp(s, arc, p[:, 1])]), np.interp(s, arc, w)


def vein_segments(model: Model, max_order: int = FIELD_MAX_ORDER):
    """(midpoints (s,2), unit directions (s,2), length × width (s,)) of the model's vein
    chains up to ``max_order`` in rest coordinates, resampled at ``SEGMENT`` × the leaf length
    (the chains themselves follow the mesh spacing)."""
    xy = model.particle_rest[:, :2]
    step = SEGMENT * model.length
    mids, dirs, wts = [], [], []
    for v in range(len(model.vein_order)):
        if model.vein_order[v] > max_order:
            continue
        lo, hi = int(model.vein_start[v]), int(model.vein_start[v + 1])
        if hi - lo < 2:
            continue
        p, w = _resample(xy[model.vein_particles[lo:hi]], model.vein_width[lo:hi], step)
        d = p[1:] - p[:-1]
        ln = np.linalg.norm(d, axis=1)
        ok = ln > 0
        mids.append(0.5 * (p[1:] + p[:-1])[ok])
        dirs.append(d[ok] / ln[ok, None])
        wts.append((ln * 0.5 * (w[1:] + w[:-1]))[ok])
    if not mids:
        return np.empty((0, 2)), np.empty((0, 2)), np.empty(0)
    return np.vstack(mids), np.vstack(dirs), np.concatenate(wts)


def vein_field(model: Model, points: np.ndarray):
    """(t (p,2) unit vein direction, c (p,) coherence) at ``points`` (p,2) [m]; c = 0 and
    t = (1, 0) where the model has no main or lateral veins."""
    pts = np.asarray(points, float).reshape(-1, 2)
    mids, dirs, wts = vein_segments(model)
    t = np.zeros((len(pts), 2))
    t[:, 0] = 1.0
    c = np.zeros(len(pts))
    if len(mids) == 0 or len(pts) == 0:
        return t, c
    k = min(NEIGHBOURS, len(mids))
    tree = cKDTree(mids)
    txx, txy, tyy = (np.zeros(len(pts)) for _ in range(3))
    for lo in range(0, len(pts), CHUNK):
        dist, idx = tree.query(pts[lo:lo + CHUNK], k=k)
        dist = dist.reshape(-1, k)
        idx = idx.reshape(-1, k)
        width = dist[:, :1] + BLEND * model.length
        g = wts[idx] * np.exp(-(dist / width) ** 2)
        dx, dy = dirs[idx, 0], dirs[idx, 1]
        txx[lo:lo + CHUNK] = (g * dx * dx).sum(1)
        txy[lo:lo + CHUNK] = (g * dx * dy).sum(1)
        tyy[lo:lo + CHUNK] = (g * dy * dy).sum(1)
    phi = 0.5 * np.arctan2(2.0 * txy, txx - tyy)
    t = np.column_stack([np.cos(phi), np.sin(phi)])
    tr = txx + tyy
    c = np.where(tr > 0, np.hypot(txx - tyy, 2.0 * txy) / np.maximum(tr, 1e-300), 0.0)
    return t, np.clip(c, 0.0, 1.0)


def hinge_alignment(model: Model) -> np.ndarray:
    """Per hinge s = c (2 (ê·t)² − 1) ∈ [−1, 1]: +1 for a hinge whose edge ê runs along a
    coherent vein direction t (it bends the blade across that vein), −1 for one across it
    (bending along the vein), 0 where the field is incoherent."""
    if model.hinge_count == 0:
        return np.zeros(0)
    xy = model.particle_rest[:, :2]
    a, b = model.hinge_idx[:, 2], model.hinge_idx[:, 3]
    e = xy[b] - xy[a]
    e /= np.maximum(np.linalg.norm(e, axis=1, keepdims=True), 1e-300)
    t, c = vein_field(model, 0.5 * (xy[a] + xy[b]))
    cos2 = (e * t).sum(1) ** 2
    return c * (2.0 * cos2 - 1.0)


def vein_frame_curl(model: Model, q: np.ndarray, align: np.ndarray | None = None) -> float:
    """How far the blade's bending follows the vein-frame curl: Σ θ s / Σ |θ| over the hinges
    off the main/lateral veins, θ the signed dihedral angle in ``q`` (> 0: bent the way the
    drying bilayer curls) and s the :func:`hinge_alignment`.  +1: every hinge across a vein
    (s > 0) curls the bilayer's way and every hinge along one bends back, i.e. the blade rolls
    up about its veins; ≈ 0: bending unrelated to the veins (one roll through the whole leaf,
    or flat); negative: it rolls up about axes across them."""
    from leafsim.sim.kernels.pbd import dihedral_angles

    if model.hinge_count == 0:
        return 0.0
    s = hinge_alignment(model) if align is None else align
    th = dihedral_angles(np.ascontiguousarray(q, float), model.hinge_idx)
    off = ~model.hinge_vein
    den = float(np.abs(th[off]).sum())
    return float((th[off] * s[off]).sum() / den) if den > 0 else 0.0
