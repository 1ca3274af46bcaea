"""The lamina's excess length (:mod:`leafsim.sim.crinkle`): per blade triangle, the compression
its two principal stretches carry against the triangle of its springs' current rest lengths,
lumped to the particles by area."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def lamina_excess(tri, tri_springs, q, rest, zero, out, area):
    """``out`` (n,) = the area-weighted mean over each particle's blade triangles of
    ½ (max(0, 1 − s₁) + max(0, 1 − s₂)), s₁ ≤ s₂ the principal stretches of the triangle
    (vertices ``tri`` (m, 3)) from its rest shape, the triangle whose sides are the rest lengths
    ``rest`` of its springs ``tri_springs`` (m, 3: a–b, b–c, c–a), to its shape at ``q``.
    Particles with ``zero`` set get 0; so do particles of no triangle.  ``area`` (n,) is
    scratch (the rest area each particle's triangles lump to it)."""
    n = out.shape[0]
    for i in range(n):
        out[i] = 0.0
        area[i] = 0.0
    for t in range(tri.shape[0]):
        a, b, c = tri[t, 0], tri[t, 1], tri[t, 2]
        lab, lbc, lca = rest[tri_springs[t, 0]], rest[tri_springs[t, 1]], rest[tri_springs[t, 2]]
        if lab <= 0.0:
            continue
        cx = (lab * lab + lca * lca - lbc * lbc) / (2.0 * lab)
        cy2 = lca * lca - cx * cx
        if cy2 <= 1e-12 * lab * lab:  # a degenerate rest triangle carries nothing
            continue
        cy = np.sqrt(cy2)
        # the rest triangle a = (0, 0), b = (lab, 0), c = (cx, cy); Dm⁻¹ = [[p, r], [0, s]]
        p = 1.0 / lab
        r = -cx / (lab * cy)
        s = 1.0 / cy
        e1x, e1y, e1z = q[b, 0] - q[a, 0], q[b, 1] - q[a, 1], q[b, 2] - q[a, 2]
        e2x, e2y, e2z = q[c, 0] - q[a, 0], q[c, 1] - q[a, 1], q[c, 2] - q[a, 2]
        g00 = e1x * e1x + e1y * e1y + e1z * e1z
        g01 = e1x * e2x + e1y * e2y + e1z * e2z
        g11 = e2x * e2x + e2y * e2y + e2z * e2z
        # C = Dm⁻ᵀ G Dm⁻¹, the right Cauchy–Green tensor in the rest triangle's frame
        c00 = p * p * g00
        c01 = p * (r * g00 + s * g01)
        c11 = r * r * g00 + 2.0 * r * s * g01 + s * s * g11
        half = 0.5 * (c00 + c11)
        dev = np.sqrt(0.25 * (c00 - c11) * (c00 - c11) + c01 * c01)
        lo = half - dev
        hi = half + dev
        s1 = np.sqrt(lo) if lo > 0.0 else 0.0
        s2 = np.sqrt(hi) if hi > 0.0 else 0.0
        d = 0.0
        if s1 < 1.0:
            d += 1.0 - s1
        if s2 < 1.0:
            d += 1.0 - s2
        A = 0.5 * lab * cy
        w = A * 0.5 * d
        for v in (a, b, c):
            out[v] += w
            area[v] += A
    for i in range(n):
        if zero[i] or area[i] <= 0.0:
            out[i] = 0.0
        else:
            out[i] /= area[i]
