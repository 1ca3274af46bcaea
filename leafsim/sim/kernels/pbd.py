"""XPBD kernels: prediction, Gauss–Seidel projection of distance, bending (signed dihedral) and
thickness (tetrahedron volume) constraints, ground contact with friction, self-collision
(spatial-hash candidates kept with a Verlet skin, projected inside the iteration loop),
velocity update and Voronoi re-placement.

Everything runs on one thread: on the shared 2-core machines this project runs on, the former
graph-coloured ``prange`` kernels (one fork/join per colour per pass) were 13–36× slower than
serial under load, and a parallel path must never lose (measured in ``leafsim bench``,
docs/performance.md).  Constraints are stored in colour order and, inside one colour, sorted
by particle (no two constraints of one colour share a particle, so that order changes no
result and makes the particle accesses nearly sequential).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import FASTMATH


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def predict(q, qd, q_old, qa, dint, invm, gz, dt):
    """Start of a substep: q_old ← q, gravity, x ← x + v Δt; ``qa`` ← the prediction and
    ``dint`` ← 0 (the internal displacement is counted from here), all in one pass."""
    for i in range(q.shape[0]):
        for k in range(3):
            q_old[i, k] = q[i, k]
        if invm[i] > 0.0:
            qd[i, 2] += gz * dt
            for k in range(3):
                q[i, k] += qd[i, k] * dt
        for k in range(3):
            qa[i, k] = q[i, k]
            dint[i, k] = 0.0


# ---------------------------------------------------------------- projection passes
# One Gauss–Seidel sweep over constraints lo…hi of one kind, in storage order (colour by
# colour), each returning the largest |Δx| it made.  Written as plain loops in one function on
# purpose (measured in docs/performance.md): the former ``inline="always"`` helpers that took
# the arrays as arguments left 6 NRT_incref + 6 NRT_decref (atomic) calls around every hinge
# in the generated code, and returned 17-tuples through the stack.  Indices are stored as
# uint32, so no negative-index wrap-around code is emitted either.

@njit(cache=True, nogil=True, fastmath=FASTMATH)
def pack_springs(perm, ij, invm, rest, salpha, rec):
    """The per-spring record of one frame, in projection order: rec[s] = (rest length,
    compliance / Δt², 1 / (w_a + w_b + compliance), w_a, w_b), for spring perm[s] of the model
    (``rest`` and ``salpha`` in model order, ``ij`` already in projection order)."""
    for s in range(perm.shape[0]):
        k = perm[s]
        wa = invm[ij[s, 0]]
        wb = invm[ij[s, 1]]
        W = wa + wb + salpha[k]
        rec[s, 0] = rest[k]
        rec[s, 1] = salpha[k]
        rec[s, 2] = 1.0 / W if W > 0.0 else 0.0
        rec[s, 3] = wa
        rec[s, 4] = wb


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


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def iteration(q, invm, ij, srec, slam, hidx, hrest, halpha, hlam, omega, vidx, vrest):
    """One Gauss–Seidel pass over all constraints: springs, hinges, thickness (each kind in
    colour order).  Returns the largest |Δx| of the pass."""
    big = spring_pass(q, ij, srec, slam, 0, ij.shape[0])
    big = max(big, hinge_pass(q, invm, hidx, hrest, halpha, hlam, omega, 0, hidx.shape[0]))
    return max(big, volume_pass(q, invm, vidx, vrest, 0, vidx.shape[0]))


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def springs_passes(q, ij, rec, lam, niter, tol):
    """``niter`` spring passes in one call (the bench's job); stops early when the largest
    change falls below ``tol``.  Returns the passes run."""
    it = 0
    while it < niter:
        it += 1
        if spring_pass(q, ij, rec, lam, 0, ij.shape[0]) < tol:
            break
    return it


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def ground_contact(q, q_old, invm, pen, mu):
    """The substep's last ground clamp (:func:`ground_clamp`) and Coulomb friction for the
    particles that touched the ground in it (PBD style), in one pass."""
    for i in range(q.shape[0]):
        if q[i, 2] < 0.0 and invm[i] > 0.0:
            pen[i] -= q[i, 2]
            q[i, 2] = 0.0
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


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def update_velocity(q, q_old, qd, dt, keep, ground):
    """v ← (x − x_old)/Δt × ``keep`` (damping), after lifting anything below the ground."""
    inv = 1.0 / dt
    for i in range(q.shape[0]):
        if ground and q[i, 2] < 0.0:
            q[i, 2] = 0.0
        for k in range(3):
            qd[i, k] = (q[i, k] - q_old[i, k]) * inv * keep


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def voronoi_heights(q, vidx, hgt):
    """Signed height of each V particle above its triangle's plane (store before projection)."""
    for t in range(vidx.shape[0]):
        iv, ia, ib, ic = vidx[t, 0], vidx[t, 1], vidx[t, 2], vidx[t, 3]
        bx = q[ib, 0] - q[ia, 0]; by = q[ib, 1] - q[ia, 1]; bz = q[ib, 2] - q[ia, 2]
        cx = q[ic, 0] - q[ia, 0]; cy = q[ic, 1] - q[ia, 1]; cz = q[ic, 2] - q[ia, 2]
        nx = by * cz - bz * cy; ny = bz * cx - bx * cz; nz = bx * cy - by * cx
        nl = math.sqrt(nx * nx + ny * ny + nz * nz) + 1e-300
        hgt[t] = ((q[iv, 0] - q[ia, 0]) * nx + (q[iv, 1] - q[ia, 1]) * ny + (q[iv, 2] - q[ia, 2]) * nz) / nl


@njit(cache=True, nogil=True, fastmath=FASTMATH)
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


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def residual(q, ij, rest):
    """max |C| / l over springs."""
    big = 0.0
    for s in range(ij.shape[0]):
        a = ij[s, 0]
        b = ij[s, 1]
        dx = q[a, 0] - q[b, 0]; dy = q[a, 1] - q[b, 1]; dz = q[a, 2] - q[b, 2]
        r = abs(math.sqrt(dx * dx + dy * dy + dz * dz) - rest[s]) / max(rest[s], 1e-30)
        if r > big:
            big = r
    return big


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


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def uninvert(q, invm, vidx, hmin, vonly, ground, dint):
    """Guard against layer inversion: a V particle closer than ``hmin`` to (or below) its
    triangle's plane is projected to height ``hmin`` (inverse-mass weighted between the V
    particle and the triangle, so momentum is conserved; with ``ground`` a vertex resting on
    the ground is not pushed into it).  Every move is added to ``dint`` (internal
    displacement).  Returns how many were corrected."""
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
            dint[iv, 0] += f * nx; dint[iv, 1] += f * ny; dint[iv, 2] += f * nz
            for j, wj in ((ia, wa), (ib, wb), (ic, wc)):
                g = -wj * dl / 3.0
                q[j, 0] += g * nx; q[j, 1] += g * ny; q[j, 2] += g * nz
                dint[j, 0] += g * nx; dint[j, 1] += g * ny; dint[j, 2] += g * nz
            moved += 1
    return moved


@njit(cache=True, nogil=True)
def canonical_pairs(pairs, g0, n):
    """Sort the pairs [g0, n) of one particle i by j and drop repeats (hash collisions can
    meet a pair twice); returns the new end."""
    for a in range(g0 + 1, n):
        jv = pairs[a, 1]
        b = a - 1
        while b >= g0 and pairs[b, 1] > jv:
            pairs[b + 1, 1] = pairs[b, 1]
            b -= 1
        pairs[b + 1, 1] = jv
    w = g0
    for a in range(g0, n):
        if a == g0 or pairs[a, 1] != pairs[w - 1, 1]:
            pairs[w, 0] = pairs[a, 0]
            pairs[w, 1] = pairs[a, 1]
            w += 1
    return w


@njit(cache=True, nogil=True, fastmath=FASTMATH)
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
        # canonical order (by i, then j): the projections then do not depend on the cell walk,
        # so a list searched at another moment (a resumed run, another skin) projects the pairs
        # that touch in the same order and gives bit-identical results
        n = canonical_pairs(pairs, g0, n)
    return n


@njit(cache=True, nogil=True, fastmath=FASTMATH)
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


@njit(cache=True, fastmath=FASTMATH, nogil=True)
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


@njit(cache=True, fastmath=FASTMATH, nogil=True)
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


@njit(cache=True, fastmath=FASTMATH, nogil=True)
def ground_clamp(q, invm, pen):
    """Ground plane z ≥ 0: lift penetrating particles and add the lift to ``pen``, the
    substep's total normal correction (∝ the normal impulse): the Coulomb budget of
    :func:`ground_contact` — the sum, not the deepest, so that it does not depend on how many
    iterations the same impulse is spread over."""
    for i in range(q.shape[0]):
        if q[i, 2] < 0.0 and invm[i] > 0.0:
            pen[i] -= q[i, 2]
            q[i, 2] = 0.0


@njit(cache=True, fastmath=FASTMATH, nogil=True)
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


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def contacts_stale(q, idx, qc, limit):
    """True when a particle of ``idx`` moved more than ``limit`` from ``qc`` (its position at
    the last contact search), or ``limit`` ≤ 0."""
    if limit <= 0.0:
        return True
    l2 = limit * limit
    for k in range(idx.shape[0]):
        i = idx[k]
        dx = q[i, 0] - qc[k, 0]
        dy = q[i, 1] - qc[k, 1]
        dz = q[i, 2] - qc[k, 2]
        if dx * dx + dy * dy + dz * dz > l2:
            return True
    return False


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def update_contacts(q, qrest, idx, radius, skin, skip2, table, nxt, pairs, qc, cstate):
    """Self-contact candidates with a Verlet skin: the spatial hash is searched at radius +
    ``skin`` and kept until some particle has moved more than half of what is left of the skin
    (the search radius less the 1.05 × ``radius`` the contact velocities look at), so every
    pair that can touch since the search is in the list and nothing is searched while nothing
    moves.  ``cstate`` float64[2] = (search radius of the list, pairs in it; −1 = none);
    ``qc`` (|idx|, 3) the positions at the search.  Returns the number of pairs."""
    if cstate[1] >= 0.0 and not contacts_stale(q, idx, qc, 0.5 * (cstate[0] - 1.05 * radius)):
        return int(cstate[1])
    search = radius + skin
    n = find_contacts(q, qrest, idx, search, skip2, table, nxt, pairs)
    for k in range(idx.shape[0]):
        i = idx[k]
        qc[k, 0] = q[i, 0]; qc[k, 1] = q[i, 1]; qc[k, 2] = q[i, 2]
    cstate[0] = search
    cstate[1] = n
    cstate[2] += 1.0
    return n


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def internal_delta(q, qa, pen, dint):
    """dint += q − qa less the ground's lift recorded in ``pen`` since the snapshot (the
    ground is external: only the constraints' own displacement counts as internal)."""
    for i in range(q.shape[0]):
        dint[i, 0] += q[i, 0] - qa[i, 0]
        dint[i, 1] += q[i, 1] - qa[i, 1]
        dint[i, 2] += q[i, 2] - qa[i, 2] - pen[i]


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def clamp_ground(q):
    for i in range(q.shape[0]):
        if q[i, 2] < 0.0:
            q[i, 2] = 0.0


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def project(q, invm, cons, omega, iters, tol, ground, pen, pairs, ncont, radius, out):
    """The substep's Gauss–Seidel iterations: (ground clamp, springs, hinges, volumes,
    self-contacts) until the largest change < ``tol`` with no contact hit, at most ``iters``.
    ``cons`` = (ij, srec, slam, hidx, hrest, halpha, hlam, vidx, vrest).  Writes the contact
    hits of the last iteration to out[1]; returns the iterations run."""
    ij, srec, slam, hidx, hrest, halpha, hlam, vidx, vrest = cons
    slam[:] = 0.0
    hlam[:] = 0.0
    it = 0
    hits = 0
    while it < iters:
        it += 1
        if ground:
            ground_clamp(q, invm, pen)
        ch = iteration(q, invm, ij, srec, slam, hidx, hrest, halpha, hlam, omega, vidx, vrest)
        if ncont:
            hits = project_contacts(q, invm, pairs, ncont, radius)
        if ch < tol and hits == 0:
            break
    out[1] = hits
    return it


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def settle(q, invm, vidx, thick, ground, dint, out):
    """No layer inversion after the substep's projections: momentum-conserving passes (vertices
    resting on the ground stay), then a V-only pass for anything neighbours undid."""
    n_fix = 0
    k = 0
    for _r in range(3):
        k = uninvert(q, invm, vidx, 0.25 * thick, False, ground, dint)
        n_fix += k
        if k == 0:
            break
    if k:
        uninvert(q, invm, vidx, 0.2 * thick, True, ground, dint)
    out[2] = n_fix


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def frame(q, qd, q_old, invm, gz, h, substeps, keep, iters, tol, cons, vidx,
          pbd, ground, pen, mu, self_coll, contact, replace, hgt, thick, conserve, qa, dint, omega, out):
    """All ``substeps`` of one dynamics frame in one call (no Python between substeps or
    iterations).  Per substep: predict; iterate (:func:`project`: ground clamp — external —
    then the internal constraints ``cons`` in projection order, self-contacts); un-invert
    layers (``vidx`` in model order); with ``conserve`` remove the rigid part of the internal
    displacement (:func:`remove_rigid`; not with pinned particles); ground contact + friction;
    velocity update with damping, inelastic self-contacts.  ``contact`` = (qrest,
    T_idx, radius, skin, skip2, table, nxt, pairs, qc, cstate) for :func:`update_contacts`.
    ``qa``/``dint`` (n, 3) scratch.  Writes (iterations, contact hits, uninverted) to ``out``
    (int64[3])."""
    qrest, T_idx, radius, skin, skip2, table, nxt, pairs, qc, cstate = contact
    its = 0
    for _ in range(substeps):
        predict(q, qd, q_old, qa, dint, invm, gz, h)
        if replace:
            voronoi_heights(q_old, vidx, hgt)
        ncont = 0
        if pbd:
            if self_coll:
                ncont = update_contacts(q, qrest, T_idx, radius, skin, skip2, table, nxt, pairs, qc, cstate)
            its += project(q, invm, cons, omega, iters, tol, ground, pen, pairs, ncont, radius, out)
            internal_delta(q, qa, pen, dint)
        if pbd:
            settle(q, invm, vidx, thick, ground, dint, out)
            if conserve:
                remove_rigid(q, q_old, invm, dint)
        # ground contact and friction last: friction anchors the contact particles against
        # everything the substep did, the rigid-motion removal included (friction first, then
        # removal, let a dried, strongly curled leaf crawl at a steady 5 mm/s for ever)
        if ground:
            ground_contact(q, q_old, invm, pen, mu)
            if pbd:
                # the clamp may push a layer through the other where the leaf lies upside down:
                # one more momentum-conserving pass (particles resting on the ground stay put)
                out[2] += uninvert(q, invm, vidx, 0.25 * thick, False, True, dint)
        update_velocity(q, q_old, qd, h, keep, ground and pbd)
        if pbd and ncont:
            contact_velocities(q, qd, invm, pairs, ncont, radius)
        if replace:
            voronoi_replace(q, vidx, hgt, 0.25 * thick)
            if ground:
                clamp_ground(q)
    out[0] = its
