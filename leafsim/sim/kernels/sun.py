"""Sun et al.'s plant dynamics (Graphical Models 118, 2021) as an explicit integrator of the
blade's elastic energy (``dynamics.integrator = sun``).

Forces, not projections: the same energy the XPBD loop minimises (membrane and vein springs,
discrete-shell bending hinges, thickness volumes, gravity) differentiated into forces, Sun's
damping force and the cells' turgor force, integrated with the explicit midpoint rule:

    a(x, v) = M⁻¹ (F_e(x) + F_d(x, v) + F_p) + g − c v
    x_½ = x + ½h v,  v_½ = v + ½h a(x, v)
    x' = x + h v_½,  v' = v + h a(x_½, v_½)

* F_e: springs −k (|d| − ℓ) d̂; hinges −k_θ (θ − θ₀) ∇θ (the dihedral gradient of the XPBD
  hinge); volumes −k_V (C − C₀) ∇C with C = 6 × the tetrahedron volume and
  k_V = E / (2 C₀), the through-thickness stiffness of the tissue the tetrahedron stands for
  (energy ½ E A d (Δd/d)², d the layer's height over its triangle, C₀ = 2 A d).
* F_d: stiffness-proportional (Rayleigh) damping β on each of those, −β k Ċ ∇C: it damps the
  stiff modes an explicit step would otherwise amplify (the midpoint rule's stability region
  does not contain the undamped imaginary axis), and leaves the slow bending modes to the
  mass-proportional drag c (``dynamics.damping``).
* F_p: Sun's turgor force k_p Σ a_ij ΔP x̂_ij along every membrane spring, ΔP the cells' loss
  of turgor pressure (≤ 0: drying cells pull their neighbours in), precomputed per spring
  (``tf``).

Ground and self-contacts are position corrections after the step, as in the XPBD loop; a
particle a correction moved takes the PBD velocity (x' − x)/h.  Internal forces come in equal
and opposite pairs (the hinge and volume gradients sum to zero), so the step conserves linear
momentum exactly; no rigid-motion removal is needed.

Everything runs on one thread (see :mod:`.pbd`).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numba import njit

from leafsim.sim.kernels import FASTMATH
from leafsim.sim.kernels.contacts import contact_velocities, project_contacts, update_contacts
from leafsim.sim.kernels.pbd import clamp_ground, ground_clamp, ground_contact, uninvert, voronoi_heights, voronoi_replace
from leafsim.sim.kernels.rigid import rigid_inertia
from leafsim.sim.kernels.scalar import atan2_


@lru_cache(maxsize=64)
def stable_courant(zeta: float) -> float:
    """The largest Y such that the explicit midpoint rule is stable for every mode with
    ω h = y ≤ Y when the Rayleigh damping gives the mode at Y the damping ratio ``zeta`` (and a
    slower mode ζ y / Y): max Y with |1 + z + z²/2| ≤ 1 for z = y(−ζ_y + i√(1 − ζ_y²)).
    0.3 → 1.65, 0.1 → 1.05, 0.5 → 2.0; 0 for no damping (an undamped mode always grows)."""
    zeta = min(max(float(zeta), 0.0), 1.0)
    best = 0.0
    frac = np.linspace(1e-3, 1.0, 1000)
    for Y in np.arange(0.005, 2.5, 0.005):
        y = frac * Y
        zy = zeta * frac
        z = y * (-zy + 1j * np.sqrt(1.0 - zy * zy))
        if np.all(np.abs(1.0 + z + 0.5 * z * z) <= 1.0 + 1e-12):
            best = float(Y)
        else:
            break
    return best


@njit(cache=True, nogil=True, fastmath=FASTMATH, error_model="numpy")
def forces(q, v, ij, sk, srest, tf, hidx, hk, hrest, vidx, vk, vrest, beta, F):
    """F ← the internal forces at (q, v): springs, hinges and volumes, each elastic plus its
    Rayleigh damping β k Ċ, and the turgor force ``tf`` along the springs.  Returns the elastic
    energy."""
    F[:] = 0.0
    energy = 0.0
    for s in range(ij.shape[0]):
        a = ij[s, 0]
        b = ij[s, 1]
        dx = q[a, 0] - q[b, 0]; dy = q[a, 1] - q[b, 1]; dz = q[a, 2] - q[b, 2]
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        if d < 1e-12:
            continue
        nx = dx / d; ny = dy / d; nz = dz / d
        rel = (v[a, 0] - v[b, 0]) * nx + (v[a, 1] - v[b, 1]) * ny + (v[a, 2] - v[b, 2]) * nz
        C = d - srest[s]
        energy += 0.5 * sk[s] * C * C
        f = -sk[s] * (C + beta * rel) + tf[s]
        F[a, 0] += f * nx; F[a, 1] += f * ny; F[a, 2] += f * nz
        F[b, 0] -= f * nx; F[b, 1] -= f * ny; F[b, 2] -= f * nz
    for e in range(hidx.shape[0]):
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
        # ∇θ (the gradients of scalar.hinge_pass): u1 = g1 n1, u2 = g2 n2, u3, u4 = −(u1 + u2 + u3)
        g1 = el / l1
        g2 = el / l2
        p1 = (ax * ex + ay * ey + az * ez - el2) / (el * l1)
        p2 = (cx * ex + cy * ey + cz * ez) / (el * l2)
        u1x = g1 * n1x; u1y = g1 * n1y; u1z = g1 * n1z
        u2x = g2 * n2x; u2y = g2 * n2y; u2z = g2 * n2z
        u3x = p1 * n1x + p2 * n2x; u3y = p1 * n1y + p2 * n2y; u3z = p1 * n1z + p2 * n2z
        u4x = -(u1x + u2x + u3x); u4y = -(u1y + u2y + u3y); u4z = -(u1z + u2z + u3z)
        rate = (u1x * v[i1, 0] + u1y * v[i1, 1] + u1z * v[i1, 2] + u2x * v[i2, 0] + u2y * v[i2, 1] + u2z * v[i2, 2]
                + u3x * v[i3, 0] + u3y * v[i3, 1] + u3z * v[i3, 2] + u4x * v[i4, 0] + u4y * v[i4, 1] + u4z * v[i4, 2])
        energy += 0.5 * hk[e] * C * C
        f = -hk[e] * (C + beta * rate)
        F[i1, 0] += f * u1x; F[i1, 1] += f * u1y; F[i1, 2] += f * u1z
        F[i2, 0] += f * u2x; F[i2, 1] += f * u2y; F[i2, 2] += f * u2z
        F[i3, 0] += f * u3x; F[i3, 1] += f * u3y; F[i3, 2] += f * u3z
        F[i4, 0] += f * u4x; F[i4, 1] += f * u4y; F[i4, 2] += f * u4z
    for t in range(vidx.shape[0]):
        iv = vidx[t, 0]; ia = vidx[t, 1]; ib = vidx[t, 2]; ic = vidx[t, 3]
        bx = q[ib, 0] - q[ia, 0]; by = q[ib, 1] - q[ia, 1]; bz = q[ib, 2] - q[ia, 2]
        cx = q[ic, 0] - q[ia, 0]; cy = q[ic, 1] - q[ia, 1]; cz = q[ic, 2] - q[ia, 2]
        vx = q[iv, 0] - q[ia, 0]; vy = q[iv, 1] - q[ia, 1]; vz = q[iv, 2] - q[ia, 2]
        gvx = by * cz - bz * cy; gvy = bz * cx - bx * cz; gvz = bx * cy - by * cx
        gbx = cy * vz - cz * vy; gby = cz * vx - cx * vz; gbz = cx * vy - cy * vx
        gcx = vy * bz - vz * by; gcy = vz * bx - vx * bz; gcz = vx * by - vy * bx
        gax = -(gvx + gbx + gcx); gay = -(gvy + gby + gcy); gaz = -(gvz + gbz + gcz)
        C = vx * gvx + vy * gvy + vz * gvz - vrest[t]
        rate = (gvx * v[iv, 0] + gvy * v[iv, 1] + gvz * v[iv, 2] + gax * v[ia, 0] + gay * v[ia, 1] + gaz * v[ia, 2]
                + gbx * v[ib, 0] + gby * v[ib, 1] + gbz * v[ib, 2] + gcx * v[ic, 0] + gcy * v[ic, 1] + gcz * v[ic, 2])
        energy += 0.5 * vk[t] * C * C
        f = -vk[t] * (C + beta * rate)
        F[iv, 0] += f * gvx; F[iv, 1] += f * gvy; F[iv, 2] += f * gvz
        F[ia, 0] += f * gax; F[ia, 1] += f * gay; F[ia, 2] += f * gaz
        F[ib, 0] += f * gbx; F[ib, 1] += f * gby; F[ib, 2] += f * gbz
        F[ic, 0] += f * gcx; F[ic, 1] += f * gcy; F[ic, 2] += f * gcz
    return energy


@njit(cache=True, nogil=True, fastmath=FASTMATH, error_model="numpy")
def stiffness_bound(q, invm, ij, sk, hidx, hk, vidx, vk, row):
    """An upper bound on the largest eigenvalue ω² of M⁻¹K, K the elastic forces' stiffness
    at q (Gershgorin over 3 × 3 blocks: ω² ≤ max_i w_i Σ_e k_e |∇C_e,i| Σ_j |∇C_e,j|, the
    Gauss–Newton part of each element's Hessian); ``row`` (n,) scratch."""
    row[:] = 0.0
    for s in range(ij.shape[0]):
        row[ij[s, 0]] += 2.0 * sk[s]
        row[ij[s, 1]] += 2.0 * sk[s]
    for e in range(hidx.shape[0]):
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
        g1 = el / l1
        g2 = el / l2
        p1 = (ax * ex + ay * ey + az * ez - el2) / (el * l1)
        p2 = (cx * ex + cy * ey + cz * ez) / (el * l2)
        u3x = p1 * n1x + p2 * n2x; u3y = p1 * n1y + p2 * n2y; u3z = p1 * n1z + p2 * n2z
        u4x = -(g1 * n1x + g2 * n2x + u3x); u4y = -(g1 * n1y + g2 * n2y + u3y); u4z = -(g1 * n1z + g2 * n2z + u3z)
        a1 = el / math.sqrt(l1)
        a2 = el / math.sqrt(l2)
        a3 = math.sqrt(u3x * u3x + u3y * u3y + u3z * u3z)
        a4 = math.sqrt(u4x * u4x + u4y * u4y + u4z * u4z)
        k = hk[e] * (a1 + a2 + a3 + a4)
        row[i1] += k * a1; row[i2] += k * a2; row[i3] += k * a3; row[i4] += k * a4
    for t in range(vidx.shape[0]):
        iv = vidx[t, 0]; ia = vidx[t, 1]; ib = vidx[t, 2]; ic = vidx[t, 3]
        bx = q[ib, 0] - q[ia, 0]; by = q[ib, 1] - q[ia, 1]; bz = q[ib, 2] - q[ia, 2]
        cx = q[ic, 0] - q[ia, 0]; cy = q[ic, 1] - q[ia, 1]; cz = q[ic, 2] - q[ia, 2]
        vx = q[iv, 0] - q[ia, 0]; vy = q[iv, 1] - q[ia, 1]; vz = q[iv, 2] - q[ia, 2]
        gvx = by * cz - bz * cy; gvy = bz * cx - bx * cz; gvz = bx * cy - by * cx
        gbx = cy * vz - cz * vy; gby = cz * vx - cx * vz; gbz = cx * vy - cy * vx
        gcx = vy * bz - vz * by; gcy = vz * bx - vx * bz; gcz = vx * by - vy * bx
        gax = -(gvx + gbx + gcx); gay = -(gvy + gby + gcy); gaz = -(gvz + gbz + gcz)
        av = math.sqrt(gvx * gvx + gvy * gvy + gvz * gvz)
        aa = math.sqrt(gax * gax + gay * gay + gaz * gaz)
        ab = math.sqrt(gbx * gbx + gby * gby + gbz * gbz)
        ac = math.sqrt(gcx * gcx + gcy * gcy + gcz * gcz)
        k = vk[t] * (av + aa + ab + ac)
        row[iv] += k * av; row[ia] += k * aa; row[ib] += k * ab; row[ic] += k * ac
    big = 0.0
    for i in range(row.shape[0]):
        r = invm[i] * row[i]
        if r > big:
            big = r
    return big


@njit(cache=True, nogil=True, fastmath=FASTMATH, error_model="numpy")
def accelerate(F, v, invm, gz, c, out):
    """out ← M⁻¹ F + g − c v (pinned particles, 1/m = 0, do not accelerate)."""
    for i in range(F.shape[0]):
        w = invm[i]
        if w > 0.0:
            out[i, 0] = w * F[i, 0] - c * v[i, 0]
            out[i, 1] = w * F[i, 1] - c * v[i, 1]
            out[i, 2] = w * F[i, 2] - c * v[i, 2] + gz
        else:
            out[i, 0] = 0.0; out[i, 1] = 0.0; out[i, 2] = 0.0


@njit(cache=True, nogil=True, fastmath=FASTMATH, error_model="numpy")
def frame(q, qd, q_old, invm, gz, h, substeps, c, beta, elastic, ground, pen, mu, self_coll, contact, replace,
          hgt, thick, F, acc, qm, vm, qa, layers, vol_idx, rigid, out):
    """All ``substeps`` explicit-midpoint steps of one frame.  ``elastic`` = (ij, sk, srest, tf,
    hidx, hk, hrest, vidx, vk, vrest) (model order); ``contact`` as in :func:`.pbd.frame`;
    ``layers``: keep the V layer above its triangles (the constraints are on); ``vol_idx`` the
    model's tetrahedra (for the un-inversion and the thesis re-placement); ``rigid`` the rigid
    modes' real inertia as in :func:`.pbd.frame` (the elastic forces' displacement h² F / m in
    the place of the internal one).  Pinned particles
    (1/m = 0) stay where they are.  Writes (substeps, contact hits, uninverted) to ``out`` and
    returns the elastic energy at the frame's end.  Compiled with fastmath, this kernel cannot
    see a NaN: the caller checks the positions after it."""
    ij, sk, srest, tf, hidx, hk, hrest, vidx, vk, vrest = elastic
    for i in range(q.shape[0]):
        if invm[i] <= 0.0:  # pinned: no velocity (it may have had one before it was pinned)
            qd[i, 0] = 0.0; qd[i, 1] = 0.0; qd[i, 2] = 0.0
    qrest, T_idx, radius, skin, skin2, skip2, table, nxt, pairs, qc, near, qn, cstate = contact
    rmode, rpx, rpy, rpz, rgain, rkratio, reps = rigid
    n = q.shape[0]
    energy = 0.0
    for _ in range(substeps):
        if replace:
            voronoi_heights(q, vol_idx, hgt)
        # the midpoint rule
        forces(q, qd, ij, sk, srest, tf, hidx, hk, hrest, vidx, vk, vrest, beta, F)
        accelerate(F, qd, invm, gz, c, acc)
        for i in range(n):
            for k in range(3):
                q_old[i, k] = q[i, k]
                qm[i, k] = q[i, k] + 0.5 * h * qd[i, k]
                vm[i, k] = qd[i, k] + 0.5 * h * acc[i, k]
        energy = forces(qm, vm, ij, sk, srest, tf, hidx, hk, hrest, vidx, vk, vrest, beta, F)
        accelerate(F, vm, invm, gz, c, acc)
        for i in range(n):
            for k in range(3):
                q[i, k] += h * vm[i, k]
                qd[i, k] += h * acc[i, k]
                qa[i, k] = q[i, k]
        # contacts: position corrections, as in the XPBD loop
        ncont = 0
        out[1] = 0
        if self_coll:
            ncont = update_contacts(q, qrest, T_idx, radius, skin, skin2, skip2, table, nxt, pairs, qc, near, qn, cstate)
            if ncont:
                out[1] = project_contacts(q, invm, near, ncont, radius)
        if ground:
            ground_clamp(q, invm, pen)
        if layers:
            out[2] += uninvert(q, invm, vol_idx, 0.25 * thick, False, ground, vm)  # vm: scratch by now
        if ground:
            ground_contact(q, q_old, invm, pen, mu)
        # a particle a correction moved takes the PBD velocity
        inv = 1.0 / h
        for i in range(n):
            if q[i, 0] != qa[i, 0] or q[i, 1] != qa[i, 1] or q[i, 2] != qa[i, 2]:
                for k in range(3):
                    qd[i, k] = (q[i, k] - q_old[i, k]) * inv
        if ncont:
            contact_velocities(q, qd, invm, near, ncont, radius)
        if rmode:
            for i in range(n):  # qm is scratch by now: the elastic forces' displacement
                for k in range(3):
                    qm[i, k] = h * h * F[i, k] * invm[i]
            rigid_inertia(q, qd, invm, qm, h, gz, rmode, rpx, rpy, rpz, rgain, rkratio, ground, reps)
        if replace:
            voronoi_replace(q, vol_idx, hgt, 0.25 * thick)
            if ground:
                clamp_ground(q)
    out[0] = substeps
    return energy
