"""Resolution-independent measures of a simulated leaf (the accuracy study's error metrics).

Two runs of the same leaf on different meshes have different particles, so they are compared
at **fixed material points of the rest leaf**: a grid inside the outline and points along the
margin, each embedded once in every mesh's rest layer T (triangle + barycentric coordinates)
and followed through that mesh's deformation.  Everything is relative to the leaf length L.

Example
-------
>>> probe = Probe(shape)                                   # doctest: +SKIP
>>> fa = probe.fields(model_a, state_a)                    # doctest: +SKIP
>>> fb = probe.fields(model_b, state_b)                    # doctest: +SKIP
>>> field_errors(fa, fb)["position_rms"]                   # RMS distance / L, own frames
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from leafsim.base.geometry import LeafShape, distance_to_polygon, points_in_polygon, resample_closed
from leafsim.sim.model import Model, State

#: grid resolution of the interior probe points (across the leaf's bounding box)
GRID = 40
#: margin probe points along the outline
MARGIN_POINTS = 200
#: top-down area raster (cells across the leaf's bounding box)
RASTER = 256


@dataclass
class Embedding:
    """Fixed points located in one mesh: triangle (k,) and barycentric weights (k, 3)."""

    tri: np.ndarray
    bary: np.ndarray

    def at(self, model: Model, q: np.ndarray) -> np.ndarray:
        """(k, 3) positions (or values, when ``q`` is (n,)) of the points for particle data ``q``."""
        idx = model.tri_T[self.tri]
        if q.ndim == 1:
            return (q[idx] * self.bary).sum(1)
        return np.einsum("kj,kjd->kd", self.bary, q[idx])


def embed(model: Model, pts: np.ndarray, tris: np.ndarray | None = None) -> Embedding:
    """Locate 2D rest points ``pts`` (k, 2) in the model's rest layer T: in the triangles
    ``tris`` (indices into tri_T; default the blade's, never the petiole's).  Points just
    outside the mesh (it approximates the outline by chords) take the nearest triangle with
    clamped, renormalised barycentric coordinates."""
    rest = model.particle_rest[:, :2]
    blade = np.flatnonzero(model.blade_tris) if tris is None else np.asarray(tris, np.int64)
    tri = model.tri_T[blade]
    cen = rest[tri].mean(1)
    kk = min(12, len(tri))
    _, cand = cKDTree(cen).query(pts, k=kk)
    cand = np.atleast_2d(cand).reshape(len(pts), kk)
    a, b, c = rest[tri[cand, 0]], rest[tri[cand, 1]], rest[tri[cand, 2]]  # (k, kk, 2)
    p = pts[:, None, :]
    v0, v1, v2 = b - a, c - a, p - a
    d00 = (v0 * v0).sum(-1); d01 = (v0 * v1).sum(-1); d11 = (v1 * v1).sum(-1)
    d20 = (v2 * v0).sum(-1); d21 = (v2 * v1).sum(-1)
    den = d00 * d11 - d01 * d01
    den = np.where(np.abs(den) < 1e-300, 1e-300, den)
    l1 = (d11 * d20 - d01 * d21) / den
    l2 = (d00 * d21 - d01 * d20) / den
    bary = np.stack([1.0 - l1 - l2, l1, l2], -1)
    best = np.argmax(bary.min(-1), axis=1)  # the containing triangle has min coordinate ≥ 0
    rows = np.arange(len(pts))
    w = np.clip(bary[rows, best], 0.0, None)
    w /= np.maximum(w.sum(1, keepdims=True), 1e-300)
    return Embedding(blade[cand[rows, best]], w)


def own_frame(P: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """``P`` (k, 3) moved by the best rigid fit (Kabsch) onto ``Q`` (k, 3)."""
    pc, qc = P.mean(0), Q.mean(0)
    H = (P - pc).T @ (Q - qc)
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T))
    R = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T
    return (P - pc) @ R.T + qc


class Probe:
    """Fixed probe points of one leaf outline (shared by every mesh of that leaf).

    Parameters
    ----------
    shape : LeafShape — the rest outline (metres).
    grid : interior grid resolution; margin : points along the outline.
    """

    def __init__(self, shape: LeafShape, grid: int = GRID, margin: int = MARGIN_POINTS):
        c = np.asarray(shape.contour, float)
        self.length = float(shape.length)
        lo, hi = c.min(0), c.max(0)
        step = float((hi - lo).max()) / grid
        xs = np.arange(lo[0] + 0.5 * step, hi[0], step)
        ys = np.arange(lo[1] + 0.5 * step, hi[1], step)
        g = np.array(np.meshgrid(xs, ys)).reshape(2, -1).T
        inside = points_in_polygon(g, c) & (distance_to_polygon(g, c) > 0.01 * self.length)
        self.interior = g[inside]
        self.margin = resample_closed(c, margin)
        self.points = np.vstack([self.interior, self.margin])
        self.n_interior = len(self.interior)
        self.rest3 = np.column_stack([self.points, np.zeros(len(self.points))])
        self.bbox = (lo, hi)
        self._emb: dict[int, tuple[weakref.ref, Embedding]] = {}

    def embedding(self, model: Model) -> Embedding:
        """The probe points' embedding in ``model``'s blade, cached per live model: a model's
        ``id`` is reused once it is freed, so the entry also holds a weak reference that must
        still point at this model (a stale entry indexed a later model's triangles)."""
        key = id(model)
        hit = self._emb.get(key)
        if hit is None or hit[0]() is not model:
            self._emb = {k: v for k, v in self._emb.items() if v[0]() is not None}
            hit = self._emb[key] = (weakref.ref(model), embed(model, self.points))
        return hit[1]

    def fields(self, model: Model, state: State) -> dict:
        """Probe fields of one state: positions ``q`` (k, 3), own-frame positions ``q_own``,
        relative water ``water_field`` (k,), plus the scalar shape measures of :func:`shape_scalars`."""
        e = self.embedding(model)
        q = e.at(model, state.particle_q)
        w = e.at(model, state.particle_water / np.maximum(model.particle_water0, 1e-300))
        out = {"q": q, "q_own": own_frame(q, self.rest3), "water_field": w}
        out.update(shape_scalars(model, state, self, q))
        return out


def _top_down_area(q: np.ndarray, tri: np.ndarray, lo: np.ndarray, span: float) -> float:
    """Area covered by the triangles projected onto the ground (overlaps counted once),
    rasterised on a RASTER² grid over ``lo``…``lo + span``."""
    import cv2

    img = np.zeros((RASTER, RASTER), np.uint8)
    px = ((q[:, :2] - lo) / span * RASTER).astype(np.float64)
    polys = np.round(px[tri] * 16).astype(np.int32)  # 4 fractional bits
    cv2.fillPoly(img, list(polys), 1, lineType=cv2.LINE_8, shift=4)
    return float(img.sum()) * (span / RASTER) ** 2


def shape_scalars(model: Model, state: State, probe: Probe, q_probe: np.ndarray | None = None) -> dict:
    """margin_lift (highest margin probe point above the lowest point of the blade, / L),
    margin_lift_mean (median margin point), area_3d (3D area of layer T now / rest),
    area_top (top-down projected area now / rest), water (total now / initial)."""
    L = probe.length
    if q_probe is None:
        q_probe = probe.embedding(model).at(model, state.particle_q)
    q = state.particle_q
    T = model.blade_T
    zmin = q[T, 2].min()
    zm = q_probe[probe.n_interior:, 2]
    tri = model.blade_tri_T
    a3 = lambda x: 0.5 * np.linalg.norm(np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]]), axis=1).sum()
    rest = model.particle_rest
    lo = np.minimum(q[T, :2].min(0), rest[T, :2].min(0))
    span = float(max(np.ptp(np.vstack([q[T, :2], rest[T, :2]]), 0).max(), 1e-9)) * 1.02
    return {
        "margin_lift": float((zm.max() - zmin) / L),
        "margin_lift_mean": float((np.median(zm) - zmin) / L),
        "area_3d": float(a3(q) / a3(rest)),
        "area_top": float(_top_down_area(q, tri, lo, span) / _top_down_area(rest, tri, lo, span)),
        "water": model.water_fraction(state.particle_water),
    }


def field_errors(a: dict, b: dict, length: float | None = None) -> dict:
    """Errors of probe fields ``a`` against reference ``b`` (both from :meth:`Probe.fields` of
    the same probe).  Positions are RMS over the probe points / L (``position_rms`` in the
    leaves' own frames, ``height_rms`` of the height above the ground); scalar measures as
    absolute differences (``d_<name>``) and relative ones (``r_<name>`` = |a − b| / |b|)."""
    L = length if length is not None else 1.0
    out = {
        "position_rms": float(np.sqrt(((a["q_own"] - b["q_own"]) ** 2).sum(1).mean()) / L),
        "height_rms": float(np.sqrt((((a["q"][:, 2] - a["q"][:, 2].min()) - (b["q"][:, 2] - b["q"][:, 2].min())) ** 2).mean()) / L),
        "water_rms": float(np.sqrt(((a["water_field"] - b["water_field"]) ** 2).mean())),
    }
    for k in ("margin_lift", "margin_lift_mean", "area_3d", "area_top"):
        out[f"d_{k}"] = float(abs(a[k] - b[k]))
        out[f"r_{k}"] = float(abs(a[k] - b[k]) / max(abs(b[k]), 1e-12))
    return out
