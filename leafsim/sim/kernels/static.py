"""Energy, gradient and a positive semi-definite Hessian of the blade's elastic energy, for
the static-equilibrium solver (:mod:`leafsim.sim.equilibrium`).

The energy is the one :mod:`.sun` differentiates into forces (membrane and vein springs
½ k (|d| − ℓ)², discrete-shell hinges ½ k_θ (θ − θ₀)², thickness volumes ½ k_V (C − C₀)²).
The Hessian is assembled per element into 3 × 3 particle blocks of a block-sparse matrix whose
pattern is fixed by the topology (:func:`block_pattern`): each element writes straight into
its blocks through a precomputed map, no sorting per solve.

* springs: the exact Hessian k (d̂d̂ᵀ + (1 − ℓ/|d|)(I − d̂d̂ᵀ));
* hinges and volumes: k ∇C ∇Cᵀ plus the residual term k C ∇²C, ∇²C by forward differences
  of the exact ∇C (exact for the volumes, whose ∇C is bilinear).

With ``spd`` the blocks are positive semi-definite instead: the springs' transverse part is
clamped at zero in compression and the residual terms are left out (Gauss–Newton).  The
solver uses the exact form: the Gauss–Newton one converged only linearly (0.92 per iteration)
on a curled, frustrated oak, where the volumes carry large stresses.  Projecting each hinge's
and volume's exact 12 × 12 Hessian onto its non-negative eigenvalues (projected Newton) was
measured too (4 December) and dropped: it never needed the Levenberg–Marquardt damping, but
from oak's hand-over it stopped at the 200-iteration cap (residual 0.03 × weight, linear near
the solution) where the exact form converges in 19, and from maple's it also reached the cap
(residual 41 × weight, 112 s) where the exact form needs 173.  A hybrid (the exact form,
and the projected one in place of the damping where the exact one is indefinite) halved
maple's first solve (84 iterations, 55 s against 97 s) but slowed oak's (24 against 19):
not adopted, since the static finish stays slower than XPBD on maple either way.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from leafsim.sim.kernels.scalar import atan2_


def block_pattern(n: int, ij: np.ndarray, hidx: np.ndarray, vidx: np.ndarray):
    """The 3 × 3 block pattern of the Hessian of ``n`` particles under springs ``ij`` (s, 2),
    hinges ``hidx`` (h, 4) and volumes ``vidx`` (m, 4): (indptr (n+1,), indices (nnzb,),
    spring map (s, 2, 2), hinge map (h, 4, 4), volume map (m, 4, 4)), the maps giving the
    block each element's particle pair (p, q) writes to.  Every diagonal block is present."""
    def pairs(idx):
        k = idx.shape[1]
        a = np.repeat(idx, k, axis=1).reshape(-1).astype(np.int64)
        b = np.tile(idx, (1, k)).reshape(-1).astype(np.int64)
        return a * n + b

    diag = np.arange(n, dtype=np.int64) * (n + 1)
    keys = np.unique(np.concatenate([diag, pairs(ij), pairs(hidx), pairs(vidx)]))
    rows = keys // n
    indices = (keys % n).astype(np.int64)
    indptr = np.zeros(n + 1, np.int64)
    np.add.at(indptr, rows + 1, 1)
    np.cumsum(indptr, out=indptr)

    def where(idx):
        k = idx.shape[1]
        return np.searchsorted(keys, pairs(idx)).reshape(len(idx), k, k).astype(np.int64)

    return indptr, indices, where(ij), where(hidx), where(vidx)


@njit(cache=True, nogil=True, error_model="numpy")
def _add_outer(data, blk, k, gx, gy, gz, hx, hy, hz):
    data[blk, 0, 0] += k * gx * hx; data[blk, 0, 1] += k * gx * hy; data[blk, 0, 2] += k * gx * hz
    data[blk, 1, 0] += k * gy * hx; data[blk, 1, 1] += k * gy * hy; data[blk, 1, 2] += k * gy * hz
    data[blk, 2, 0] += k * gz * hx; data[blk, 2, 1] += k * gz * hy; data[blk, 2, 2] += k * gz * hz


