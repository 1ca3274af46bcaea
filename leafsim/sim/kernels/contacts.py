"""Self-contacts between layer-T particles (numba): a spatial-hash search into a Verlet list
kept while the particles have moved against each other by less than its skin (a common
translation ignored), the near list filtered from it, in canonical pair order (results do not
depend on the skins), the contact projections and the inelastic contact velocities."""

from __future__ import annotations

import math

from numba import njit

from leafsim.sim.kernels import FASTMATH


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
def find_contacts(q, rest, idx, search, skip2, table, nxt, qc, pairs):
    """Candidate self-contact pairs (spatial hash): layer-T particles closer than ``search``
    whose rest distance² > ``skip2``, in canonical order (by i, then j).  ``idx`` must be
    ascending.  Cells are 2 × search wide, so each particle visits only the 2 × 2 × 2 cells on
    its side of its own cell (a neighbour closer than ``search`` cannot lie farther away)
    instead of 27.  ``qc`` (|idx|, 5) receives each particle's position and rest position at
    the search, compact in ``idx`` order: the walk reads them there (one array, no
    indirection) and :func:`contacts_stale` measures the motion since the search from them.
    Every bucket's chain holds its particles in descending k, so a particle's walk stops at the
    first k' ≤ k: pairs with j ≤ i are never looked at (idx ascending: j > i ⟺ k' > k).
    Writes up to len(pairs) pairs; returns (the count, whether a pair found did not fit: the
    count alone cannot tell, since repeats are dropped after the list filled)."""
    nt = table.shape[0]
    mask = nt - 1
    pow2 = (nt & mask) == 0  # power-of-two table: bit mask instead of a signed 64-bit modulo
    table[:] = -1
    inv = 0.5 / search
    for k in range(idx.shape[0]):
        i = idx[k]
        x = q[i, 0]; y = q[i, 1]; z = q[i, 2]
        qc[k, 0] = x; qc[k, 1] = y; qc[k, 2] = z; qc[k, 3] = rest[i, 0]; qc[k, 4] = rest[i, 1]
        h = (int(math.floor(x * inv)) * 73856093 ^ int(math.floor(y * inv)) * 19349663
             ^ int(math.floor(z * inv)) * 83492791)
        h = (h & mask) if pow2 else h % nt
        nxt[k] = table[h]
        table[h] = k
    s2 = search * search
    n = 0
    cap = pairs.shape[0]
    full = False
    for k in range(idx.shape[0]):
        i = idx[k]
        g0 = n
        x = qc[k, 0]; y = qc[k, 1]; z = qc[k, 2]; rx = qc[k, 3]; ry = qc[k, 4]
        gx = x * inv
        gy = y * inv
        gz = z * inv
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
                    while m > k:
                        dx = x - qc[m, 0]
                        dy = y - qc[m, 1]
                        dz = z - qc[m, 2]
                        if dx * dx + dy * dy + dz * dz < s2:
                            ex = rx - qc[m, 3]
                            ey = ry - qc[m, 4]
                            if ex * ex + ey * ey > skip2:
                                if n < cap:
                                    pairs[n, 0] = i
                                    pairs[n, 1] = idx[m]
                                    n += 1
                                else:
                                    full = True
                        m = nxt[m]
        # canonical order (by i, then j), repeats dropped (two of the 8 cells can share a bucket,
        # so a chain can be walked twice): the projections then do not depend on the cell walk,
        # so a list searched at another moment (a resumed run, another skin) projects the pairs
        # that touch in the same order and gives bit-identical results
        n = canonical_pairs(pairs, g0, n)
    return n, full


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


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def contacts_stale(q, idx, qc, limit):
    """True unless every pair of ``idx`` particles is still within 2 × ``limit`` of the
    distance it had at the last contact search (positions ``qc``), or ``limit`` ≤ 0.

    A common translation c moves no pair: |Δᵢ − Δⱼ| = |(Δᵢ − c) − (Δⱼ − c)| ≤ d₁ + d₂ for
    the motions Δ since the search and d₁ ≥ d₂ the two largest |Δ − c|.  With c the centre of
    the motions' bounding box, a leaf that falls or drifts as a whole is not searched again;
    d₁ + d₂ ≤ 2 × ``limit`` is the same guarantee as every |Δᵢ| ≤ ``limit``."""
    if limit <= 0.0:
        return True
    n = idx.shape[0]
    if n == 0:
        return False
    lo0 = hi0 = q[idx[0], 0] - qc[0, 0]
    lo1 = hi1 = q[idx[0], 1] - qc[0, 1]
    lo2 = hi2 = q[idx[0], 2] - qc[0, 2]
    for k in range(1, n):
        i = idx[k]
        dx = q[i, 0] - qc[k, 0]
        dy = q[i, 1] - qc[k, 1]
        dz = q[i, 2] - qc[k, 2]
        lo0 = min(lo0, dx); hi0 = max(hi0, dx)
        lo1 = min(lo1, dy); hi1 = max(hi1, dy)
        lo2 = min(lo2, dz); hi2 = max(hi2, dz)
    c0 = 0.5 * (lo0 + hi0); c1 = 0.5 * (lo1 + hi1); c2 = 0.5 * (lo2 + hi2)
    d1 = 0.0
    d2 = 0.0
    for k in range(n):
        i = idx[k]
        dx = q[i, 0] - qc[k, 0] - c0
        dy = q[i, 1] - qc[k, 1] - c1
        dz = q[i, 2] - qc[k, 2] - c2
        r2 = dx * dx + dy * dy + dz * dz
        if r2 > d2:
            if r2 > d1:
                d2 = d1
                d1 = r2
            else:
                d2 = r2
    return math.sqrt(d1) + math.sqrt(d2) > 2.0 * limit


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def near_pairs(q, pairs, n, reach, idx, near, qn):
    """The pairs of ``pairs[:n]`` closer than ``reach`` now, in the same (canonical) order,
    into ``near``; ``qn`` (|idx|, 3) ← the ``idx`` particles' positions.  Returns the count."""
    r2 = reach * reach
    m = 0
    for k in range(n):
        i = pairs[k, 0]
        j = pairs[k, 1]
        dx = q[i, 0] - q[j, 0]
        dy = q[i, 1] - q[j, 1]
        dz = q[i, 2] - q[j, 2]
        if dx * dx + dy * dy + dz * dz < r2:
            near[m, 0] = i
            near[m, 1] = j
            m += 1
    for k in range(idx.shape[0]):
        i = idx[k]
        qn[k, 0] = q[i, 0]; qn[k, 1] = q[i, 1]; qn[k, 2] = q[i, 2]
    return m


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def update_contacts(q, qrest, idx, radius, skin, skin2, skip2, table, nxt, pairs, qc, near, qn, cstate):
    """Self-contact candidates in two Verlet lists; returns the pairs in the near list.

    The *search list* ``pairs`` holds every pair closer than radius + ``skin`` at its
    spatial-hash search (:func:`find_contacts`, positions ``qc``).  The *near list* ``near``
    holds those of them closer than 1.05 × ``radius`` + ``skin2`` at its filtering
    (:func:`near_pairs`, positions ``qn``): the projections and contact velocities walk only
    it.  Each list is kept until the particles have moved against each other by more than
    the margin it was made with (:func:`contacts_stale`): the near list while the motion since
    its filtering stays below ``skin2``, the search list while the motion since its search
    stays below its radius less the near list's reach.  So at every substep the near list
    holds every pair within 1.05 × ``radius`` (all the contacts and the contact velocities
    can meet), a wide search skin costs no projections, and the hash is searched only when
    the leaf has really moved.  The near list keeps the canonical order, so the results do
    not depend on when either list was made.

    ``cstate`` float64[8] = (search radius, search pairs (−1 = none), searches made, near
    reach, near pairs (−1 = none), filterings made, 1 if a search overflowed the list (it was
    searched again at the near reach; the caller should give it more room), 1 if that search
    overflowed too (pairs within reach may be missing: the caller must grow the list and run
    the frame again))."""
    reach = 1.05 * radius + skin2
    if cstate[1] >= 0.0 and cstate[4] >= 0.0 and not contacts_stale(q, idx, qn, 0.5 * (cstate[3] - 1.05 * radius)):
        return int(cstate[4])
    if cstate[1] < 0.0 or contacts_stale(q, idx, qc, 0.5 * (cstate[0] - reach)):
        search = max(radius + skin, reach)  # never narrower than the near list it feeds
        n, full = find_contacts(q, qrest, idx, search, skip2, table, nxt, qc, pairs)
        cstate[2] += 1.0
        if full and search > reach:
            # pairs did not fit: search again at the near reach only (a list valid for this
            # substep, searched afresh at the next) and have the caller double the list
            cstate[6] = 1.0
            search = reach
            n, full = find_contacts(q, qrest, idx, search, skip2, table, nxt, qc, pairs)
            cstate[2] += 1.0
        if full:
            cstate[6] = 1.0
            cstate[7] = 1.0
        cstate[0] = search
        cstate[1] = n
    m = near_pairs(q, pairs, int(cstate[1]), reach, idx, near, qn)
    cstate[3] = reach
    cstate[4] = m
    cstate[5] += 1.0
    return m
