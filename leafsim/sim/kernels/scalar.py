"""XPBD projections one constraint at a time: distance springs, bending hinges (signed
dihedral) and thickness volumes over any range lo…hi of constraints.

These are the reference the production's blocked kernels (:mod:`.blocked`) are tested
against bit for bit, the contenders the bench races them with, and what the parallel
contenders (:mod:`.contenders`) and the float32 *ceiling* call on sub-ranges (numba
specialises them per dtype).  Written as plain loops on purpose (docs/performance.md): the
former ``inline="always"`` helpers that took the arrays as arguments left 6 NRT_incref + 6
NRT_decref (atomic) calls around every hinge in the generated code, and returned 17-tuples
through the stack.  Indices are uint32, so no negative-index wrap-around code is emitted."""

from __future__ import annotations

import math

from numba import njit

from leafsim.sim.kernels import FASTMATH


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def spring_pass(q, ij, rec, lam, lo, hi):
    """XPBD distance constraints lo…hi (records of :func:`pack_springs`): one sqrt and one
    division each."""
    big = 0.0
    for s in range(lo, hi):
        a = ij[s, 0]
        b = ij[s, 1]
        dx = q[a, 0] - q[b, 0]
        dy = q[a, 1] - q[b, 1]
        dz = q[a, 2] - q[b, 2]
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        if d < 1e-12:
            continue
        wa = rec[s, 3]
        wb = rec[s, 4]
        dl = (rec[s, 0] - d - rec[s, 1] * lam[s]) * rec[s, 2]
        lam[s] += dl
        f = dl / d
        q[a, 0] += wa * f * dx; q[a, 1] += wa * f * dy; q[a, 2] += wa * f * dz
        q[b, 0] -= wb * f * dx; q[b, 1] -= wb * f * dy; q[b, 2] -= wb * f * dz
        ch = abs(dl) * max(wa, wb)
        if ch > big:
            big = ch
    return big