@njit(cache=True, nogil=True, error_model="numpy")
def _hinge_grad(x, u):
    """∇θ of the dihedral angle of the four points ``x`` (4, 3) = (c, d, a, b) into ``u``
    (4, 3) (the gradients of :func:`.scalar.hinge_pass`); returns θ (nan when degenerate)."""
    ex = x[3, 0] - x[2, 0]; ey = x[3, 1] - x[2, 1]; ez = x[3, 2] - x[2, 2]
    ax = x[0, 0] - x[2, 0]; ay = x[0, 1] - x[2, 1]; az = x[0, 2] - x[2, 2]
    cx = x[1, 0] - x[3, 0]; cy = x[1, 1] - x[3, 1]; cz = x[1, 2] - x[3, 2]
    n1x = ey * az - ez * ay; n1y = ez * ax - ex * az; n1z = ex * ay - ey * ax
    n2x = cy * ez - cz * ey; n2y = cz * ex - cx * ez; n2z = cx * ey - cy * ex
    el2 = ex * ex + ey * ey + ez * ez
    l1 = n1x * n1x + n1y * n1y + n1z * n1z
    l2 = n2x * n2x + n2y * n2y + n2z * n2z
    if el2 < 1e-24 or l1 < 1e-30 or l2 < 1e-30:
        return math.nan
    el = math.sqrt(el2)
    g1 = el / l1
    g2 = el / l2
    p1 = (ax * ex + ay * ey + az * ez - el2) / (el * l1)
    p2 = (cx * ex + cy * ey + cz * ez) / (el * l2)
    u[0, 0] = g1 * n1x; u[0, 1] = g1 * n1y; u[0, 2] = g1 * n1z
    u[1, 0] = g2 * n2x; u[1, 1] = g2 * n2y; u[1, 2] = g2 * n2z
    u[2, 0] = p1 * n1x + p2 * n2x; u[2, 1] = p1 * n1y + p2 * n2y; u[2, 2] = p1 * n1z + p2 * n2z
    for c in range(3):
        u[3, c] = -(u[0, c] + u[1, c] + u[2, c])
    return atan2_(el * (n2x * ax + n2y * ay + n2z * az), n1x * n2x + n1y * n2y + n1z * n2z)


@njit(cache=True, nogil=True, error_model="numpy")
def _wrap(C):
    """An angle difference into (−π, π]."""
    if C > math.pi:
        return C - 2 * math.pi
    if C < -math.pi:
        return C + 2 * math.pi
    return C


@njit(cache=True, nogil=True, error_model="numpy")
def _vol_grad(x, u):
    """∇C of C = 6 × the signed volume of the tetrahedron ``x`` (4, 3) = (v, a, b, c) into
    ``u`` (4, 3); returns C."""
    bx = x[2, 0] - x[1, 0]; by = x[2, 1] - x[1, 1]; bz = x[2, 2] - x[1, 2]
    cx = x[3, 0] - x[1, 0]; cy = x[3, 1] - x[1, 1]; cz = x[3, 2] - x[1, 2]
    vx = x[0, 0] - x[1, 0]; vy = x[0, 1] - x[1, 1]; vz = x[0, 2] - x[1, 2]
    u[0, 0] = by * cz - bz * cy; u[0, 1] = bz * cx - bx * cz; u[0, 2] = bx * cy - by * cx
    u[2, 0] = cy * vz - cz * vy; u[2, 1] = cz * vx - cx * vz; u[2, 2] = cx * vy - cy * vx
    u[3, 0] = vy * bz - vz * by; u[3, 1] = vz * bx - vx * bz; u[3, 2] = vx * by - vy * bx
    for c in range(3):
        u[1, c] = -(u[0, c] + u[2, c] + u[3, c])
    return vx * u[0, 0] + vy * u[0, 1] + vz * u[0, 2]


