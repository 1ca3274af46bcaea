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
    holes : tuple of (k, 2) float64 — closed polygons (clockwise, metres) of holes in the
        blade: closed sinuses where overlapping lobes leave the background showing.  They
        are margins like the outer contour; nothing grows or is meshed inside them.
    """

    contour: np.ndarray
    base: np.ndarray
    apex: np.ndarray
    lobes: np.ndarray
    length: float
    px_to_world: np.ndarray = field(default_factory=lambda: np.eye(2, 3))
    image: str | None = None
    image_size: tuple[int, int] | None = None
    holes: tuple = ()

    def inside(self, pts: np.ndarray) -> np.ndarray:
        """Boolean (n,) mask of points in the blade: inside the contour, outside every hole."""
        return points_in_region(pts, self.contour, self.holes)

    def margin_distance(self, pts: np.ndarray) -> np.ndarray:
        """Distance (n,) from each point to the nearest margin (the contour or a hole's edge)."""
        return distance_to_outline(pts, self.contour, self.holes)

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
        """Blade area: the contour's minus its holes'."""
        return polygon_area(self.contour) - sum(abs(polygon_area(h)) for h in self.holes)


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


def resample_closed_keeping(poly: np.ndarray, n: int) -> np.ndarray:
    """Resample a closed polygon to ``n`` points that keep every vertex (a Douglas–Peucker
    polygon's tooth tips and notches): each edge is split into equal parts, as many as its share
    of the perimeter asks for (largest remainders, at least one: its first vertex), starting at
    ``poly[0]``.  With fewer points than vertices, equal arc length (:func:`resample_closed`)."""
    poly = np.asarray(poly, float)
    m, n = len(poly), int(n)
    if n < m:
        return resample_closed(poly, n)
    p = np.vstack([poly, poly[:1]])
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    share = (n - m) * seg / max(float(seg.sum()), 1e-300)
    k = 1 + np.floor(share).astype(np.int64)
    k[np.argsort(-(share - np.floor(share)), kind="stable")[: n - int(k.sum())]] += 1
    i = np.repeat(np.arange(m), k)
    t = (np.arange(n) - np.repeat(np.cumsum(k) - k, k)) / np.repeat(k, k)
    return p[i] + t[:, None] * (p[i + 1] - p[i])


def resample_polyline(line: np.ndarray, spacing: float) -> np.ndarray:
    """Resample an open polyline at (about) ``spacing``, keeping both end points."""
    seg = np.linalg.norm(np.diff(line, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] <= 0:
        return line[:1].copy()
    n = max(1, int(round(s[-1] / spacing)))
    t = np.linspace(0.0, s[-1], n + 1)
    return np.column_stack([np.interp(t, s, line[:, 0]), np.interp(t, s, line[:, 1])])


#: up to this many points the (points × edges) numpy expressions answer (a one-point check
#: when a species library is loaded needs no compiled kernel); more go to the compiled loops
#: of :mod:`leafsim.base.polykernels` (the same arithmetic in the same order: bit-identical)
FEW_POINTS = 4


def _xy(pts, what: str) -> np.ndarray:
    """``pts`` as a C-contiguous float64 (n, 2) array: one point (2,) or points (n, 2)."""
    a = np.asarray(pts, dtype=np.float64)
    if a.ndim == 1 and a.shape[0] == 2:
        a = a[None]
    if a.ndim != 2 or a.shape[1] != 2:
        raise ValueError(f"{what}: expected points of shape (n, 2), got {a.shape}")
    return np.ascontiguousarray(a)


def _ring(poly) -> np.ndarray:
    """A polygon's vertices (m, ≥ 2) as C-contiguous float64 (m, 2) (x, y of each)."""
    a = np.asarray(poly, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] < 2:
        raise ValueError(f"polygon: expected vertices of shape (m, 2), got {a.shape}")
    return np.ascontiguousarray(a[:, :2])


def points_in_polygon(pts: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Boolean (n,) mask of points strictly inside a closed polygon (even-odd rule): an edge
    (y0 > y) != (y1 > y) crosses the ray to +x where x < x0 + (y − y0)(x1 − x0)/(y1 − y0)."""
    pts, poly = _xy(pts, "points_in_polygon"), _ring(poly)
    if len(pts) <= FEW_POINTS:
        x0, y0 = poly[:, 0], poly[:, 1]
        x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
        x, y = pts[:, 0:1], pts[:, 1:2]
        cond = (y0 > y) != (y1 > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xi = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
        return (np.count_nonzero(cond & (x < xi), axis=1) % 2) == 1
    from leafsim.base.polykernels import inside_even_odd  # compiled only when many points ask

    out = np.zeros(len(pts), bool)
    inside_even_odd(pts, poly, out)
    return out


def points_in_region(pts: np.ndarray, contour: np.ndarray, holes=()) -> np.ndarray:
    """Boolean (n,) mask of points inside ``contour`` and outside every polygon of ``holes``."""
    inside = points_in_polygon(pts, contour)
    for h in holes:
        if inside.any():
            inside[inside] &= ~points_in_polygon(_xy(pts, "points_in_region")[inside], h)
    return inside


def distance_to_outline(pts: np.ndarray, contour: np.ndarray, holes=()) -> np.ndarray:
    """Distance (n,) from each point to the nearest edge of the contour or of a hole."""
    d = distance_to_polygon(pts, contour)
    for h in holes:
        d = np.minimum(d, distance_to_polygon(pts, h))
    return d


def outline_edges(contour: np.ndarray, holes=()) -> tuple[np.ndarray, np.ndarray]:
    """All margin edges (P, Q) of a contour and its holes (each polygon closed)."""
    rings = [np.asarray(contour, float)] + [np.asarray(h, float) for h in holes]
    return np.vstack(rings), np.vstack([np.roll(r, -1, axis=0) for r in rings])


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


def ray_polygon_hit(origin: np.ndarray, direction: np.ndarray, poly: np.ndarray, holes=()) -> float | None:
    """Distance along a unit ``direction`` from ``origin`` to the first polygon edge (of
    ``poly`` or of one of its ``holes``), or None."""
    P, Q = outline_edges(poly, holes)
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
    """Distance (n,) from each point to the nearest polygon edge (NaN where a NaN or infinite
    coordinate makes it undefined)."""
    pts, poly = _xy(pts, "distance_to_polygon"), _ring(poly)
    if len(pts) <= FEW_POINTS:
        if not len(poly):
            return np.full(len(pts), np.inf)
        P, Q = poly, np.roll(poly, -1, axis=0)
        with np.errstate(invalid="ignore"):  # a NaN or infinite coordinate: NaN, said by the result
            d = Q - P
            L2 = np.maximum((d * d).sum(1), 1e-30)
            x = pts[:, None, :]
            t = np.clip(((x - P) * d).sum(-1) / L2, 0, 1)
            proj = P + t[..., None] * d
            return np.sqrt(((x - proj) ** 2).sum(-1)).min(1)
    from leafsim.base.polykernels import distance_to_edges  # compiled only when many points ask

    out = np.empty(len(pts))
    distance_to_edges(pts, poly, out)
    return out


def crossing_pairs(P: np.ndarray, Q: np.ndarray, first: bool = False, touching: bool = False) -> np.ndarray:
    """Pairs (i, j), i < j, of segments P[i]Q[i] and P[j]Q[j] that cross properly.

    Touching at end points (shared vertices of a polyline or polygon) does not count, unless
    ``touching``: then every contact counts — crossing, an end point on the other segment,
    shared end points, collinear overlap.
    ``first``: stop at the first chunk holding a crossing (enough to say "not simple").
    Segments are visited in chunks sorted by x and tested only against those whose bounding
    boxes overlap the chunk's, so a long outline costs far less than all n² pairs.
    Returns an (k, 2) int64 array.
    """
    P = np.asarray(P, float).reshape(-1, 2)
    Q = np.asarray(Q, float).reshape(-1, 2)
    n = len(P)
    lo, hi = np.minimum(P, Q), np.maximum(P, Q)
    order = np.argsort(lo[:, 0], kind="stable")
    found = []
    eps = 1e-9
    for k in range(0, n, 256):
        ch = order[k : k + 256]
        clo, chi = lo[ch].min(0), hi[ch].max(0)
        cand = np.flatnonzero((lo[:, 0] <= chi[0]) & (hi[:, 0] >= clo[0]) & (lo[:, 1] <= chi[1]) & (hi[:, 1] >= clo[1]))
        a, r = P[ch, None, :], (Q - P)[ch, None, :]
        s = (Q - P)[cand][None]
        qp = P[cand][None] - a
        denom = r[..., 0] * s[..., 1] - r[..., 1] * s[..., 0]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            t = (qp[..., 0] * s[..., 1] - qp[..., 1] * s[..., 0]) / denom
            u = (qp[..., 0] * r[..., 1] - qp[..., 1] * r[..., 0]) / denom
        if touching:
            rr = (r * r).sum(-1)
            par = np.abs(denom) <= 1e-12 * np.sqrt(rr * (s * s).sum(-1))
            hit = ~par & (t >= -eps) & (t <= 1 + eps) & (u >= -eps) & (u <= 1 + eps)
            hit |= par & _collinear_overlap(qp, r, s, rr, eps)
        else:
            hit = (np.abs(denom) > 1e-18) & (t > eps) & (t < 1 - eps) & (u > eps) & (u < 1 - eps)
        hit &= cand[None, :] > ch[:, None]
        ii, jj = np.nonzero(hit)
        if len(ii):
            found.append(np.column_stack([ch[ii], cand[jj]]))
            if first:
                break
    if not found:
        return np.zeros((0, 2), np.int64)
    pairs = np.vstack(found).astype(np.int64)
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


def _collinear_overlap(qp, r, s, rr, eps):
    """For parallel segment pairs a + [0, 1]·r and (a + qp) + [0, 1]·s: on one line and their
    parameter ranges along r meet (touching end to end included)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        off = np.abs(qp[..., 0] * r[..., 1] - qp[..., 1] * r[..., 0]) / np.sqrt(rr)
        t0 = (qp * r).sum(-1) / rr
        t1 = ((qp + s) * r).sum(-1) / rr
    on_line = off <= eps * np.sqrt(rr)
    return on_line & (np.minimum(1.0, np.maximum(t0, t1)) >= np.maximum(0.0, np.minimum(t0, t1)) - eps)


def _self_contact(c: np.ndarray):
    """First pair of edges (i, j) of a closed polygon that touch though they should not:
    non-adjacent edges meeting anywhere, or neighbours folding back onto each other (a spike)."""
    n = len(c)
    d = np.roll(c, -1, axis=0) - c
    prev = np.roll(d, 1, axis=0)
    spike = (np.abs(prev[:, 0] * d[:, 1] - prev[:, 1] * d[:, 0]) <= 1e-12 * np.hypot(*prev.T) * np.hypot(*d.T)) \
        & ((prev * d).sum(1) < 0)
    if spike.any():
        k = int(np.flatnonzero(spike)[0])
        return (k - 1) % n, k
    pairs = crossing_pairs(c, np.roll(c, -1, axis=0), touching=True)
    i, j = pairs[:, 0], pairs[:, 1]
    pairs = pairs[(j - i != 1) & ~((i == 0) & (j == n - 1))]
    return (int(pairs[0, 0]), int(pairs[0, 1])) if len(pairs) else None


#: an outline point may lie at most this many leaf lengths (base→apex) from the base
OUTLINE_MAX_REACH = 3.0
#: base and apex may lie at most this many leaf lengths outside the outline
OUTLINE_END_TOLERANCE = 0.1
#: an outline must enclose at least this area, in leaf lengths squared
OUTLINE_MIN_AREA = 1e-3


def outline_problem(contour: np.ndarray, base, apex) -> str | None:
    """Why a closed polygon cannot be the blade of a leaf with this base and apex, or None.

    A leaf outline has at least 3 distinct, finite points, encloses an area (not collinear),
    does not cross itself, reaches no farther than ``OUTLINE_MAX_REACH`` leaf lengths from
    the base, and has the base (petiole junction) and the apex on (or inside) its margin.
    The text is a sentence fragment for a one-line error ("the outline ...").
    """
    c = np.asarray(contour, float).reshape(-1, 2)
    base = np.asarray(base, float).reshape(2)
    apex = np.asarray(apex, float).reshape(2)
    if not (np.isfinite(c).all() and np.isfinite(base).all() and np.isfinite(apex).all()):
        return "has a non-finite coordinate"
    keep = np.r_[True, np.any(np.diff(c, axis=0) != 0, axis=1)]
    c = c[keep]
    if len(c) > 1 and np.array_equal(c[0], c[-1]):
        c = c[:-1]
    if len(np.unique(c, axis=0)) < 3:
        return f"has {len(np.unique(c, axis=0))} distinct point(s), expected at least 3"
    L = float(np.linalg.norm(apex - base))
    if L <= 0:
        return "has its base and apex at the same point"
    with np.errstate(over="ignore", invalid="ignore"):
        reach = np.hypot(*((c - base) / L).T)
    i = int(np.argmax(reach))
    if not reach[i] <= OUTLINE_MAX_REACH:
        return (f"reaches {reach[i]:.3g} leaf lengths from the base at point {i} "
                f"(expected within {OUTLINE_MAX_REACH:g}; leaf units put the base at (0, 0) and the apex at (0, 1))")
    area = abs(polygon_area(c)) / L**2
    if area < OUTLINE_MIN_AREA:
        return (f"encloses {area:.3g} leaf lengths² (expected at least {OUTLINE_MIN_AREA:g}: "
                "points collinear, or the outline is not scaled to base (0, 0) → apex (0, 1))")
    dup = _duplicate_vertex(c)
    if dup is not None:
        return f"passes twice through point {dup[0]} = point {dup[1]} (the outline must not touch itself)"
    contact = _self_contact(c)
    if contact is not None:
        i, j = contact
        return f"crosses or touches itself: edge {i}→{(i + 1) % len(c)} meets edge {j}→{(j + 1) % len(c)} (expected a simple polygon)"
    for name, q in (("base", base), ("apex", apex)):
        if points_in_polygon(q[None], c)[0]:
            continue
        d = float(distance_to_polygon(q[None], c)[0]) / L
        if d > OUTLINE_END_TOLERANCE:
            return f"does not contain the {name}: it lies {d:.3g} leaf lengths outside (expected on the margin or inside)"
    return None


def _duplicate_vertex(c: np.ndarray):
    """Indices (i, j) of the first two non-consecutive equal vertices, or None."""
    _, first, inv, cnt = np.unique(c, axis=0, return_index=True, return_inverse=True, return_counts=True)
    if (cnt > 1).any():
        k = int(np.flatnonzero(cnt > 1)[0])
        idx = np.flatnonzero(inv.ravel() == k)
        return int(idx[0]), int(idx[1])
    return None


def targets_problem(targets: np.ndarray, contour: np.ndarray, length: float) -> str | None:
    """Why vein targets cannot be used with this outline (one lies outside it), or None."""
    t = np.asarray(targets, float).reshape(-1, 2)
    inside = points_in_polygon(t, contour)
    for k in np.flatnonzero(~inside):
        d = float(distance_to_polygon(t[k : k + 1], contour)[0]) / length
        if d > OUTLINE_END_TOLERANCE:
            x, y = (float(v) / length for v in t[k])
            return (f"target {k} at ({x:.4g}, {y:.4g}) leaf units lies {d:.3g} leaf lengths outside the outline "
                    "(expected inside the blade)")
    return None


def holes_problem(holes, contour: np.ndarray) -> str | None:
    """Why these holes cannot be holes of this blade outline, or None: each has at least 3
    points, lies inside the contour and touches neither the contour, itself nor another
    hole.  The text is a sentence fragment for a one-line error ("the outline ...")."""
    c = np.asarray(contour, float)
    rings = [c] + [np.asarray(h, float).reshape(-1, 2) for h in holes]
    for k, h in enumerate(rings[1:]):
        if len(h) < 3 or not np.isfinite(h).all() or abs(polygon_area(h)) <= 0:
            return f"has hole {k} with fewer than 3 distinct finite points or no area"
        if not points_in_polygon(h, c).all():
            return f"has hole {k} reaching outside the blade contour"
    P = np.vstack(rings)
    Q = np.vstack([np.roll(r, -1, axis=0) for r in rings])
    ring = np.concatenate([np.full(len(r), i) for i, r in enumerate(rings)])
    pairs = crossing_pairs(P, Q, touching=True)
    n = np.array([len(r) for r in rings])[ring]
    start = np.concatenate([[0], np.cumsum([len(r) for r in rings])[:-1]])[ring]
    for i, j in pairs:
        if ring[i] == ring[j]:
            a, b = i - start[i], j - start[j]
            if abs(a - b) == 1 or abs(a - b) == n[i] - 1:
                continue  # neighbours on one ring share a vertex
            if ring[i] == 0:
                continue  # the contour itself is checked by outline_problem
        return f"has hole {max(ring[i], ring[j]) - 1} touching {'the contour' if min(ring[i], ring[j]) == 0 else 'another hole or itself'}"
    return None


def boundary_edges(tri: np.ndarray) -> np.ndarray:
    """(b, 2) edges used by one triangle only, oriented as in that triangle."""
    tri = np.asarray(tri)
    if not len(tri):
        return np.zeros((0, 2), tri.dtype if tri.dtype.kind in "iu" else np.int64)
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    key = np.sort(e, axis=1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return e[cnt[inv.ravel()] == 1]
