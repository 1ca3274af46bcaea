"""Frozen copy of :mod:`leafsim.sim.kernels.pbd` as it was before the speed work (issue 10):
the reference every rewritten kernel is checked against (same inputs → same outputs to
round-off) in ``tests/test_kernels.py``.  Not used by the library; do not edit."""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from leafsim.base.cache import configure_numba_cache

configure_numba_cache()  # before the first @njit(cache=True): the cache folder keyed to the kernel sources


@njit(cache=True, nogil=True, fastmath=True)
def predict(q, qd, q_old, invm, gz, dt):
    for i in range(q.shape[0]):
        for k in range(3):
            q_old[i, k] = q[i, k]
        if invm[i] > 0.0:
            qd[i, 2] += gz * dt
            for k in range(3):
                q[i, k] += qd[i, k] * dt


# ---------------------------------------------------------------- one constraint each
# Inlined into every loop variant below (parallel colour loops write the change into an
# array, serial loops track the largest inline); each returns |Δx| of its projection.

@njit(inline="always", fastmath=True)
def _spring(q, invm, ij, rest, salpha, slam, s):
    a = ij[s, 0]
    b = ij[s, 1]
    wa = invm[a]
    wb = invm[b]
    dx = q[a, 0] - q[b, 0]
    dy = q[a, 1] - q[b, 1]
    dz = q[a, 2] - q[b, 2]
    d = math.sqrt(dx * dx + dy * dy + dz * dz)
    W = wa + wb + salpha[s]
    if d < 1e-12 or W <= 0.0:
        return 0.0
    C = d - rest[s]
    dl = (-C - salpha[s] * slam[s]) / W
    slam[s] += dl
    f = dl / d
    q[a, 0] += wa * f * dx
    q[a, 1] += wa * f * dy
    q[a, 2] += wa * f * dz
    q[b, 0] -= wb * f * dx
    q[b, 1] -= wb * f * dy
    q[b, 2] -= wb * f * dz
    return abs(dl) * max(wa, wb)


