"""The drying path's prolongation (:mod:`leafsim.sim.path`): the coarse mesh's positions and
velocities carried to the leaf's own mesh by one sparse matrix, both in one pass."""

from __future__ import annotations

from numba import njit

from leafsim.sim.kernels import FASTMATH


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def prolong_pair(indptr, indices, data, a, b, out_a, out_b):
    """out_a = T a and out_b = T b for the CSR matrix T = (data, indices, indptr) and (n, 3)
    arrays a, b: each row summed in the matrix's order, as scipy's product does (the same
    result to the last bit), in one pass over the matrix instead of two."""
    for i in range(indptr.shape[0] - 1):
        a0 = 0.0
        a1 = 0.0
        a2 = 0.0
        b0 = 0.0
        b1 = 0.0
        b2 = 0.0
        for jj in range(indptr[i], indptr[i + 1]):
            j = indices[jj]
            w = data[jj]
            a0 += w * a[j, 0]
            a1 += w * a[j, 1]
            a2 += w * a[j, 2]
            b0 += w * b[j, 0]
            b1 += w * b[j, 1]
            b2 += w * b[j, 2]
        out_a[i, 0] = a0
        out_a[i, 1] = a1
        out_a[i, 2] = a2
        out_b[i, 0] = b0
        out_b[i, 1] = b1
        out_b[i, 2] = b2
