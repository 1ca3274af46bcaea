"""Compiled point–polygon kernels behind :mod:`leafsim.base.geometry`.

A leaf's build asks "inside the outline?" and "how far from the margin?" for every candidate
and every particle: (points × edges) work that numpy did in chunks of temporaries and that took
90 % of a maple's build (2.4 of 2.6 s).  These loops do the same arithmetic, in the same order,
without the temporaries (no fast-math: the results are bit-identical to the numpy expressions
they replace, which the tests keep as the reference).  Kept apart from ``geometry.py`` so that
editing the geometry helpers does not invalidate every cached kernel (the cache is keyed to the
sources that mention numba; :mod:`leafsim.base.cache`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from leafsim.base.cache import configure_numba_cache

configure_numba_cache()  # before the first @njit(cache=True)


@njit(cache=True, nogil=True)
def inside_even_odd(pts, poly, out):  # pragma: no cover - numba
    """out[i] = point i strictly inside the closed polygon ``poly`` (even–odd rule): the number
    of edges (y0 > y) != (y1 > y) with x < x0 + (y − y0)(x1 − x0)/(y1 − y0) is odd."""
    m = poly.shape[0]
    for i in range(pts.shape[0]):
        x = pts[i, 0]
        y = pts[i, 1]
        c = 0
        for j in range(m):
            k = j + 1 if j + 1 < m else 0
            x0 = poly[j, 0]
            y0 = poly[j, 1]
            x1 = poly[k, 0]
            y1 = poly[k, 1]
            if (y0 > y) != (y1 > y):
                xi = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
                if x < xi:
                    c += 1
        out[i] = (c % 2) == 1


@njit(cache=True, nogil=True)
def distance_to_edges(pts, poly, out):  # pragma: no cover - numba
    """out[i] = distance from point i to the nearest edge of the closed polygon ``poly``
    (projection clamped to the segment; edges shorter than 1e-15 count as points).  NaN when a
    NaN appears on the way (a NaN or infinite coordinate), as numpy's ``min`` gives."""
    m = poly.shape[0]
    for i in range(pts.shape[0]):
        x = pts[i, 0]
        y = pts[i, 1]
        best = np.inf
        for j in range(m):
            k = j + 1 if j + 1 < m else 0
            px = poly[j, 0]
            py = poly[j, 1]
            dx = poly[k, 0] - px
            dy = poly[k, 1] - py
            L2 = max(dx * dx + dy * dy, 1e-30)
            t = ((x - px) * dx + (y - py) * dy) / L2
            if t < 0.0:
                t = 0.0
            elif t > 1.0:
                t = 1.0
            ex = x - (px + t * dx)
            ey = y - (py + t * dy)
            d2 = ex * ex + ey * ey
            if d2 != d2:  # NaN: numpy's min propagates it
                best = d2
                break
            if d2 < best:
                best = d2
        out[i] = np.sqrt(best)
