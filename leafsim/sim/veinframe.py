"""The local vein direction at every bending hinge, for the anisotropic bilayer curl.

A drying lamina does not shrink the same in every direction: the veins and the cells and
fibres aligned with them hold their length, the tissue between them gives way across them.
So the bilayer's curl is strongest *across* the veins — the blade rolls about axes that run
along its main and lateral veins — and weak along them.  A palmate lobe then cups about its
own main vein instead of the whole leaf rolling into one tube (docs/method.md §6).

The direction field is the orientation tensor of the main and lateral vein segments near a
point, weighted by segment length × vein width × a Gaussian of the distance whose width is
the distance to the nearest such vein plus ``BLEND`` × the leaf length: it follows the
nearest vein closely and blends smoothly where two veins meet, and as a length of the leaf
(not of the mesh) it converges under refinement.  Its principal direction is t and its
coherence c = (λ₁ − λ₂) / (λ₁ + λ₂) ∈ [0, 1] (0 where the veins nearby disagree).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .model import Model

#: veins that steer the curl: main (0) and lateral (1), the orders that are stiff rods
FIELD_MAX_ORDER = 1
#: segments considered per point
NEIGHBOURS = 24
#: blend length of the field, × leaf length (≈ 5 mm on a 12 cm leaf)
BLEND = 0.04


def vein_segments(model: Model, max_order: int = FIELD_MAX_ORDER):
    """(midpoints (s,2), unit directions (s,2), length × width (s,)) of the model's vein
    chains up to ``max_order``, in rest coordinates."""
    xy = model.particle_rest[:, :2]
    mids, dirs, wts = [], [], []
    for v in range(len(model.vein_order)):
        if model.vein_order[v] > max_order:
            continue
        lo, hi = int(model.vein_start[v]), int(model.vein_start[v + 1])
        if hi - lo < 2:
            continue
        p = xy[model.vein_particles[lo:hi]]
        w = model.vein_width[lo:hi]
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
    dist, idx = cKDTree(mids).query(pts, k=k)
    dist = dist.reshape(len(pts), k)
    idx = idx.reshape(len(pts), k)
    width = dist[:, :1] + BLEND * model.length
    g = wts[idx] * np.exp(-(dist / width) ** 2)
    dx, dy = dirs[idx, 0], dirs[idx, 1]
    txx = (g * dx * dx).sum(1)
    txy = (g * dx * dy).sum(1)
    tyy = (g * dy * dy).sum(1)
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
    """How much of the blade's bending runs across its veins: Σ θ s / Σ |θ| over the hinges
    off the main/lateral veins, θ the signed dihedral angle in ``q`` and s the
    :func:`hinge_alignment`.  +1: every hinge bends the blade about an axis along its local
    vein (lobes cup about their own veins); −1: every bend runs along the veins; ≈ 0: bending
    unrelated to the veins (one roll through the whole leaf, or flat)."""
    from .kernels.pbd import dihedral_angles

    if model.hinge_count == 0:
        return 0.0
    s = hinge_alignment(model) if align is None else align
    th = dihedral_angles(np.ascontiguousarray(q, float), model.hinge_idx)
    off = ~model.hinge_vein
    den = float(np.abs(th[off]).sum())
    return float((th[off] * s[off]).sum() / den) if den > 0 else 0.0
