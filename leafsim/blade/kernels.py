"""Kernels used while building a blade: Poisson-disk acceptance and greedy graph colouring."""

from __future__ import annotations

import numpy as np
from numba import njit

from leafsim.base.cache import configure_numba_cache

configure_numba_cache()  # before the first @njit(cache=True): the cache folder keyed to the kernel sources


@njit(cache=True, nogil=True)
def poisson_accept(cand, fixed, r, lo, hi):
    """Greedy dart throwing: accept candidates (k,2) in order if ≥ r from every fixed and
    previously accepted point.  A background grid of cell r/√2 makes it O(k).  Returns a mask."""
    cell = r / np.sqrt(2.0)
    nx = int((hi[0] - lo[0]) / cell) + 3
    ny = int((hi[1] - lo[1]) / cell) + 3
    # up to 4 points per cell for fixed points (they may be closer than r to each other)
    cap = 6
    grid = -np.ones((nx, ny, cap), np.int64)
    cnt = np.zeros((nx, ny), np.int64)
    npts = fixed.shape[0] + cand.shape[0]
    pts = np.empty((npts, 2))
    m = 0
    for i in range(fixed.shape[0]):
        gx = int((fixed[i, 0] - lo[0]) / cell) + 1
        gy = int((fixed[i, 1] - lo[1]) / cell) + 1
        pts[m] = fixed[i]
        if cnt[gx, gy] < cap:
            grid[gx, gy, cnt[gx, gy]] = m
            cnt[gx, gy] += 1
        m += 1
    ok = np.zeros(cand.shape[0], np.bool_)
    r2 = r * r
    for i in range(cand.shape[0]):
        x, y = cand[i, 0], cand[i, 1]
        gx = int((x - lo[0]) / cell) + 1
        gy = int((y - lo[1]) / cell) + 1
        good = True
        for ix in range(max(gx - 2, 0), min(gx + 3, nx)):
            for iy in range(max(gy - 2, 0), min(gy + 3, ny)):
                for k in range(cnt[ix, iy]):
                    j = grid[ix, iy, k]
                    dx = pts[j, 0] - x
                    dy = pts[j, 1] - y
                    if dx * dx + dy * dy < r2:
                        good = False
                        break
                if not good:
                    break
            if not good:
                break
        if good and cnt[gx, gy] < cap:
            ok[i] = True
            pts[m, 0] = x
            pts[m, 1] = y
            grid[gx, gy, cnt[gx, gy]] = m
            cnt[gx, gy] += 1
            m += 1
    return ok


@njit(cache=True, nogil=True)
def greedy_colour(idx, n):
    """Colour constraints (k, p) particle indices so that no two constraints of one colour
    share a particle (negative indices ignored).  Returns colour (k,) int64."""
    k, p = idx.shape
    used = np.zeros(n, np.uint64)  # bitmask of colours touching each particle (≤ 64 per pass)
    colour = -np.ones(k, np.int64)
    base = 0
    remaining = k
    while remaining > 0:
        used[:] = 0
        for c in range(k):
            if colour[c] >= 0:
                continue
            mask = np.uint64(0)
            for q in range(p):
                j = idx[c, q]
                if j >= 0:
                    mask |= used[j]
            b = 0
            while b < 64 and (mask >> np.uint64(b)) & np.uint64(1):
                b += 1
            if b < 64:
                colour[c] = base + b
                remaining -= 1
                for q in range(p):
                    j = idx[c, q]
                    if j >= 0:
                        used[j] |= np.uint64(1) << np.uint64(b)
        base += 64
    return colour