@njit(inline="always", fastmath=True)
def _hinge_geom(q, hidx, e):
    """Signed dihedral angle θ of hinge e = (x1, x2; x3–x4) and its gradients u1…u4 (Bridson
    et al. 2003); also |e| and the wing gradient scales for the step limit.  ``ok`` False for a
    degenerate hinge."""
    i1 = hidx[e, 0]
    i2 = hidx[e, 1]
    i3 = hidx[e, 2]
    i4 = hidx[e, 3]
    ex = q[i4, 0] - q[i3, 0]
    ey = q[i4, 1] - q[i3, 1]
    ez = q[i4, 2] - q[i3, 2]
    el = math.sqrt(ex * ex + ey * ey + ez * ez)
    # n1 = (x1 - x3) x (x1 - x4), n2 = (x2 - x4) x (x2 - x3)
    ax = q[i1, 0] - q[i3, 0]; ay = q[i1, 1] - q[i3, 1]; az = q[i1, 2] - q[i3, 2]
    bx = q[i1, 0] - q[i4, 0]; by = q[i1, 1] - q[i4, 1]; bz = q[i1, 2] - q[i4, 2]
    n1x = ay * bz - az * by; n1y = az * bx - ax * bz; n1z = ax * by - ay * bx
    cx = q[i2, 0] - q[i4, 0]; cy = q[i2, 1] - q[i4, 1]; cz = q[i2, 2] - q[i4, 2]
    dx = q[i2, 0] - q[i3, 0]; dy = q[i2, 1] - q[i3, 1]; dz = q[i2, 2] - q[i3, 2]
    n2x = cy * dz - cz * dy; n2y = cz * dx - cx * dz; n2z = cx * dy - cy * dx
    l1 = n1x * n1x + n1y * n1y + n1z * n1z
    l2 = n2x * n2x + n2y * n2y + n2z * n2z
    if el < 1e-12 or l1 < 1e-30 or l2 < 1e-30:
        return (False, 0.0, el, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    s1 = math.sqrt(l1)
    s2 = math.sqrt(l2)
    cosv = (n1x * n2x + n1y * n2y + n1z * n2z) / (s1 * s2)
    # sin = (n2 x n1) . e / |e|
    kx = n2y * n1z - n2z * n1y
    ky = n2z * n1x - n2x * n1z
    kz = n2x * n1y - n2y * n1x
    sinv = (kx * ex + ky * ey + kz * ez) / (s1 * s2 * el)
    th = math.atan2(sinv, cosv)
    g1 = el / l1
    g2 = el / l2
    t31 = (bx * ex + by * ey + bz * ez) / el  # (x1 - x4).e/|e|
    t32 = (cx * ex + cy * ey + cz * ez) / el  # (x2 - x4).e/|e|
    t41 = (ax * ex + ay * ey + az * ez) / el  # (x1 - x3).e/|e|
    t42 = (dx * ex + dy * ey + dz * ez) / el  # (x2 - x3).e/|e|
    p1 = t31 / l1; p2 = t32 / l2
    r1 = -t41 / l1; r2 = -t42 / l2
    return (True, th, el, g1 * n1x, g1 * n1y, g1 * n1z, g2 * n2x, g2 * n2y, g2 * n2z,
            p1 * n1x + p2 * n2x, p1 * n1y + p2 * n2y, p1 * n1z + p2 * n2z,
            r1 * n1x + r2 * n2x, r1 * n1y + r2 * n2y, r1 * n1z + r2 * n2z, g1 * s1, g2 * s2)


@njit(inline="always", fastmath=True)
def _hinge_move(q, invm, hidx, e, dl, u1x, u1y, u1z, u2x, u2y, u2z, u3x, u3y, u3z, u4x, u4y, u4z):
    i1 = hidx[e, 0]; i2 = hidx[e, 1]; i3 = hidx[e, 2]; i4 = hidx[e, 3]
    w1 = invm[i1] * dl; w2 = invm[i2] * dl; w3 = invm[i3] * dl; w4 = invm[i4] * dl
    q[i1, 0] += w1 * u1x; q[i1, 1] += w1 * u1y; q[i1, 2] += w1 * u1z
    q[i2, 0] += w2 * u2x; q[i2, 1] += w2 * u2y; q[i2, 2] += w2 * u2z
    q[i3, 0] += w3 * u3x; q[i3, 1] += w3 * u3y; q[i3, 2] += w3 * u3z
    q[i4, 0] += w4 * u4x; q[i4, 1] += w4 * u4y; q[i4, 2] += w4 * u4z


@njit(inline="always", fastmath=True)
def _hinge_step_limit(invm, hidx, e, dl, el, u1x, u1y, u1z, u2x, u2y, u2z, u3x, u3y, u3z, u4x, u4y, u4z):
    """Degenerate hinges: never move a vertex by more than half the edge length."""
    gm = max(invm[hidx[e, 0]] * math.sqrt(u1x * u1x + u1y * u1y + u1z * u1z),
             invm[hidx[e, 1]] * math.sqrt(u2x * u2x + u2y * u2y + u2z * u2z),
             invm[hidx[e, 2]] * math.sqrt(u3x * u3x + u3y * u3y + u3z * u3z),
             invm[hidx[e, 3]] * math.sqrt(u4x * u4x + u4y * u4y + u4z * u4z))
    if abs(dl) * gm > 0.5 * el:
        return math.copysign(0.5 * el / gm, dl)
    return dl


@njit(inline="always", fastmath=True)
def _hinge(q, invm, hidx, hrest, halpha, hlam, e, omega):
    ok, th, el, u1x, u1y, u1z, u2x, u2y, u2z, u3x, u3y, u3z, u4x, u4y, u4z, k1, k2 = _hinge_geom(q, hidx, e)
    if not ok:
        return 0.0
    C = th - hrest[e]
    if C > math.pi:
        C -= 2 * math.pi
    elif C < -math.pi:
        C += 2 * math.pi
    w1 = invm[hidx[e, 0]]; w2 = invm[hidx[e, 1]]; w3 = invm[hidx[e, 2]]; w4 = invm[hidx[e, 3]]
    W = (w1 * (u1x * u1x + u1y * u1y + u1z * u1z) + w2 * (u2x * u2x + u2y * u2y + u2z * u2z)
         + w3 * (u3x * u3x + u3y * u3y + u3z * u3z) + w4 * (u4x * u4x + u4y * u4y + u4z * u4z) + halpha[e])
    if W <= 0.0:
        return 0.0
    dl = _hinge_step_limit(invm, hidx, e, omega * (-C - halpha[e] * hlam[e]) / W, el,
                           u1x, u1y, u1z, u2x, u2y, u2z, u3x, u3y, u3z, u4x, u4y, u4z)
    hlam[e] += dl
    _hinge_move(q, invm, hidx, e, dl, u1x, u1y, u1z, u2x, u2y, u2z, u3x, u3y, u3z, u4x, u4y, u4z)
    return abs(dl) * max(w1 * k1, w2 * k2)


@njit(inline="always", fastmath=True)
def _volume(q, invm, vidx, vrest, t):
    iv = vidx[t, 0]
    ia = vidx[t, 1]
    ib = vidx[t, 2]
    ic = vidx[t, 3]
    bx = q[ib, 0] - q[ia, 0]; by = q[ib, 1] - q[ia, 1]; bz = q[ib, 2] - q[ia, 2]
    cx = q[ic, 0] - q[ia, 0]; cy = q[ic, 1] - q[ia, 1]; cz = q[ic, 2] - q[ia, 2]
    vx = q[iv, 0] - q[ia, 0]; vy = q[iv, 1] - q[ia, 1]; vz = q[iv, 2] - q[ia, 2]
    gvx = by * cz - bz * cy; gvy = bz * cx - bx * cz; gvz = bx * cy - by * cx
    gbx = cy * vz - cz * vy; gby = cz * vx - cx * vz; gbz = cx * vy - cy * vx
    gcx = vy * bz - vz * by; gcy = vz * bx - vx * bz; gcz = vx * by - vy * bx
    gax = -(gvx + gbx + gcx); gay = -(gvy + gby + gcy); gaz = -(gvz + gbz + gcz)
    C = vx * gvx + vy * gvy + vz * gvz - vrest[t]
    wv = invm[iv]; wa = invm[ia]; wb = invm[ib]; wc = invm[ic]
    W = (wv * (gvx * gvx + gvy * gvy + gvz * gvz) + wa * (gax * gax + gay * gay + gaz * gaz)
         + wb * (gbx * gbx + gby * gby + gbz * gbz) + wc * (gcx * gcx + gcy * gcy + gcz * gcz))
    if W <= 1e-300:
        return 0.0
    dl = -C / W
    gm = max(wv * math.sqrt(gvx * gvx + gvy * gvy + gvz * gvz), wa * math.sqrt(gax * gax + gay * gay + gaz * gaz),
             wb * math.sqrt(gbx * gbx + gby * gby + gbz * gbz), wc * math.sqrt(gcx * gcx + gcy * gcy + gcz * gcz))
    lim = 0.5 * math.sqrt(math.sqrt(bx * bx + by * by + bz * bz) * math.sqrt(cx * cx + cy * cy + cz * cz))
    if abs(dl) * gm > lim:
        dl = math.copysign(lim / gm, dl)
    q[iv, 0] += wv * dl * gvx; q[iv, 1] += wv * dl * gvy; q[iv, 2] += wv * dl * gvz
    q[ia, 0] += wa * dl * gax; q[ia, 1] += wa * dl * gay; q[ia, 2] += wa * dl * gaz
    q[ib, 0] += wb * dl * gbx; q[ib, 1] += wb * dl * gby; q[ib, 2] += wb * dl * gbz
    q[ic, 0] += wc * dl * gcx; q[ic, 1] += wc * dl * gcy; q[ic, 2] += wc * dl * gcz
    return abs(dl) * wv * math.sqrt(gvx * gvx + gvy * gvy + gvz * gvz)


def _iteration(q, invm, ij, rest, salpha, slam, scs,
               hidx, hrest, halpha, hlam, hcs, omega,
               vidx, vrest, vlam, vcs, change):
    """One Gauss–Seidel pass over all constraints, colour by colour.  ``salpha``/``halpha`` are
    compliances already divided by Δt².  Writes |Δx| per constraint into ``change`` (size ≥
    max count) and returns the largest."""
    big = 0.0
    # ---------------- distance constraints
    for c in range(scs.shape[0] - 1):
        for s in prange(scs[c], scs[c + 1]):
            change[s] = _spring(q, invm, ij, rest, salpha, slam, s)
    for s in range(scs[-1]):
        if change[s] > big:
            big = change[s]
    # ---------------- bending hinges (c, d, a, b): signed dihedral angle, cup (wings up) > 0
    for c in range(hcs.shape[0] - 1):
        for e in prange(hcs[c], hcs[c + 1]):
            change[e] = _hinge(q, invm, hidx, hrest, halpha, hlam, e, omega)
    for e in range(hcs[-1]):
        if change[e] > big:
            big = change[e]
    # ---------------- thickness: 6 × volume of (v, a, b, c) = det, keeps V on the top side
    for c in range(vcs.shape[0] - 1):
        for t in prange(vcs[c], vcs[c + 1]):
            change[t] = _volume(q, invm, vidx, vrest, t)
    for t in range(vcs[-1]):
        if change[t] > big:
            big = change[t]
    return big


iteration_par = njit(cache=True, nogil=True, parallel=True, fastmath=True)(_iteration)


@njit(cache=True, nogil=True, fastmath=True)
def iteration_ser(q, invm, ij, rest, salpha, slam, scs,
                  hidx, hrest, halpha, hlam, hcs, omega,
                  vidx, vrest, vlam, vcs, change):
    """Serial twin of :func:`_iteration` (same projection, same order; ``prange`` → ``range``
    and the largest change tracked inline, so ``change`` is not written and not scanned —
    keep the two in sync).  Returns the largest |Δx| of the pass.  Write-up of the
    arguments: :func:`_iteration`."""
    big = 0.0
    # ---------------- distance constraints
    for c in range(scs.shape[0] - 1):
        for s in range(scs[c], scs[c + 1]):
            ch = _spring(q, invm, ij, rest, salpha, slam, s)
            if ch > big:
                big = ch
    # ---------------- bending hinges (c, d, a, b): signed dihedral angle, cup (wings up) > 0
    for c in range(hcs.shape[0] - 1):
        for e in range(hcs[c], hcs[c + 1]):
            ch = _hinge(q, invm, hidx, hrest, halpha, hlam, e, omega)
            if ch > big:
                big = ch
    # ---------------- thickness: 6 × volume of (v, a, b, c) = det, keeps V on the top side
    for c in range(vcs.shape[0] - 1):
        for t in range(vcs[c], vcs[c + 1]):
            ch = _volume(q, invm, vidx, vrest, t)
            if ch > big:
                big = ch
    return big


def _springs_only(q, invm, ij, rest, salpha, slam, scs, change):
    """Distance constraints only (the benchmark's PBD pass)."""
    for c in range(scs.shape[0] - 1):
        for s in prange(scs[c], scs[c + 1]):
            change[s] = _spring(q, invm, ij, rest, salpha, slam, s)
    big = 0.0
    for s in range(scs[-1]):
        if change[s] > big:
            big = change[s]
    return big


springs_par = njit(cache=True, nogil=True, parallel=True, fastmath=True)(_springs_only)
springs_ser = njit(cache=True, nogil=True, parallel=False, fastmath=True)(_springs_only)


@njit(cache=True, nogil=True, parallel=True, fastmath=True)
def jacobi_springs(q, invm, ij, rest, salpha, slam, adj_ptr, adj_s, adj_sign, dq):
    """Atomics-free Jacobi pass: per-spring correction, then per-particle gather (CSR)."""
    ns = ij.shape[0]
    for s in prange(ns):
        a = ij[s, 0]
        b = ij[s, 1]
        dx = q[a, 0] - q[b, 0]
        dy = q[a, 1] - q[b, 1]
        dz = q[a, 2] - q[b, 2]
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        W = invm[a] + invm[b] + salpha[s]
        if d < 1e-12 or W <= 0.0:
            dq[s, 0] = 0.0; dq[s, 1] = 0.0; dq[s, 2] = 0.0
            continue
        dl = (rest[s] - d - salpha[s] * slam[s]) / W
        slam[s] += dl
        f = dl / d
        dq[s, 0] = f * dx; dq[s, 1] = f * dy; dq[s, 2] = f * dz
    for i in prange(q.shape[0]):
        w = invm[i]
        n = adj_ptr[i + 1] - adj_ptr[i]
        if n == 0:
            continue
        sx = 0.0; sy = 0.0; sz = 0.0
        for k in range(adj_ptr[i], adj_ptr[i + 1]):
            s = adj_s[k]
            g = adj_sign[k]
            sx += g * dq[s, 0]; sy += g * dq[s, 1]; sz += g * dq[s, 2]
        # averaged (Jacobi) with relaxation 1.5 / n
        f = 1.5 * w / n
        q[i, 0] += f * sx; q[i, 1] += f * sy; q[i, 2] += f * sz


@njit(cache=True, nogil=True, fastmath=True)
def ground_friction(q, q_old, pen, mu):
    """Coulomb friction for particles that touched the ground this frame (PBD style)."""
    for i in range(q.shape[0]):
        p = pen[i]
        if p <= 0.0:
            continue
        dx = q[i, 0] - q_old[i, 0]
        dy = q[i, 1] - q_old[i, 1]
        t = math.sqrt(dx * dx + dy * dy)
        lim = mu * p
        if t <= lim:
            q[i, 0] = q_old[i, 0]
            q[i, 1] = q_old[i, 1]
        else:
            f = lim / t
            q[i, 0] -= f * dx
            q[i, 1] -= f * dy
        pen[i] = 0.0


@njit(cache=True, nogil=True, fastmath=True)
def update_velocity(q, q_old, qd, dt, keep):
    inv = 1.0 / dt
    for i in range(q.shape[0]):
        for k in range(3):
            qd[i, k] = (q[i, k] - q_old[i, k]) * inv * keep


@njit(cache=True, nogil=True, fastmath=True)
def voronoi_heights(q, vidx, hgt):
    """Signed height of each V particle above its triangle's plane (store before projection)."""
    for t in range(vidx.shape[0]):
        iv, ia, ib, ic = vidx[t, 0], vidx[t, 1], vidx[t, 2], vidx[t, 3]
        bx = q[ib, 0] - q[ia, 0]; by = q[ib, 1] - q[ia, 1]; bz = q[ib, 2] - q[ia, 2]
        cx = q[ic, 0] - q[ia, 0]; cy = q[ic, 1] - q[ia, 1]; cz = q[ic, 2] - q[ia, 2]
        nx = by * cz - bz * cy; ny = bz * cx - bx * cz; nz = bx * cy - by * cx
        nl = math.sqrt(nx * nx + ny * ny + nz * nz) + 1e-300
        hgt[t] = ((q[iv, 0] - q[ia, 0]) * nx + (q[iv, 1] - q[ia, 1]) * ny + (q[iv, 2] - q[ia, 2]) * nz) / nl


@njit(cache=True, nogil=True, fastmath=True)
def voronoi_replace(q, vidx, hgt, hmin):
    """Thesis re-placement: x_V = centroid + max(h_i, hmin) n_F (after the velocity update)."""
    for t in range(vidx.shape[0]):
        iv, ia, ib, ic = vidx[t, 0], vidx[t, 1], vidx[t, 2], vidx[t, 3]
        bx = q[ib, 0] - q[ia, 0]; by = q[ib, 1] - q[ia, 1]; bz = q[ib, 2] - q[ia, 2]
        cx = q[ic, 0] - q[ia, 0]; cy = q[ic, 1] - q[ia, 1]; cz = q[ic, 2] - q[ia, 2]
        nx = by * cz - bz * cy; ny = bz * cx - bx * cz; nz = bx * cy - by * cx
        nl = math.sqrt(nx * nx + ny * ny + nz * nz)
        if nl < 1e-300:
            continue
        h = hgt[t]
        if h < hmin:
            h = hmin
        for k, nk in ((0, nx), (1, ny), (2, nz)):
            q[iv, k] = (q[ia, k] + q[ib, k] + q[ic, k]) / 3.0 + h * nk / nl


@njit(cache=True, nogil=True, parallel=True, fastmath=True)
def residual(q, ij, rest):
    """max |C| / l over springs."""
    out = np.empty(ij.shape[0])
    for s in prange(ij.shape[0]):
        a = ij[s, 0]
        b = ij[s, 1]
        dx = q[a, 0] - q[b, 0]; dy = q[a, 1] - q[b, 1]; dz = q[a, 2] - q[b, 2]
        out[s] = abs(math.sqrt(dx * dx + dy * dy + dz * dz) - rest[s]) / max(rest[s], 1e-30)
    return out.max() if out.shape[0] else 0.0


@njit(cache=True, nogil=True)
def dihedral_angles(q, hidx):
    """Signed dihedral angle per hinge (same convention as the projection)."""
    out = np.empty(hidx.shape[0])
    for e in range(hidx.shape[0]):
        i1, i2, i3, i4 = hidx[e, 0], hidx[e, 1], hidx[e, 2], hidx[e, 3]
        ev = q[i4] - q[i3]
        n1 = np.cross(q[i1] - q[i3], q[i1] - q[i4])
        n2 = np.cross(q[i2] - q[i4], q[i2] - q[i3])
        s = np.sqrt((n1 * n1).sum() * (n2 * n2).sum()) + 1e-300
        out[e] = math.atan2((np.cross(n2, n1) * ev).sum() / (s * np.sqrt((ev * ev).sum()) + 1e-300), (n1 * n2).sum() / s)
    return out


@njit(cache=True, nogil=True, fastmath=True)
def uninvert(q, invm, vidx, hmin, vonly, ground):
    """Guard against layer inversion: a V particle closer than ``hmin`` to (or below) its
    triangle's plane is projected to height ``hmin`` (inverse-mass weighted between the V
    particle and the triangle, so momentum is conserved; with ``ground`` a vertex resting on
    the ground is not pushed into it).  Returns how many were corrected."""
    moved = 0
    for t in range(vidx.shape[0]):
        iv, ia, ib, ic = vidx[t, 0], vidx[t, 1], vidx[t, 2], vidx[t, 3]
        bx = q[ib, 0] - q[ia, 0]; by = q[ib, 1] - q[ia, 1]; bz = q[ib, 2] - q[ia, 2]
        cx = q[ic, 0] - q[ia, 0]; cy = q[ic, 1] - q[ia, 1]; cz = q[ic, 2] - q[ia, 2]
        nx = by * cz - bz * cy; ny = bz * cx - bx * cz; nz = bx * cy - by * cx
        nl = math.sqrt(nx * nx + ny * ny + nz * nz)
        if nl < 1e-14:
            continue
        nx /= nl; ny /= nl; nz /= nl
        h = ((q[iv, 0] - (q[ia, 0] + q[ib, 0] + q[ic, 0]) / 3.0) * nx + (q[iv, 1] - (q[ia, 1] + q[ib, 1] + q[ic, 1]) / 3.0) * ny
             + (q[iv, 2] - (q[ia, 2] + q[ib, 2] + q[ic, 2]) / 3.0) * nz)
        if h < hmin:
            wa = 0.0 if vonly or (ground and nz > 0.0 and q[ia, 2] <= 1e-12) else invm[ia]
            wb = 0.0 if vonly or (ground and nz > 0.0 and q[ib, 2] <= 1e-12) else invm[ib]
            wc = 0.0 if vonly or (ground and nz > 0.0 and q[ic, 2] <= 1e-12) else invm[ic]
            W = invm[iv] + (wa + wb + wc) / 9.0
            if W <= 0.0:
                continue
            dl = (hmin - h) / W
            f = invm[iv] * dl
            q[iv, 0] += f * nx; q[iv, 1] += f * ny; q[iv, 2] += f * nz
            for j, wj in ((ia, wa), (ib, wb), (ic, wc)):
                g = -wj * dl / 3.0
                q[j, 0] += g * nx; q[j, 1] += g * ny; q[j, 2] += g * nz
            moved += 1
    return moved


from leafsim.sim.kernels.contacts import canonical_pairs as _canonical


@njit(cache=True, nogil=True, fastmath=True)
def find_contacts(q, rest, idx, search, skip2, table, nxt, pairs):
    """Candidate self-contact pairs (found once per substep with a spatial hash): layer-T
    particles closer than ``search`` whose rest distance² > ``skip2``.  Cells are 2 × search
    wide, so each particle visits only the 2 × 2 × 2 cells on its side of its own cell (a
    neighbour closer than ``search`` cannot lie farther away) instead of 27.  Writes up to
    len(pairs) pairs; returns the count."""
    nt = table.shape[0]
    mask = nt - 1
    pow2 = (nt & mask) == 0  # power-of-two table: bit mask instead of a signed 64-bit modulo
    table[:] = -1
    inv = 0.5 / search
    for k in range(idx.shape[0]):
        i = idx[k]
        h = (int(math.floor(q[i, 0] * inv)) * 73856093 ^ int(math.floor(q[i, 1] * inv)) * 19349663
             ^ int(math.floor(q[i, 2] * inv)) * 83492791)
        h = (h & mask) if pow2 else h % nt
        nxt[k] = table[h]
        table[h] = k
    s2 = search * search
    n = 0
    cap = pairs.shape[0]
    for k in range(idx.shape[0]):
        i = idx[k]
        g0 = n
        gx = q[i, 0] * inv
        gy = q[i, 1] * inv
        gz = q[i, 2] * inv
        cx = math.floor(gx)
        cy = math.floor(gy)
        cz = math.floor(gz)
        lx = int(cx) - (1 if gx - cx < 0.5 else 0)
        ly = int(cy) - (1 if gy - cy < 0.5 else 0)
        lz = int(cz) - (1 if gz - cz < 0.5 else 0)
        for ox in range(lx, lx + 2):
            for oy in range(ly, ly + 2):
                for oz in range(lz, lz + 2):
                    h = (ox * 73856093 ^ oy * 19349663 ^ oz * 83492791)
                    h = (h & mask) if pow2 else h % nt
                    m = table[h]
                    while m >= 0:
                        j = idx[m]
                        if j > i and n < cap:
                            dx = q[i, 0] - q[j, 0]
                            dy = q[i, 1] - q[j, 1]
                            dz = q[i, 2] - q[j, 2]
                            if dx * dx + dy * dy + dz * dz < s2:
                                ex = rest[i, 0] - rest[j, 0]
                                ey = rest[i, 1] - rest[j, 1]
                                if ex * ex + ey * ey > skip2:
                                    dup = False
                                    # the cell walk can meet a pair twice through hash collisions
                                    for t in range(max(0, n - 8), n):
                                        if pairs[t, 0] == i and pairs[t, 1] == j:
                                            dup = True
                                    if not dup:
                                        pairs[n, 0] = i
                                        pairs[n, 1] = j
                                        n += 1
                        m = nxt[m]
        n = _canonical(pairs, g0, n)  # (the one change: the rewrite's canonical pair order)
    return n


@njit(cache=True, nogil=True, fastmath=True)
def project_contacts(q, invm, pairs, n, radius):
    """Unilateral distance constraints |xi − xj| ≥ radius for the candidate pairs."""
    hits = 0
    for k in range(n):
        i = pairs[k, 0]
        j = pairs[k, 1]
        dx = q[i, 0] - q[j, 0]
        dy = q[i, 1] - q[j, 1]
        dz = q[i, 2] - q[j, 2]
        d2 = dx * dx + dy * dy + dz * dz
        if d2 < radius * radius and d2 > 1e-24:
            W = invm[i] + invm[j]
            if W > 0.0:
                d = math.sqrt(d2)
                f = (radius - d) / (d * W)
                q[i, 0] += invm[i] * f * dx; q[i, 1] += invm[i] * f * dy; q[i, 2] += invm[i] * f * dz
                q[j, 0] -= invm[j] * f * dx; q[j, 1] -= invm[j] * f * dy; q[j, 2] -= invm[j] * f * dz
                hits += 1
    return hits


def _springs_multi(q, invm, ij, rest, salpha, slam, scs, change, niter, tol):
    """``niter`` passes of :func:`springs_par` in one call (no Python between passes); stops
    early when the largest change falls below ``tol``.  Returns the passes run."""
    it = 0
    while it < niter:
        it += 1
        big = _springs_only(q, invm, ij, rest, salpha, slam, scs, change)
        if big < tol:
            break
    return it


@njit(cache=True, nogil=True, fastmath=True)
def springs_multi_ser(q, invm, ij, rest, salpha, slam, scs, niter, tol):
    """Serial fused version of :func:`_springs_multi`: the largest change is tracked inline
    (no ``change`` array, no second scan)."""
    it = 0
    while it < niter:
        it += 1
        big = 0.0
        for s in range(scs[-1]):
            ch = _spring(q, invm, ij, rest, salpha, slam, s)
            if ch > big:
                big = ch
        if big < tol:
            break
    return it


@njit(cache=True, nogil=True, parallel=True, fastmath=True)
def springs_multi_par(q, invm, ij, rest, salpha, slam, scs, change, niter, tol):
    """Coloured parallel passes, all in one call (fork/join per colour remains)."""
    it = 0
    while it < niter:
        it += 1
        for c in range(scs.shape[0] - 1):
            for s in prange(scs[c], scs[c + 1]):
                change[s] = _spring(q, invm, ij, rest, salpha, slam, s)
        big = 0.0
        for s in range(scs[-1]):
            if change[s] > big:
                big = change[s]
        if big < tol:
            break
    return it


@njit(cache=True, fastmath=True, nogil=True)
def hinge_compliance(hidx, water, w0, kbend, kdry, hgeom, krod, inv_h2, halpha):
    """XPBD compliance / Δt² of every hinge: k = D (1 + k_dry · clip(dry, 0, 1)) · geom + k_rod
    [N·m/rad], D the blade's bending stiffness [N·m], geom = 3|e|²/(A₁+A₂), k_rod the vein's
    E_v I/ℓ̄ share; dry = 1 − (w_a + w_b) / (w0_a + w0_b) over the hinge's shared edge a–b."""
    for e in range(hidx.shape[0]):
        a = hidx[e, 2]
        b = hidx[e, 3]
        dry = 1.0 - (water[a] + water[b]) / max(w0[a] + w0[b], 1e-300)
        if dry < 0.0:
            dry = 0.0
        elif dry > 1.0:
            dry = 1.0
        halpha[e] = inv_h2 / (kbend * (1.0 + kdry * dry) * hgeom[e] + krod[e])


@njit(cache=True, fastmath=True, nogil=True)
def contact_velocities(q, qd, invm, pairs, n, radius):
    """Inelastic self-contact (restitution 0): for the pairs that touch after the substep,
    remove the separating part of their relative normal velocity (mass-weighted, so momentum
    is conserved).  A position-based contact turns the penetration that *other* constraints
    push into a pair into a separating velocity; without this the contacts of a rolled leaf
    pump energy into a jitter that never dies."""
    r2 = (1.05 * radius) ** 2
    for k in range(n):
        i = pairs[k, 0]
        j = pairs[k, 1]
        dx = q[i, 0] - q[j, 0]
        dy = q[i, 1] - q[j, 1]
        dz = q[i, 2] - q[j, 2]
        d2 = dx * dx + dy * dy + dz * dz
        W = invm[i] + invm[j]
        if d2 >= r2 or d2 < 1e-24 or W <= 0.0:
            continue
        d = math.sqrt(d2)
        nx = dx / d; ny = dy / d; nz = dz / d
        vn = (qd[i, 0] - qd[j, 0]) * nx + (qd[i, 1] - qd[j, 1]) * ny + (qd[i, 2] - qd[j, 2]) * nz
        if vn <= 0.0:
            continue
        fi = invm[i] / W * vn
        fj = invm[j] / W * vn
        qd[i, 0] -= fi * nx; qd[i, 1] -= fi * ny; qd[i, 2] -= fi * nz
        qd[j, 0] += fj * nx; qd[j, 1] += fj * ny; qd[j, 2] += fj * nz


@njit(cache=True, fastmath=True, nogil=True)
def ground_clamp(q, invm, pen):
    """Ground plane z ≥ 0: lift penetrating particles and add the lift to ``pen``, the
    substep's total normal correction (∝ the normal impulse): the Coulomb budget of
    :func:`ground_friction` — the sum, not the deepest, so that it does not depend on how many
    iterations the same impulse is spread over."""
    for i in range(q.shape[0]):
        if q[i, 2] < 0.0 and invm[i] > 0.0:
            pen[i] -= q[i, 2]
            q[i, 2] = 0.0


@njit(cache=True, fastmath=True, nogil=True)
def add_delta(q, qa, dint):
    """dint += q − qa (the displacement of the internal projections since the snapshot qa)."""
    for i in range(q.shape[0]):
        for k in range(3):
            dint[i, k] += q[i, k] - qa[i, k]


@njit(cache=True, fastmath=True, nogil=True)
def remove_rigid(q, q_old, invm, dint):
    """Internal forces carry no net momentum.  A Gauss–Seidel sweep conserves linear and
    angular momentum only to first order (each projection is exact at the positions it sees,
    the sweep's sum is not), and on frustrated constraints the second-order remainder adds up
    to a steady spin or crawl.  This removes from the positions the translation and the
    rotation about the old centre of mass contained in the internal displacement ``dint``:
    afterwards Σ m Δ = 0 and Σ m (x_old − c) × Δ = 0, i.e. the substep's internal impulses
    leave L = Σ m x × v exactly unchanged (x_new = x_old + h v_new).  Returns nothing."""
    n = q.shape[0]
    M = 0.0
    cx = 0.0; cy = 0.0; cz = 0.0
    px = 0.0; py = 0.0; pz = 0.0
    for i in range(n):
        if invm[i] <= 0.0:
            continue
        m = 1.0 / invm[i]
        M += m
        cx += m * q_old[i, 0]; cy += m * q_old[i, 1]; cz += m * q_old[i, 2]
        px += m * dint[i, 0]; py += m * dint[i, 1]; pz += m * dint[i, 2]
    if M <= 0.0:
        return
    cx /= M; cy /= M; cz /= M
    tx = px / M; ty = py / M; tz = pz / M
    Lx = 0.0; Ly = 0.0; Lz = 0.0
    Ixx = 0.0; Iyy = 0.0; Izz = 0.0; Ixy = 0.0; Ixz = 0.0; Iyz = 0.0
    for i in range(n):
        if invm[i] <= 0.0:
            continue
        m = 1.0 / invm[i]
        rx = q_old[i, 0] - cx; ry = q_old[i, 1] - cy; rz = q_old[i, 2] - cz
        dx = dint[i, 0] - tx; dy = dint[i, 1] - ty; dz = dint[i, 2] - tz
        Lx += m * (ry * dz - rz * dy); Ly += m * (rz * dx - rx * dz); Lz += m * (rx * dy - ry * dx)
        Ixx += m * (ry * ry + rz * rz); Iyy += m * (rx * rx + rz * rz); Izz += m * (rx * rx + ry * ry)
        Ixy -= m * rx * ry; Ixz -= m * rx * rz; Iyz -= m * ry * rz
    # ω = I⁻¹ L (3 × 3, symmetric; adjugate / determinant)
    a00 = Iyy * Izz - Iyz * Iyz; a01 = Ixz * Iyz - Ixy * Izz; a02 = Ixy * Iyz - Ixz * Iyy
    a11 = Ixx * Izz - Ixz * Ixz; a12 = Ixy * Ixz - Ixx * Iyz; a22 = Ixx * Iyy - Ixy * Ixy
    det = Ixx * a00 + Ixy * a01 + Ixz * a02
    if abs(det) < 1e-300:
        return
    wx = (a00 * Lx + a01 * Ly + a02 * Lz) / det
    wy = (a01 * Lx + a11 * Ly + a12 * Lz) / det
    wz = (a02 * Lx + a12 * Ly + a22 * Lz) / det
    for i in range(n):
        if invm[i] <= 0.0:
            continue
        rx = q_old[i, 0] - cx; ry = q_old[i, 1] - cy; rz = q_old[i, 2] - cz
        q[i, 0] -= tx + wy * rz - wz * ry
        q[i, 1] -= ty + wz * rx - wx * rz
        q[i, 2] -= tz + wx * ry - wy * rx


@njit(cache=True, nogil=True, fastmath=True)
def frame(q, qd, q_old, invm, gz, h, substeps, keep, iters, tol, par,
          ij, rest, salpha, slam, scs,
          hidx, hrest, halpha, hlam, hcs,
          vidx, vrest, vlam, vcs,
          pbd, ground, pen, change, mu,
          self_coll, qrest, T_idx, search, skip2, table, nxt, pairs, radius,
          replace, hgt, thick, conserve, qa, dint, omega, out):
    """All ``substeps`` of one dynamics frame in one call (no Python between substeps or
    iterations; SPEC §8 order).  Per substep: predict; iterate (ground clamp — external —
    then the internal constraints: springs, hinges, volumes, self-contacts); ground contact +
    friction; un-invert layers; with ``conserve`` remove the rigid part of the internal
    displacement (see :func:`remove_rigid`; not with pinned particles); velocity update with
    damping, inelastic self-contacts.  ``omega`` over-relaxes the hinge projections (SOR).  ``par`` picks the coloured-parallel projection; ``qa``/``dint``
    (n, 3) scratch.  Writes (iterations, contacts, uninverted) to ``out`` (int64[3])."""
    its = 0
    for _ in range(substeps):
        predict(q, qd, q_old, invm, gz, h)
        if replace:
            voronoi_heights(q_old, vidx, hgt)
        dint[:] = 0.0
        it = 0
        ncont = 0
        if pbd:
            slam[:] = 0.0
            hlam[:] = 0.0
            if self_coll:
                ncont = find_contacts(q, qrest, T_idx, search, skip2, table, nxt, pairs)
            hits = 0
            while it < iters:
                it += 1
                if ground:
                    ground_clamp(q, invm, pen)
                qa[:] = q
                if par:
                    ch = iteration_par(q, invm, ij, rest, salpha, slam, scs, hidx, hrest, halpha, hlam, hcs, omega,
                                       vidx, vrest, vlam, vcs, change)
                else:
                    ch = iteration_ser(q, invm, ij, rest, salpha, slam, scs, hidx, hrest, halpha, hlam, hcs, omega,
                                       vidx, vrest, vlam, vcs, change)
                if ncont:
                    hits = project_contacts(q, invm, pairs, ncont, radius)
                add_delta(q, qa, dint)
                if ch < tol and hits == 0:
                    break
            out[1] = hits
        if pbd:
            # no layer inversion: momentum-conserving passes (vertices resting on the ground stay),
            # then a V-only pass for anything neighbours undid
            qa[:] = q
            n_fix = 0
            k = 0
            for _r in range(3):
                k = uninvert(q, invm, vidx, 0.25 * thick, False, ground)
                n_fix += k
                if k == 0:
                    break
            if k:
                uninvert(q, invm, vidx, 0.2 * thick, True, ground)
            out[2] = n_fix
            add_delta(q, qa, dint)
            if conserve:
                remove_rigid(q, q_old, invm, dint)
        if ground:  # (changed since the freeze, as in production: contact + friction after the removal)
            ground_clamp(q, invm, pen)
            ground_friction(q, q_old, pen, mu)
            if pbd:
                out[2] += uninvert(q, invm, vidx, 0.25 * thick, False, True)
        update_velocity(q, q_old, qd, h, keep)
        if pbd and ncont:
            contact_velocities(q, qd, invm, pairs, ncont, radius)
        if replace:
            voronoi_replace(q, vidx, hgt, 0.25 * thick)
            if ground:
                for i in range(q.shape[0]):
                    if q[i, 2] < 0.0:
                        q[i, 2] = 0.0
        its += it
    out[0] = its
