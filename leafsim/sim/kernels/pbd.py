"""XPBD frame: prediction, Gauss–Seidel projection of distance, bending (signed dihedral) and
thickness (tetrahedron volume) constraints (the passes themselves: :mod:`.scalar` springs,
:mod:`.blocked` hinges and volumes), ground contact with friction, self-collision
(spatial-hash candidates kept in two Verlet lists, projected inside the iteration loop),
velocity update and Voronoi re-placement.

Everything runs on one thread: on the shared 2-core machines this project runs on, the former
graph-coloured ``prange`` kernels (one fork/join per colour per pass) were 13–36× slower than
serial under load, and a parallel path must never lose (measured in ``leafsim bench``,
docs/performance.md); the speed comes from SIMD inside one thread instead.  Constraints are
stored in colour order and, inside one colour, sorted by largest particle index (no two
constraints of one colour share a particle, so that order changes no result and makes the
particle accesses nearly sequential).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from leafsim.sim.kernels import FASTMATH
from leafsim.sim.kernels.blocked import hinges_blocked, volumes_blocked
from leafsim.sim.kernels.contacts import contact_velocities, project_contacts, update_contacts
from leafsim.sim.kernels.rigid import rigid_inertia
from leafsim.sim.kernels.scalar import atan2_, hinge_pass, spring_pass, volume_pass  # noqa: F401  (the reference kernels, re-exported)


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
# One Gauss–Seidel sweep over all constraints of one kind, in storage order (colour by
# colour), each returning the largest |Δx| it made: springs one at a time
# (:mod:`.scalar`), hinges and volumes in blocks of one colour (:mod:`.blocked`, SIMD).

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
def iteration(q, cons, omega):
    """One Gauss–Seidel pass over all constraints: springs, hinges, thickness (each kind in
    colour order).  ``cons`` = (ij, srec, slam, hidx, hrec, hlam, hblocks, vidx, vrec, vblocks,
    B): projection-order indices, per-frame records (:func:`pack_springs`,
    :func:`~.blocked.pack_hinges`, :func:`~.blocked.pack_volumes`), multipliers, block offsets
    and the block buffer.  Returns the largest |Δx| of the pass."""
    ij, srec, slam, hidx, hrec, hlam, hblocks, vidx, vrec, vblocks, B = cons
    big = spring_pass(q, ij, srec, slam, 0, ij.shape[0])
    big = max(big, hinges_blocked(q, hidx, hrec, hlam, omega, hblocks, B))
    return max(big, volumes_blocked(q, vidx, vrec, vblocks, B))


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
    return uninvert_since(q, invm, vidx, hmin, vonly, ground, dint, np.empty(0, np.int64), 0, -1)


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def uninvert_since(q, invm, vidx, hmin, vonly, ground, dint, stamp, now, since):
    """:func:`uninvert` that, with ``since`` ≥ 0, looks only at pairs a particle of which moved
    since the pair's last look: ``stamp`` (n,) int64 holds, per particle, the clock of its last
    move; this pass's look at pair t is clock ``now`` + t, the last pass's was ``since`` + t.
    A pair none of whose four particles moved since then has the very positions it had, so
    the test would decide as it did (no correction), and skipping it changes no bit; a pair
    that was corrected then stamped its particles, so it is looked at again.  ``since`` < 0
    looks at every pair (and ``stamp`` may then be empty)."""
    moved = 0
    track = stamp.shape[0] > 0
    # a pair clearly above hmin is skipped without the square root and divisions: its height
    # times |n|, squared, against hmin² |n|² (1 + 1e-6).  The margin (5e-7 hmin) is far above
    # the exact test's rounding (a few 1e-16 of the V particle's distance to the centroid), so the pairs
    # skipped here are exactly pairs that test skips, and the others take it unchanged.
    fast = hmin > 0.0
    hmin2 = hmin * hmin * (1.0 + 1e-6)
    for t in range(vidx.shape[0]):
        iv, ia, ib, ic = vidx[t, 0], vidx[t, 1], vidx[t, 2], vidx[t, 3]
        if since >= 0 and max(max(stamp[iv], stamp[ia]), max(stamp[ib], stamp[ic])) < since + t:
            continue
        bx = q[ib, 0] - q[ia, 0]; by = q[ib, 1] - q[ia, 1]; bz = q[ib, 2] - q[ia, 2]
        cx = q[ic, 0] - q[ia, 0]; cy = q[ic, 1] - q[ia, 1]; cz = q[ic, 2] - q[ia, 2]
        nx = by * cz - bz * cy; ny = bz * cx - bx * cz; nz = bx * cy - by * cx
        n2 = nx * nx + ny * ny + nz * nz
        s = ((q[iv, 0] - (q[ia, 0] + q[ib, 0] + q[ic, 0]) / 3.0) * nx + (q[iv, 1] - (q[ia, 1] + q[ib, 1] + q[ic, 1]) / 3.0) * ny
             + (q[iv, 2] - (q[ia, 2] + q[ib, 2] + q[ic, 2]) / 3.0) * nz)
        if fast and s > 0.0 and s * s > hmin2 * n2:
            continue
        nl = math.sqrt(n2)
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
            if track:
                stamp[iv] = now + t; stamp[ia] = now + t; stamp[ib] = now + t; stamp[ic] = now + t
            moved += 1
    return moved


@njit(cache=True, fastmath=FASTMATH, nogil=True)
def pair_dryness(water, w0, a, b):
    """The share of their water that particles a and b have lost together, clipped to [0, 1]:
    dry = 1 − (w_a + w_b) / (w0_a + w0_b) (the stiffening of a hinge's shared edge or a spring)."""
    dry = 1.0 - (water[a] + water[b]) / max(w0[a] + w0[b], 1e-300)
    if dry < 0.0:
        return 0.0
    if dry > 1.0:
        return 1.0
    return dry


@njit(cache=True, fastmath=FASTMATH, nogil=True)
def hinge_compliance(hidx, water, w0, kbend, kdry, hgeom, krod, inv_h2, halpha, turgor=0.0, tlp=0.85, power=1.0):
    """XPBD compliance / Δt² of every hinge: k = D s(dry) · geom + k_rod c(dry) [N·m/rad], D the
    blade's bending stiffness [N·m], geom the hinge's weight (material.hinge_weights: 3|e|²/(A₁+A₂)
    by default, leafsim.sim.bending), k_rod the vein's E_v I/ℓ̄ share;
    dry = 1 − (w_a + w_b) / (w0_a + w0_b) over the hinge's shared edge a–b, RWC = 1 − dry.

    Turgor (share T of the fresh stiffness, lost linearly down to the turgor-loss point RWC =
    ``tlp``: t = clip((RWC − tlp)/(1 − tlp), 0, 1)) and dry stiffening (k_dry, growing as dry^p):
    c = (1 − T) + T t for the veins and s = c + (k_dry + T) dry^p for the lamina, so a fresh
    leaf has D, a dried one D (1 + k_dry), and one at the turgor-loss point wilts.  T = 0,
    p = 1 is the plain law D (1 + k_dry dry) + k_rod."""
    plain = turgor == 0.0 and power == 1.0
    for e in range(hidx.shape[0]):
        dry = pair_dryness(water, w0, hidx[e, 2], hidx[e, 3])
        if plain:
            halpha[e] = inv_h2 / (kbend * (1.0 + kdry * dry) * hgeom[e] + krod[e])
        else:
            t = (1.0 - dry - tlp) / max(1.0 - tlp, 1e-9)
            t = min(max(t, 0.0), 1.0)
            c = 1.0 - turgor + turgor * t
            s = c + (kdry + turgor) * dry ** power
            halpha[e] = inv_h2 / (kbend * s * hgeom[e] + krod[e] * c)


@njit(cache=True, fastmath=FASTMATH, nogil=True)
def spring_stiffness(ij, water, w0, klam, krod, kdry, power, out):
    """Stiffness [N/m] of every spring as its tissue dries: k = k_lam (1 + k_dry dry^p) + k_rod,
    dry = 1 − (w_a + w_b) / (w0_a + w0_b) over the spring's ends (the lamina's share k_lam
    stiffens, the vein's rod share k_rod does not; ``material.stiffening_stretch``)."""
    for s in range(ij.shape[0]):
        dry = pair_dryness(water, w0, ij[s, 0], ij[s, 1])
        f = dry if power == 1.0 else dry ** power
        out[s] = klam[s] * (1.0 + kdry * f) + krod[s]


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
def masses(invm, out):
    """out[i] = 1 / invm[i] (0 for a pinned particle): a frame's masses, for :func:`remove_rigid`."""
    for i in range(invm.shape[0]):
        out[i] = 1.0 / invm[i] if invm[i] > 0.0 else 0.0


@njit(cache=True, fastmath=FASTMATH, nogil=True)
def remove_rigid(q, q_old, invm, dint, mass):
    """Internal forces carry no net momentum.  A Gauss–Seidel sweep conserves linear and
    angular momentum only to first order (each projection is exact at the positions it sees,
    the sweep's sum is not), and on frustrated constraints the second-order remainder adds up
    to a steady spin or crawl.  This removes from the positions the translation and the
    rotation about the old centre of mass contained in the internal displacement ``dint``:
    afterwards Σ m Δ = 0 and Σ m (x_old − c) × Δ = 0, i.e. the substep's internal impulses
    leave L = Σ m x × v exactly unchanged (x_new = x_old + h v_new).  ``mass`` (n,): the
    frame's :func:`masses` (two divisions per particle per substep were a third of this pass).
    Returns nothing."""
    n = q.shape[0]
    M = 0.0
    cx = 0.0; cy = 0.0; cz = 0.0
    px = 0.0; py = 0.0; pz = 0.0
    for i in range(n):
        if invm[i] <= 0.0:
            continue
        m = mass[i]
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
        m = mass[i]
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
    ``cons``: see :func:`iteration`.  Writes the contact hits of the last iteration to out[1];
    returns the iterations run."""
    slam = cons[2]
    hlam = cons[5]
    slam[:] = 0.0
    hlam[:] = 0.0
    it = 0
    hits = 0
    while it < iters:
        it += 1
        if ground:
            ground_clamp(q, invm, pen)
        ch = iteration(q, cons, omega)
        if ncont:
            hits = project_contacts(q, invm, pairs, ncont, radius)
        if ch < tol and hits == 0:
            break
    out[1] = hits
    return it


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def settle(q, invm, vidx, thick, ground, dint, out, stamp):
    """No layer inversion after the substep's projections: momentum-conserving passes (vertices
    resting on the ground stay), then a V-only pass for anything neighbours undid.  The first
    pass looks at every pair; the later ones only at pairs with a particle moved since their
    last look (:func:`uninvert_since`, ``stamp`` (n,) int64 scratch), with the same result:
    a leaf with one pair squeezed below its minimum height each substep paid three full
    passes for it (each correction is linear, so it leaves ~10⁻³ of the deficit)."""
    m = vidx.shape[0]
    stamp[:] = -1
    n_fix = 0
    k = 0
    r = 0
    while r < 3:
        k = uninvert_since(q, invm, vidx, 0.25 * thick, False, ground, dint, stamp, r * m, (r - 1) * m)
        n_fix += k
        r += 1
        if k == 0:
            break
    if k:
        uninvert_since(q, invm, vidx, 0.2 * thick, True, ground, dint, stamp, r * m, (r - 1) * m)
    out[2] = n_fix


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def frame(q, qd, q_old, invm, gz, h, substeps, keep, iters, tol, cons, vidx,
          pbd, ground, pen, mu, self_coll, contact, replace, hgt, thick, conserve, qa, dint, omega, rigid, out):
    """All ``substeps`` of one dynamics frame in one call (no Python between substeps or
    iterations).  Per substep: predict; iterate (:func:`project`: ground clamp — external —
    then the internal constraints ``cons`` in projection order, self-contacts); un-invert
    layers (``vidx`` in model order); with ``conserve`` remove the rigid part of the internal
    displacement (:func:`remove_rigid`; not with pinned particles); ground contact + friction;
    velocity update with damping, inelastic self-contacts; the rigid modes' real inertia
    (:func:`.rigid.rigid_inertia`, ``rigid`` = (mode, pin x, y, z, M − 1, air factor, ground
    reach); mode 0: off).  ``contact`` = (qrest,
    T_idx, radius, skin, skin2, skip2, table, nxt, pairs, qc, near, qn, cstate) for
    :func:`update_contacts`.
    ``qa``/``dint`` (n, 3) scratch.  Writes (iterations, contact hits, uninverted) to ``out``
    (int64[3])."""
    qrest, T_idx, radius, skin, skin2, skip2, table, nxt, pairs, qc, near, qn, cstate = contact
    rmode, rpx, rpy, rpz, rgain, rkratio, reps = rigid
    its = 0
    stamp = np.empty(q.shape[0], np.int64)
    mass = np.empty(q.shape[0])
    if pbd and conserve:
        masses(invm, mass)
    for _ in range(substeps):
        predict(q, qd, q_old, qa, dint, invm, gz, h)
        if replace:
            voronoi_heights(q_old, vidx, hgt)
        ncont = 0
        if pbd:
            if self_coll:
                ncont = update_contacts(q, qrest, T_idx, radius, skin, skin2, skip2, table, nxt, pairs, qc, near, qn,
                                        cstate)
            its += project(q, invm, cons, omega, iters, tol, ground, pen, near, ncont, radius, out)
            internal_delta(q, qa, pen, dint)
        if pbd:
            settle(q, invm, vidx, thick, ground, dint, out, stamp)
            if conserve:
                remove_rigid(q, q_old, invm, dint, mass)
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
            contact_velocities(q, qd, invm, near, ncont, radius)
        if rmode:
            rigid_inertia(q, qd, invm, dint, h, gz, rmode, rpx, rpy, rpz, rgain, rkratio, ground, reps)
        if replace:
            voronoi_replace(q, vidx, hgt, 0.25 * thick)
            if ground:
                clamp_ground(q)
    out[0] = its
