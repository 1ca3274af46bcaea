"""The lamina's compression (:mod:`leafsim.sim.crinkle`): per blade triangle, the compression
its two principal stretches carry against the triangle of its springs' current rest lengths,
as a tensor over the leaf's flat rest plane, lumped to the particles by area."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _cauchy_green(q, a, b, c, p, r, s):
    """C = Dm⁻ᵀ G Dm⁻¹ (its 00, 01, 11 entries): the right Cauchy–Green tensor of the triangle
    (a, b, c) at ``q`` in its rest triangle's frame, Dm⁻¹ = [[p, r], [0, s]], G the Gram matrix
    of its two edges from a."""
    e1x, e1y, e1z = q[b, 0] - q[a, 0], q[b, 1] - q[a, 1], q[b, 2] - q[a, 2]
    e2x, e2y, e2z = q[c, 0] - q[a, 0], q[c, 1] - q[a, 1], q[c, 2] - q[a, 2]
    g00 = e1x * e1x + e1y * e1y + e1z * e1z
    g01 = e1x * e2x + e1y * e2y + e1z * e2z
    g11 = e2x * e2x + e2y * e2y + e2z * e2z
    return p * p * g00, p * (r * g00 + s * g01), r * r * g00 + 2.0 * r * s * g01 + s * s * g11


@njit(cache=True, nogil=True)
def _rest_compression(c00, c01, c11):
    """K = Σ max(0, 1 − sₖ) uₖ uₖᵀ in the rest frame (xx, xy, yy) from C: sₖ² its eigenvalues,
    K from C's spectral projectors (Sylvester): k₁ on the smaller one's eigenspace, k₂ on the
    larger's; k I when C is isotropic (no direction to pick).  (0, 0, 0) when neither principal
    stretch is below 1."""
    half = 0.5 * (c00 + c11)
    dev = np.sqrt(0.25 * (c00 - c11) * (c00 - c11) + c01 * c01)
    lo = half - dev
    hi = half + dev
    s1 = np.sqrt(lo) if lo > 0.0 else 0.0
    s2 = np.sqrt(hi) if hi > 0.0 else 0.0
    k1 = 1.0 - s1 if s1 < 1.0 else 0.0
    k2 = 1.0 - s2 if s2 < 1.0 else 0.0
    if k1 == 0.0 and k2 == 0.0:
        return 0.0, 0.0, 0.0
    if dev > 1e-12 * half:
        g = (k2 - k1) / (2.0 * dev)  # K = k₁ P_lo + k₂ P_hi = k̄ I + g (C − half I)
        kbar = 0.5 * (k1 + k2)
        return kbar + g * (c00 - half), g * c01, kbar + g * (c11 - half)
    return 0.5 * (k1 + k2), 0.0, 0.5 * (k1 + k2)


@njit(cache=True, nogil=True)
def _to_flat(flat, a, b, c, p, r, s, rxx, rxy, ryy):
    """K from the rest frame to the flat plane: A = Df Dm⁻¹ carries a rest vector to the same
    material line in the flat plane; K turns with A's rotation (its polar factor), which keeps
    its eigenvalues, so a shrink that is not the same every way cannot skew it.  A flat triangle
    that runs the other way round is mirrored in y first."""
    f1x, f1y = flat[b, 0] - flat[a, 0], flat[b, 1] - flat[a, 1]
    f2x, f2y = flat[c, 0] - flat[a, 0], flat[c, 1] - flat[a, 1]
    a11, a12 = f1x * p, f1x * r + f2x * s
    a21, a22 = f1y * p, f1y * r + f2y * s
    if a11 * a22 - a12 * a21 < 0.0:
        a12, a22, rxy = -a12, -a22, -rxy
    cr, sr = a11 + a22, a21 - a12
    nr = np.sqrt(cr * cr + sr * sr)
    if nr > 0.0:
        cr /= nr
        sr /= nr
    else:
        cr, sr = 1.0, 0.0
    # K_flat = R K Rᵀ, R = [[cr, −sr], [sr, cr]]
    return (cr * cr * rxx - 2.0 * cr * sr * rxy + sr * sr * ryy,
            cr * sr * (rxx - ryy) + (cr * cr - sr * sr) * rxy,
            sr * sr * rxx + 2.0 * cr * sr * rxy + cr * cr * ryy)


@njit(cache=True, nogil=True)
def lamina_compression(tri, tri_springs, q, rest, flat, zero, out, area):
    """``out`` (n, 3) = the area-weighted mean over each particle's blade triangles of the
    compression tensor K = Σ max(0, 1 − sₖ) uₖ uₖᵀ (its xx, xy, yy entries), sₖ the principal
    stretches of the triangle (vertices ``tri`` (m, 3)) from its rest shape, the triangle whose
    sides are the rest lengths ``rest`` of its springs ``tri_springs`` (m, 3: a–b, b–c, c–a), to
    its shape at ``q``, and uₖ their directions, turned into the flat rest plane ``flat`` (n, 2)
    by the rotation that carries the rest triangle onto its flat one (the polar factor of that
    map: K keeps its eigenvalues).  ½ tr K is the excess length
    ½ (max(0, 1 − s₁) + max(0, 1 − s₂)).  Particles with ``zero`` set get 0; so do particles
    of no triangle.  ``area`` (n,) is scratch (the rest area each particle's triangles lump to it).
    Stages per triangle: the rest triangle from its springs, :func:`_cauchy_green`,
    :func:`_rest_compression`, :func:`_to_flat`, then the lumping."""
    n = out.shape[0]
    for i in range(n):
        out[i, 0] = 0.0
        out[i, 1] = 0.0
        out[i, 2] = 0.0
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
        c00, c01, c11 = _cauchy_green(q, a, b, c, p, r, s)
        rxx, rxy, ryy = _rest_compression(c00, c01, c11)
        if rxx == 0.0 and rxy == 0.0 and ryy == 0.0:
            kxx = kxy = kyy = 0.0
        else:
            kxx, kxy, kyy = _to_flat(flat, a, b, c, p, r, s, rxx, rxy, ryy)
        A = 0.5 * lab * cy
        for v in (a, b, c):
            out[v, 0] += A * kxx
            out[v, 1] += A * kxy
            out[v, 2] += A * kyy
            area[v] += A
    for i in range(n):
        if zero[i] or area[i] <= 0.0:
            out[i, 0] = 0.0
            out[i, 1] = 0.0
            out[i, 2] = 0.0
        else:
            out[i, 0] /= area[i]
            out[i, 1] /= area[i]
            out[i, 2] /= area[i]
