"""Leaf shape in world units and small 2D geometry helpers shared by every stage.

World frame: metres, the petiole junction (base) at the origin, the apex on the +y axis,
the blade in the z = 0 plane (z up).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class LeafShape:
    """Outline of one leaf in world units.

    Attributes
    ----------
    contour : (n, 2) float64 — closed polygon (first point not repeated), counter-clockwise, metres.
    base : (2,) float64 — petiole junction, always (0, 0).
    apex : (2,) float64 — apex, on the +y axis, |apex| = length.
    lobes : (k, 2) float64 — detected lobe tips (may be empty).
    length : float — real leaf length base→apex in metres.
    px_to_world : (2, 3) float64 — affine map from photo pixels (x, y) to world (x, y);
        identity-like for drawn outlines.  Its inverse gives texture coordinates.
    image : str | None — photo path, None for drawn outlines.
    image_size : (w, h) of the photo in pixels, or None.
    """

    contour: np.ndarray
    base: np.ndarray
    apex: np.ndarray
    lobes: np.ndarray
    length: float
    px_to_world: np.ndarray = field(default_factory=lambda: np.eye(2, 3))
    image: str | None = None
    image_size: tuple[int, int] | None = None

    def world_to_px(self, pts: np.ndarray) -> np.ndarray:
        """Map world (n, 2) points back to photo pixel coordinates."""
        A = np.vstack([self.px_to_world, [0.0, 0.0, 1.0]])
        Ai = np.linalg.inv(A)
        p = np.asarray(pts, float)
        return p @ Ai[:2, :2].T + Ai[:2, 2]

    def texcoords(self, pts: np.ndarray) -> np.ndarray:
        """Texture coordinates in [0, 1]² of world points (rest positions) on the photo."""
        if self.image_size is None:
            lo = self.contour.min(0)
            hi = self.contour.max(0)
            return (np.asarray(pts, float)[:, :2] - lo) / np.maximum(hi - lo, 1e-12)
        px = self.world_to_px(np.asarray(pts, float)[:, :2])
        w, h = self.image_size
        return np.column_stack([px[:, 0] / w, px[:, 1] / h])

    @property
    def area(self) -> float:
        return polygon_area(self.contour)


def polygon_area(poly: np.ndarray) -> float:
    """Signed area (positive when counter-clockwise) of a closed polygon (n, 2)."""
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def resample_closed(poly: np.ndarray, n: int) -> np.ndarray:
    """Resample a closed polygon to ``n`` points at equal arc length."""
    p = np.vstack([poly, poly[:1]])
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    t = np.linspace(0.0, s[-1], n, endpoint=False)
    return np.column_stack([np.interp(t, s, p[:, 0]), np.interp(t, s, p[:, 1])])


def resample_polyline(line: np.ndarray, spacing: float) -> np.ndarray:
    """Resample an open polyline at (about) ``spacing``, keeping both end points."""
    seg = np.linalg.norm(np.diff(line, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] <= 0:
        return line[:1].copy()
    n = max(1, int(round(s[-1] / spacing)))
    t = np.linspace(0.0, s[-1], n + 1)
    return np.column_stack([np.interp(t, s, line[:, 0]), np.interp(t, s, line[:, 1])])


def points_in_polygon(pts: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Boolean (n,) mask of points strictly inside a closed polygon (even-odd rule)."""
    pts = np.asarray(pts, float).reshape(-1, 2)
    poly = np.asarray(poly, float)
    x0, y0 = poly[:, 0], poly[:, 1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    out = np.zeros(len(pts), bool)
    # chunks of points keep the (points × edges) temporaries at a few MB (a dense mesh tests
    # millions of candidate points against the outline)
    step = max(1, 262144 // max(len(poly), 1))
    for k in range(0, len(pts), step):
        x, y = pts[k : k + step, 0:1], pts[k : k + step, 1:2]
        cond = (y0 > y) != (y1 > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xi = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
        out[k : k + step] = (np.count_nonzero(cond & (x < xi), axis=1) % 2) == 1
    return out


def segments_intersect(p1, p2, q1, q2) -> bool:
    """Proper intersection test of segments p1p2 and q1q2 (touching at end points excluded)."""
    d1 = _cross(q2 - q1, p1 - q1)
    d2 = _cross(q2 - q1, p2 - q1)
    d3 = _cross(p2 - p1, q1 - p1)
    d4 = _cross(p2 - p1, q2 - p1)
    return (d1 * d2 < 0) and (d3 * d4 < 0)


def _cross(a, b):
    return a[0] * b[1] - a[1] * b[0]


def segment_hits(a: np.ndarray, b: np.ndarray, P: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """Vectorised proper-intersection test of one segment ab against segments P[i]Q[i].

    Returns the parameters t ∈ (0, 1) along ab of every hit (empty array if none).
    """
    if len(P) == 0:
        return np.empty(0)
    r = b - a
    s = Q - P
    denom = r[0] * s[:, 1] - r[1] * s[:, 0]
    qp = P - a
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (qp[:, 0] * s[:, 1] - qp[:, 1] * s[:, 0]) / denom
        u = (qp[:, 0] * r[1] - qp[:, 1] * r[0]) / denom
    eps = 1e-9
    ok = (np.abs(denom) > 1e-18) & (t > eps) & (t < 1 - eps) & (u > eps) & (u < 1 - eps)
    return t[ok]


def ray_polygon_hit(origin: np.ndarray, direction: np.ndarray, poly: np.ndarray) -> float | None:
    """Distance along a unit ``direction`` from ``origin`` to the first polygon edge, or None."""
    P = poly
    Q = np.roll(poly, -1, axis=0)
    s = Q - P
    r = direction
    denom = r[0] * s[:, 1] - r[1] * s[:, 0]
    qp = P - origin
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (qp[:, 0] * s[:, 1] - qp[:, 1] * s[:, 0]) / denom
        u = (qp[:, 0] * r[1] - qp[:, 1] * r[0]) / denom
    ok = (np.abs(denom) > 1e-18) & (t > 1e-12) & (u >= 0) & (u <= 1)
    if not ok.any():
        return None
    return float(t[ok].min())


def distance_to_polygon(pts: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Distance (n,) from each point to the nearest polygon edge."""
    P = poly
    Q = np.roll(poly, -1, axis=0)
    d = Q - P
    L2 = np.maximum((d * d).sum(1), 1e-30)
    pts = np.asarray(pts, float)
    out = np.full(len(pts), np.inf)
    for k in range(0, len(pts), 2048):
        x = pts[k : k + 2048, None, :]
        t = np.clip(((x - P) * d).sum(-1) / L2, 0, 1)
        proj = P + t[..., None] * d
        out[k : k + 2048] = np.sqrt(((x - proj) ** 2).sum(-1)).min(1)
    return out
