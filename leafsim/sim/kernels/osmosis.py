"""Osmosis kernels: conservative symmetric water flux (SPEC §6), CSR matvec and PCG, and the
factored direct step, serial or in two halves on two threads."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from leafsim.sim.kernels import FASTMATH


@njit(inline="always", fastmath=FASTMATH)
def _loss(w, rate, dt, w_ref):
    """Evaporation of one particle this step: rate Δt w_ref, never more than its water w."""
    l = rate * dt * w_ref
    if l > w:
        l = w
    if l < 0.0:
        l = 0.0
    return l


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def loss_rhs(M, c, w0, rate, dt, rhs, loss):
    """rhs = M c − loss with loss = min(rate Δt w0, w) so water stays ≥ 0."""
    for i in range(M.shape[0]):
        w = M[i] * c[i]
        loss[i] = _loss(w, rate[i], dt, w0[i])
        rhs[i] = w - loss[i]


@njit(cache=True, nogil=True, fastmath=False)
def pcg(indptr, indices, data, diag, b, x, tol, maxit):
    """Jacobi-preconditioned CG on an SPD CSR matrix, warm-started from x (in place).
    Returns the iteration count."""
    n = b.shape[0]
    r = np.empty(n)
    z = np.empty(n)
    p = np.empty(n)
    q = np.empty(n)
    bn = 0.0
    for i in range(n):
        bn += b[i] * b[i]
    bn = np.sqrt(bn)
    if bn == 0.0:
        x[:] = 0.0
        return 0
    for i in range(n):
        s = 0.0
        for k in range(indptr[i], indptr[i + 1]):
            s += data[k] * x[indices[k]]
        r[i] = b[i] - s
    rz = 0.0
    rn = 0.0
    for i in range(n):
        z[i] = r[i] / diag[i]
        p[i] = z[i]
        rz += r[i] * z[i]
        rn += r[i] * r[i]
    it = 0
    while it < maxit and np.sqrt(rn) > tol * bn:
        pq = 0.0
        for i in range(n):
            s = 0.0
            for k in range(indptr[i], indptr[i + 1]):
                s += data[k] * p[indices[k]]
            q[i] = s
            pq += p[i] * s
        al = rz / pq
        rn = 0.0
        rz2 = 0.0
        for i in range(n):
            x[i] += al * p[i]
            r[i] -= al * q[i]
            z[i] = r[i] / diag[i]
            rz2 += r[i] * z[i]
            rn += r[i] * r[i]
        be = rz2 / rz
        rz = rz2
        for i in range(n):
            p[i] = z[i] + be * p[i]
        it += 1
    return it


@njit(cache=True, nogil=True, fastmath=False)
def jacobi(indptr, indices, data, diag, b, x, tol, maxit):
    """Damped-free Jacobi sweeps (diagonally dominant M-matrix → converges); returns count."""
    n = b.shape[0]
    y = np.empty(n)
    bn = 0.0
    for i in range(n):
        bn += b[i] * b[i]
    bn = np.sqrt(bn) + 1e-300
    it = 0
    while it < maxit:
        rn = 0.0
        for i in range(n):
            s = 0.0
            for k in range(indptr[i], indptr[i + 1]):
                j = indices[k]
                if j != i:
                    s += data[k] * x[j]
            y[i] = (b[i] - s) / diag[i]
            d = b[i] - s - diag[i] * x[i]
            rn += d * d
        x[:] = y
        it += 1
        if np.sqrt(rn) <= tol * bn:
            break
    return it


@njit(cache=True, nogil=True, fastmath=False)
def direct_step(M, w, w0, rate, dt, Lp, Li, Lx, Up, Ui, Ux, Ud, perm_r, perm_c, y, rhs, loss):
    """One implicit osmosis step with a factored matrix, in one call: rhs = M c − loss
    (as :func:`loss_rhs`), solve Pr A Pc = L U, then w = max(c, 0) M.  L (unit diagonal) and
    U are CSR rows without their diagonal (U's is ``Ud``).  ``y`` is (n,) scratch."""
    n = M.shape[0]
    for i in range(n):
        wi = w[i]  # = M c
        l = _loss(wi, rate[i], dt, w0[i])
        loss[i] = l
        rhs[i] = wi - l
        y[perm_r[i]] = wi - l
    for i in range(n):  # L z = Pr b (forward; unit diagonal)
        s = y[i]
        for k in range(Lp[i], Lp[i + 1]):
            s -= Lx[k] * y[Li[k]]
        y[i] = s
    for i in range(n - 1, -1, -1):  # U v = z (backward)
        s = y[i]
        for k in range(Up[i], Up[i + 1]):
            s -= Ux[k] * y[Ui[k]]
        y[i] = s / Ud[i]
    for i in range(n):  # x = Pc v; round-off guard (M-matrix: exact solution ≥ 0)
        c = y[perm_c[i]]
        if c < 0.0:
            c = 0.0
        w[i] = c * M[i]


@njit(nogil=True, fastmath=False)
def _forward_part(y, Lp, Li, Lx, r0, r1, cut0, cut1, acc):
    """L's rows r0..r1 of one half (they read only that half's columns), then that half's share
    of every separator row's sum: Σ L[r, k] y[k] over the half's columns, into ``acc``."""
    for i in range(r0, r1):
        s = y[i]
        for k in range(Lp[i], Lp[i + 1]):
            s -= Lx[k] * y[Li[k]]
        y[i] = s
    for r in range(acc.shape[0]):
        s = 0.0
        for k in range(cut0[r], cut1[r]):
            s += Lx[k] * y[Li[k]]
        acc[r] = s


@njit(nogil=True, fastmath=False)
def _backward_rows(y, Up, Ui, Ux, Ud, r0, r1):
    """U's rows r1−1 down to r0 (unit-free: divided by U's diagonal ``Ud``)."""
    for i in range(r1 - 1, r0 - 1, -1):
        s = y[i]
        for k in range(Up[i], Up[i + 1]):
            s -= Ux[k] * y[Ui[k]]
        y[i] = s / Ud[i]


@njit(cache=True, nogil=True, parallel=True, fastmath=False)
def direct_step_split(M, w, w0, rate, dt, Lp, Li, Lx, Up, Ui, Ux, Ud, perm, bounds, cuts, y, rhs, loss, acc):
    """:func:`direct_step` on a matrix ordered by one level of nested dissection: two halves
    [0, b₁) and [b₁, b₂) with no entry between them, then their separator [b₂, n).  Forward,
    each half's rows and its share of the separator rows' sums run on their own thread, then
    the separator's rows; backward, the separator's rows, then each half on its own thread.
    ``perm`` maps a particle to its row (rows and columns alike); ``cuts`` (3, n − b₂) are the
    separator rows' first entry in the first half's, the second half's and the separator's
    columns; ``acc`` (2, n − b₂) is scratch.  With one numba thread the halves run in turn."""
    n = M.shape[0]
    b1 = bounds[1]
    b2 = bounds[2]
    for i in range(n):
        wi = w[i]
        l = _loss(wi, rate[i], dt, w0[i])
        loss[i] = l
        rhs[i] = wi - l
        y[perm[i]] = wi - l
    for p in prange(2):
        if p == 0:
            _forward_part(y, Lp, Li, Lx, 0, b1, cuts[0], cuts[1], acc[0])
        else:
            _forward_part(y, Lp, Li, Lx, b1, b2, cuts[1], cuts[2], acc[1])
    for i in range(b2, n):
        r = i - b2
        s = y[i] - acc[0, r] - acc[1, r]
        for k in range(cuts[2, r], Lp[i + 1]):
            s -= Lx[k] * y[Li[k]]
        y[i] = s
    _backward_rows(y, Up, Ui, Ux, Ud, b2, n)
    for p in prange(2):
        if p == 0:
            _backward_rows(y, Up, Ui, Ux, Ud, 0, b1)
        else:
            _backward_rows(y, Up, Ui, Ux, Ud, b1, b2)
    for i in range(n):
        c = y[perm[i]]
        if c < 0.0:
            c = 0.0
        w[i] = c * M[i]
