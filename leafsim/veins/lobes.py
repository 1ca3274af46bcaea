"""Lobe tips of an outline (Kim's automatic main-vein targets): convex-hull vertices that are
contour extrema beyond a depth threshold."""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull  # noqa: E402


def detect_lobe_tips(contour: np.ndarray, length: float, min_depth: float, max_angle: float = 160.0, radial: bool = True) -> np.ndarray:
    """Lobe tips of a leaf contour (world frame, base at origin, apex on +y).

    The contour is split at sinuses — the deepest contour point between two consecutive
    convex-hull vertices, when deeper than ``min_depth × length`` below the hull edge.
    In every piece the point farthest from the base is a lobe tip.  Pieces whose tip lies
    near the base (< 0.2 length) or points back along the petiole (angle from +y above
    ``max_angle``) are dropped.  ``radial`` (palmate leaves, lobes radiate from the base):
    the tip is the lobe point farthest from the base; otherwise (pinnate lobes) the point
    protruding farthest beyond the chord joining the lobe's two sinuses.
    Returns (k, 2) tips ordered by angle from the apex.
    """
    n = len(contour)
    thr = min_depth * length

    def deepest(idx):
        p, q = contour[idx[0]], contour[idx[-1]]
        d = q - p
        L = np.linalg.norm(d)
        if L == 0 or len(idx) < 3:
            return None
        chain = contour[idx]
        depth = np.abs(d[0] * (chain[:, 1] - p[1]) - d[1] * (chain[:, 0] - p[0])) / L
        k = int(np.argmax(depth))
        return int(idx[k]) if depth[k] > thr else None

    def refine(idx, out):
        """Sinuses inside an open chain: hull of the chain, deepest point under each hull edge."""
        if len(idx) < 4:
            return
        try:
            hv = np.sort(ConvexHull(contour[idx]).vertices)
        except Exception:
            return
        for a, b in zip(hv[:-1], hv[1:]):
            if b - a < 2:
                continue
            k = deepest(idx[a : b + 1])
            if k is not None:
                out.append(k)
                kk = int(np.flatnonzero(idx == k)[0])
                refine(idx[a : kk + 1], out)
                refine(idx[kk : b + 1], out)

    hull = np.sort(ConvexHull(contour).vertices)
    sinuses = []
    for a, b in zip(hull, np.roll(hull, -1)):
        idx = np.arange(a, b + (n if b <= a else 0) + 1) % n
        k = deepest(idx)
        if k is not None:
            sinuses.append(k)
            kk = int(np.flatnonzero(idx == k)[0])
            refine(idx[: kk + 1], sinuses)
            refine(idx[kk:], sinuses)
    r = np.linalg.norm(contour, axis=1)
    if len(sinuses) < 2:
        return contour[[int(np.argmax(r))]]
    sinuses = sorted(set(sinuses))
    tips = []
    for a, b in zip(sinuses, sinuses[1:] + [sinuses[0] + n]):
        idx = np.arange(a, b + 1) % n
        # the tip protrudes farthest beyond the chord joining the lobe's two sinuses
        p0, p1 = contour[idx[0]], contour[idx[-1]]
        d = p1 - p0
        prot = (d[0] * (contour[idx, 1] - p0[1]) - d[1] * (contour[idx, 0] - p0[0])) * -1.0
        if radial or np.linalg.norm(d) < 1e-12 or prot.max() <= 0:
            k = idx[int(np.argmax(r[idx]))]
        else:
            prot = prot / np.linalg.norm(d)
            if prot.max() < thr:
                continue
            k = idx[int(np.argmax(prot))]
        t = contour[k]
        ang = np.degrees(np.arctan2(t[0], t[1]))
        if r[k] >= 0.2 * length and abs(ang) <= max_angle:
            tips.append(t)
    if not tips:
        return contour[[int(np.argmax(r))]]
    tips = np.array(tips)
    return tips[np.argsort(np.abs(np.degrees(np.arctan2(tips[:, 0], tips[:, 1]))))]