@njit(cache=True, nogil=True, error_model="numpy")
def _spring_terms(q, ij, sk, srest, smap, grad, data, hessian, spd, energy):
    """The springs' share of :func:`elastic`, added to ``energy`` (returned), ``grad`` and
    ``data``: the exact Hessian k (d̂d̂ᵀ + (1 − ℓ/|d|)(I − d̂d̂ᵀ)), the transverse part clamped at
    zero in compression with ``spd``."""
    for s in range(ij.shape[0]):
        a = ij[s, 0]
        b = ij[s, 1]
        dx = q[a, 0] - q[b, 0]; dy = q[a, 1] - q[b, 1]; dz = q[a, 2] - q[b, 2]
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        if d < 1e-15:
            continue
        nx = dx / d; ny = dy / d; nz = dz / d
        C = d - srest[s]
        k = sk[s]
        energy += 0.5 * k * C * C
        f = k * C
        grad[a, 0] += f * nx; grad[a, 1] += f * ny; grad[a, 2] += f * nz
        grad[b, 0] -= f * nx; grad[b, 1] -= f * ny; grad[b, 2] -= f * nz
        if hessian:
            t = 1.0 - srest[s] / d
            if spd and t < 0.0:
                t = 0.0
            n3 = (nx, ny, nz)
            for r in range(3):
                for c in range(3):
                    v = k * ((1.0 - t) * n3[r] * n3[c] + (t if r == c else 0.0))
                    data[smap[s, 0, 0], r, c] += v
                    data[smap[s, 1, 1], r, c] += v
                    data[smap[s, 0, 1], r, c] -= v
                    data[smap[s, 1, 0], r, c] -= v
    return energy


@njit(cache=True, nogil=True, error_model="numpy")
def _hinge_terms(q, hidx, hk, hrest, hmap, grad, data, hessian, spd, energy, x, u, w):
    """The hinges' share of :func:`elastic`, added to ``energy`` (returned), ``grad`` and
    ``data``: k ∇θ ∇θᵀ, plus the residual term k C ∇²θ by forward differences of the exact ∇θ
    (symmetrised) without ``spd``.  ``x``, ``u``, ``w`` (4, 3) are scratch."""
    for e in range(hidx.shape[0]):
        for p in range(4):
            for c in range(3):
                x[p, c] = q[hidx[e, p], c]
        theta = _hinge_grad(x, u)
        if math.isnan(theta):
            continue
        C = _wrap(theta - hrest[e])
        k = hk[e]
        energy += 0.5 * k * C * C
        f = k * C
        for p in range(4):
            ip = hidx[e, p]
            grad[ip, 0] += f * u[p, 0]; grad[ip, 1] += f * u[p, 1]; grad[ip, 2] += f * u[p, 2]
        if hessian:
            for p in range(4):
                for r in range(4):
                    _add_outer(data, hmap[e, p, r], k, u[p, 0], u[p, 1], u[p, 2], u[r, 0], u[r, 1], u[r, 2])
            if not spd and f != 0.0:
                el = math.sqrt((x[3, 0] - x[2, 0]) ** 2 + (x[3, 1] - x[2, 1]) ** 2 + (x[3, 2] - x[2, 2]) ** 2)
                dlt = 1e-7 * el
                for r in range(4):
                    for c in range(3):
                        x[r, c] += dlt
                        th = _hinge_grad(x, w)
                        x[r, c] -= dlt
                        if math.isnan(th):
                            continue
                        for p in range(4):
                            blk = hmap[e, p, r]
                            blt = hmap[e, r, p]
                            for d in range(3):
                                v = 0.5 * f * (w[p, d] - u[p, d]) / dlt
                                data[blk, d, c] += v
                                data[blt, c, d] += v
    return energy


