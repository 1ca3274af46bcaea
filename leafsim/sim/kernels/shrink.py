"""Shrink kernels [Jeong eq. 2.10–2.11]: rest lengths, hinge rest angles and thickness rest."""

from __future__ import annotations

import numpy as np
from numba import njit, prange


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


shrink_springs = njit(cache=True, nogil=True, parallel=False, fastmath=True)(_shrink_springs)
shrink_springs_par = njit(cache=True, nogil=True, parallel=True, fastmath=True)(_shrink_springs)


@njit(cache=True, nogil=True, fastmath=True)
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


@njit(cache=True, nogil=True, fastmath=True)
def hinge_targets(hidx, hV, ij, rest0, sig_top, sig_bot, alpha, l_min, cyt, water, w0, m0, h, gain, setw, plastic, hrest):
    """Bilayer rest angle per hinge: θ0 = θ_plastic + gain · (ε_top − ε_bottom) / h · d.
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
        tb = gain * (et - eb) / h * rest0[s]
        if setw > 0.0:
            p = plastic[e]
            if abs(tb) > abs(p) or tb * p < 0.0:
                p += setw * (tb - p)
                plastic[e] = p
            hrest[e] = p
        else:
            hrest[e] = tb


@njit(cache=True, nogil=True, fastmath=True)
def vol_targets(vsp, rest0, rest, vol0, vrest):
    """Thickness constraint rest value follows the in-plane shrink of its triangle (area ∝ l²)."""
    for t in range(vsp.shape[0]):
        f = (rest[vsp[t, 0]] / rest0[vsp[t, 0]] + rest[vsp[t, 1]] / rest0[vsp[t, 1]] + rest[vsp[t, 2]] / rest0[vsp[t, 2]]) / 3.0
        vrest[t] = vol0[t] * f * f