@njit(inline="always", fastmath=FASTMATH)
def atan2_(y, x):
    """atan2 without the libm call: Cephes' atan (rational P4/Q5 after reducing to
    |t| ≤ tan π/8; relative error 1.9e-16) with atan2's quadrants.  Agrees with ``math.atan2``
    to 4.5e-16 rad (tests/test_kernels.py); written with selects, so no branch to mispredict."""
    ay = abs(y)
    ax = abs(x)
    t = min(ay, ax) / max(max(ay, ax), 1e-300)
    hi = t > 0.41421356237309503
    t = (t - 1.0) / (t + 1.0) if hi else t
    z = t * t
    p = (((-8.750608600031904122785e-1 * z - 1.615753718733365076637e1) * z - 7.500855792314704667340e1) * z
         - 1.228866684490136173410e2) * z - 6.485021904942025371773e1
    r = ((((z + 2.485846490142306297962e1) * z + 1.650270098316988542046e2) * z + 4.328810604912902668951e2) * z
         + 4.853903996359136964868e2) * z + 1.945506571482613964425e2
    a = t * z * p / r + t + (0.7853981633974483 + 3.061616997868383e-17 if hi else 0.0)
    a = 1.5707963267948966 - a if ay > ax else a
    a = math.pi - a if x < 0.0 else a
    return a if y >= 0.0 else -a


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def hinge_pass(q, invm, hidx, hrest, halpha, hlam, omega, lo, hi):
    """Bending hinges lo…hi, hidx = (x1, x2; x3–x4): signed dihedral angle θ (cup, wings up,
    > 0) and its gradients u1…u4 (Bridson et al. 2003), XPBD step over-relaxed by ``omega``,
    never moving a vertex by more than half the edge length (degenerate hinges).

    With e = x4 − x3, a = x1 − x3, c = x2 − x4 the normals are n1 = e × a, n2 = c × e, and
    (n2 × n1)·e = |e|² (n2·a), so θ = atan2(|e| n2·a, n1·n2) (no |n1| |n2|: both arguments
    share that positive factor); u4 = −(u1 + u2 + u3) (translation invariance); the step limit
    compares squares.  Same values as the textbook form to round-off, in about 60 % of the
    operations: one atan2 (inline), one square root and four divisions per hinge."""
    big2 = 0.0
    for e in range(lo, hi):
        i1 = hidx[e, 0]; i2 = hidx[e, 1]; i3 = hidx[e, 2]; i4 = hidx[e, 3]
        ex = q[i4, 0] - q[i3, 0]; ey = q[i4, 1] - q[i3, 1]; ez = q[i4, 2] - q[i3, 2]
        ax = q[i1, 0] - q[i3, 0]; ay = q[i1, 1] - q[i3, 1]; az = q[i1, 2] - q[i3, 2]
        cx = q[i2, 0] - q[i4, 0]; cy = q[i2, 1] - q[i4, 1]; cz = q[i2, 2] - q[i4, 2]
        n1x = ey * az - ez * ay; n1y = ez * ax - ex * az; n1z = ex * ay - ey * ax
        n2x = cy * ez - cz * ey; n2y = cz * ex - cx * ez; n2z = cx * ey - cy * ex
        el2 = ex * ex + ey * ey + ez * ez
        l1 = n1x * n1x + n1y * n1y + n1z * n1z
        l2 = n2x * n2x + n2y * n2y + n2z * n2z
        if el2 < 1e-24 or l1 < 1e-30 or l2 < 1e-30:
            continue
        el = math.sqrt(el2)
        C = atan2_(el * (n2x * ax + n2y * ay + n2z * az), n1x * n2x + n1y * n2y + n1z * n2z) - hrest[e]
        if C > math.pi:
            C -= 2 * math.pi
        elif C < -math.pi:
            C += 2 * math.pi
        il1 = 1.0 / l1
        il2 = 1.0 / l2
        iel = 1.0 / el
        g1 = el * il1
        g2 = el * il2
        p1 = (ax * ex + ay * ey + az * ez - el2) * iel * il1  # (x1 − x4)·e / |e| / |n1|²
        p2 = (cx * ex + cy * ey + cz * ez) * iel * il2  # (x2 − x4)·e / |e| / |n2|²
        u3x = p1 * n1x + p2 * n2x; u3y = p1 * n1y + p2 * n2y; u3z = p1 * n1z + p2 * n2z
        u4x = -(g1 * n1x + g2 * n2x + u3x); u4y = -(g1 * n1y + g2 * n2y + u3y); u4z = -(g1 * n1z + g2 * n2z + u3z)
        w1 = invm[i1]; w2 = invm[i2]; w3 = invm[i3]; w4 = invm[i4]
        s1 = el2 * il1  # |u1|²
        s2 = el2 * il2
        s3 = u3x * u3x + u3y * u3y + u3z * u3z
        s4 = u4x * u4x + u4y * u4y + u4z * u4z
        W = w1 * s1 + w2 * s2 + w3 * s3 + w4 * s4 + halpha[e]
        if W <= 0.0:
            continue
        dl = omega * (-C - halpha[e] * hlam[e]) / W
        m12 = max(w1 * w1 * s1, w2 * w2 * s2)
        gm2 = max(m12, max(w3 * w3 * s3, w4 * w4 * s4))
        if dl * dl * gm2 > 0.25 * el2:
            dl = math.copysign(0.5 * el / math.sqrt(gm2), dl)
        hlam[e] += dl
        f1 = w1 * dl * g1; f2 = w2 * dl * g2; f3 = w3 * dl; f4 = w4 * dl
        q[i1, 0] += f1 * n1x; q[i1, 1] += f1 * n1y; q[i1, 2] += f1 * n1z
        q[i2, 0] += f2 * n2x; q[i2, 1] += f2 * n2y; q[i2, 2] += f2 * n2z
        q[i3, 0] += f3 * u3x; q[i3, 1] += f3 * u3y; q[i3, 2] += f3 * u3z
        q[i4, 0] += f4 * u4x; q[i4, 1] += f4 * u4y; q[i4, 2] += f4 * u4z
        ch2 = dl * dl * m12  # the change², compared squared: one square root per pass
        if ch2 > big2:
            big2 = ch2
    return math.sqrt(big2)


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def volume_pass(q, invm, vidx, vrest, lo, hi):
    """Thickness constraints lo…hi: 6 × the volume of tetrahedron (v, a, b, c) = det, which
    keeps V on the top side; the step is limited to half the triangle's edge scale (compared
    in squares: one square root and one division per tetrahedron)."""
    big2 = 0.0
    for t in range(lo, hi):
        iv = vidx[t, 0]; ia = vidx[t, 1]; ib = vidx[t, 2]; ic = vidx[t, 3]
        bx = q[ib, 0] - q[ia, 0]; by = q[ib, 1] - q[ia, 1]; bz = q[ib, 2] - q[ia, 2]
        cx = q[ic, 0] - q[ia, 0]; cy = q[ic, 1] - q[ia, 1]; cz = q[ic, 2] - q[ia, 2]
        vx = q[iv, 0] - q[ia, 0]; vy = q[iv, 1] - q[ia, 1]; vz = q[iv, 2] - q[ia, 2]
        gvx = by * cz - bz * cy; gvy = bz * cx - bx * cz; gvz = bx * cy - by * cx
        gbx = cy * vz - cz * vy; gby = cz * vx - cx * vz; gbz = cx * vy - cy * vx
        gcx = vy * bz - vz * by; gcy = vz * bx - vx * bz; gcz = vx * by - vy * bx
        gax = -(gvx + gbx + gcx); gay = -(gvy + gby + gcy); gaz = -(gvz + gbz + gcz)
        C = vx * gvx + vy * gvy + vz * gvz - vrest[t]
        wv = invm[iv]; wa = invm[ia]; wb = invm[ib]; wc = invm[ic]
        sv = gvx * gvx + gvy * gvy + gvz * gvz
        sa = gax * gax + gay * gay + gaz * gaz
        sb = gbx * gbx + gby * gby + gbz * gbz
        sc = gcx * gcx + gcy * gcy + gcz * gcz
        W = wv * sv + wa * sa + wb * sb + wc * sc
        if W <= 1e-300:
            continue
        dl = -C / W
        gm2 = max(max(wv * wv * sv, wa * wa * sa), max(wb * wb * sb, wc * wc * sc))
        lim2 = 0.25 * math.sqrt((bx * bx + by * by + bz * bz) * (cx * cx + cy * cy + cz * cz))
        if dl * dl * gm2 > lim2:
            dl = math.copysign(math.sqrt(lim2 / gm2), dl)
        fv = wv * dl; fa = wa * dl; fb = wb * dl; fc = wc * dl
        q[iv, 0] += fv * gvx; q[iv, 1] += fv * gvy; q[iv, 2] += fv * gvz
        q[ia, 0] += fa * gax; q[ia, 1] += fa * gay; q[ia, 2] += fa * gaz
        q[ib, 0] += fb * gbx; q[ib, 1] += fb * gby; q[ib, 2] += fb * gbz
        q[ic, 0] += fc * gcx; q[ic, 1] += fc * gcy; q[ic, 2] += fc * gcz
        ch2 = dl * dl * wv * wv * sv
        if ch2 > big2:
            big2 = ch2
    return math.sqrt(big2)