@njit(cache=True, nogil=True, error_model="numpy")
def _volume_terms(q, vidx, vk, vrest, vmap, grad, data, hessian, spd, energy, x, u, w):
    """The thickness volumes' share of :func:`elastic`, added to ``energy`` (returned), ``grad``
    and ``data``: k ∇C ∇Cᵀ, plus k C ∇²C without ``spd`` (∇C is bilinear, so forward
    differences are exact).  ``x``, ``u``, ``w`` (4, 3) are scratch."""
    for t in range(vidx.shape[0]):
        for p in range(4):
            for c in range(3):
                x[p, c] = q[vidx[t, p], c]
        C = _vol_grad(x, u) - vrest[t]
        k = vk[t]
        energy += 0.5 * k * C * C
        f = k * C
        for p in range(4):
            ip = vidx[t, p]
            grad[ip, 0] += f * u[p, 0]; grad[ip, 1] += f * u[p, 1]; grad[ip, 2] += f * u[p, 2]
        if hessian:
            for p in range(4):
                for r in range(4):
                    _add_outer(data, vmap[t, p, r], k, u[p, 0], u[p, 1], u[p, 2], u[r, 0], u[r, 1], u[r, 2])
            if not spd and f != 0.0:
                for r in range(4):
                    for c in range(3):
                        x[r, c] += 1.0
                        _vol_grad(x, w)
                        x[r, c] -= 1.0
                        for p in range(4):
                            blk = vmap[t, p, r]
                            for d in range(3):
                                data[blk, d, c] += f * (w[p, d] - u[p, d])
    return energy


@njit(cache=True, nogil=True, error_model="numpy")
def elastic(q, ij, sk, srest, hidx, hk, hrest, vidx, vk, vrest, smap, hmap, vmap, grad, data, hessian, spd=True):
    """Elastic energy at ``q``; ``grad`` (n, 3) ← its gradient and, with ``hessian``, ``data``
    (nnzb, 3, 3) ← the Hessian blocks: exact, or with ``spd`` positive semi-definite (module
    doc).  Springs, hinges, then volumes, each adding onto the running sums (:func:`_spring_terms`,
    :func:`_hinge_terms`, :func:`_volume_terms`)."""
    grad[:] = 0.0
    if hessian:
        data[:] = 0.0
    x = np.empty((4, 3))
    u = np.empty((4, 3))
    w = np.empty((4, 3))
    energy = _spring_terms(q, ij, sk, srest, smap, grad, data, hessian, spd, 0.0)
    energy = _hinge_terms(q, hidx, hk, hrest, hmap, grad, data, hessian, spd, energy, x, u, w)
    return _volume_terms(q, vidx, vk, vrest, vmap, grad, data, hessian, spd, energy, x, u, w)


@njit(cache=True, nogil=True, error_model="numpy")
def elastic_energy(q, ij, sk, srest, hidx, hk, hrest, vidx, vk, vrest):
    """The elastic energy alone (the line search's evaluations)."""
    energy = 0.0
    for s in range(ij.shape[0]):
        a = ij[s, 0]
        b = ij[s, 1]
        dx = q[a, 0] - q[b, 0]; dy = q[a, 1] - q[b, 1]; dz = q[a, 2] - q[b, 2]
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        if d < 1e-15:  # as in elastic()
            continue
        C = d - srest[s]
        energy += 0.5 * sk[s] * C * C
    x = np.empty((4, 3))
    u = np.empty((4, 3))
    for e in range(hidx.shape[0]):
        for p in range(4):
            for c in range(3):
                x[p, c] = q[hidx[e, p], c]
        theta = _hinge_grad(x, u)
        if math.isnan(theta):
            continue
        C = _wrap(theta - hrest[e])
        energy += 0.5 * hk[e] * C * C
    for t in range(vidx.shape[0]):
        for p in range(4):
            for c in range(3):
                x[p, c] = q[vidx[t, p], c]
        C = _vol_grad(x, u) - vrest[t]
        energy += 0.5 * vk[t] * C * C
    return energy
