"""Shrink kernels [Jeong eq. 2.10–2.11]: rest lengths, hinge rest angles and thickness rest."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from leafsim.sim.kernels import FASTMATH


def _shrink_springs(ij, rest0, sigma, alpha, l_min, cyt, water, m0, rest):
    """rest[s] = l0 (1 − σ (1 − v_rel)^α) clamped to [l_min l0, l0]; v_rel from mass ratio."""
    n = cyt.shape[0]
    mass = np.empty(n)  # one pass over particles: 4 instead of 6 random loads per spring
    for i in prange(n):
        mass[i] = cyt[i] + water[i]
    for s in prange(ij.shape[0]):
        a = ij[s, 0]
        b = ij[s, 1]
        v = (mass[a] + mass[b]) / (m0[a] + m0[b])
        d = 1.0 - v
        if d < 0.0:
            d = 0.0
        if alpha != 1.0:
            d = d ** alpha
        f = 1.0 - sigma[s] * d
        if f < l_min:
            f = l_min
        if f > 1.0:
            f = 1.0
        rest[s] = rest0[s] * f


#: serial in production (``prange`` runs as ``range``): its parallel twin, compiled by the bench
#: (:func:`leafsim.measure.parallel.parallel_twin`), lost under load (docs/performance.md)
shrink_springs = njit(cache=True, nogil=True, parallel=False, fastmath=FASTMATH)(_shrink_springs)


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def _strain(sigma, alpha, l_min, m, m0):
    d = 1.0 - m / m0
    if d < 0.0:
        d = 0.0
    if alpha != 1.0:
        d = d ** alpha
    e = sigma * d
    if e > 1.0 - l_min:
        e = 1.0 - l_min
    return e


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def hinge_targets(hidx, hV, ij, rest0, sig_top, sig_bot, alpha, l_min, cyt, water, w0, m0, h, gain, setw, plastic, hrest):
    """Bilayer rest angle per hinge: θ0 = θ_plastic + gain · (ε_top − ε_bottom) / h · d, h the
    current thickness h⁰ (1 − ε_bottom).
    ε_top: surface shrink strain of the top layer from the two V particles over the hinge,
    ε_bottom: of the bottom layer from the hinge's four T particles (same law as the springs),
    d: rest distance of the two triangle centroids (Timoshenko bimetal curvature × arc).
    Drying tissue sets (``setw`` = plasticity rate × Δt > 0): the hinge remembers the largest
    bilayer angle it reached, P ← P + setw (θ_bilayer − P) while |θ_bilayer| > |P|, and uses P
    as its target, so a curl reached while the top dried first lasts when both layers are dry.
    """
    for e in range(hidx.shape[0]):
        s = hV[e]
        va = ij[s, 0]
        vb = ij[s, 1]
        mt = cyt[va] + water[va] + cyt[vb] + water[vb]
        mt0 = m0[va] + m0[vb]
        mb = 0.0
        mb0 = 0.0
        ww = 0.0
        ww0 = 0.0
        for k in range(4):
            j = hidx[e, k]
            mb += cyt[j] + water[j]
            mb0 += m0[j]
            ww += water[j]
            ww0 += w0[j]
        et = _strain(sig_top, alpha, l_min, mt, mt0)
        eb = _strain(sig_bot, alpha, l_min, mb, mb0)
        tb = gain * (et - eb) / (h * max(1.0 - eb, 0.05)) * rest0[s]  # thickness shrinks with the tissue
        if setw > 0.0:
            p = plastic[e]
            if abs(tb) > abs(p) or tb * p < 0.0:
                p += setw * (tb - p)
                plastic[e] = p
            hrest[e] = p
        else:
            hrest[e] = tb


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def tri_ratios(tri_springs, rest0, rest, out):
    """out[k, j] = rest / rest⁰ of the j-th T spring of the triangle under V particle k (already
    updated in ``rest``): the in-plane shrink the links, top-surface springs and thickness
    volumes follow, gathered once per triangle instead of once per reader (a triangle is read
    by three links, up to three hinges and one volume; the readers sum the same quotients in
    the same order as when each divided for itself, so the rest values are bit-identical)."""
    for k in range(tri_springs.shape[0]):
        for j in range(3):
            t = tri_springs[k, j]
            out[k, j] = rest[t] / rest0[t]


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def vol_targets(vtri, ratios, vol0, vrest):
    """Thickness constraint rest value (6 × prism volume) follows the isotropic shrink of its
    triangle (``vtri``: the row of :func:`tri_ratios` of each volume): area ∝ f², thickness ∝ f."""
    for t in range(vtri.shape[0]):
        k = vtri[t]
        f = (ratios[k, 0] + ratios[k, 1] + ratios[k, 2]) / 3.0
        vrest[t] = vol0[t] * f * f * f


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def link_targets(links, link_tri, ratios, rest0, rest):
    """Rest length of each link V → T vertex: the tissue shrinks isotropically with its
    bottom layer, in the plane and through the thickness, so a link (the triangle's
    cross-section) scales with the mean ratio f of its triangle's three T springs
    (``link_tri``: the row of :func:`tri_ratios` of each link): l = l⁰ f."""
    for k in range(links.shape[0]):
        s = links[k]
        r = link_tri[k]
        f = 0.0
        for j in range(3):
            f += ratios[r, j]
        rest[s] = rest0[s] * f / 3.0


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def dual_targets(hV, ij, nT, ratios, rest0, hrest, h, rest):
    """Rest length of each V spring (the top surface across hinge e): the dual edge bent to the
    hinge's rest angle θ0 at the current thickness f h, f (d0 − h θ0) (a strip of curvature
    θ0/(f d0) is shorter by that on its upper side), f the in-plane shrink of the T layer under
    it (the mean ratio of the two triangles' T springs, rows of :func:`tri_ratios`)."""
    for e in range(hV.shape[0]):
        s = hV[e]
        f = 0.0
        for v in (ij[s, 0], ij[s, 1]):
            for j in range(3):
                f += ratios[v - nT, j]
        f /= 6.0
        d = rest0[s] - h * hrest[e]
        if d < 0.1 * rest0[s]:
            d = 0.1 * rest0[s]
        rest[s] = f * d
