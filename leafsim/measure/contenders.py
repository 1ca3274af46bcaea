"""Parallel spring sweeps that ``leafsim bench`` races against the production (serial) one;
not used by the simulation.  Both call the production :func:`~leafsim.sim.kernels.scalar.spring_pass`
on sub-ranges, so they differ from it only in how the work is split over threads:

* :func:`coloured_passes` — the former design: every colour split over the threads, one
  fork/join per colour per pass (≈ 20 colours × passes);
* :func:`block_passes` — a domain split: the springs inside each of two halves of the blade
  (``block_order``) swept by one thread each, one fork/join per pass, then the springs across
  the cut on one thread.

(The bench's float32 *ceiling* is the production kernel itself compiled for float32 positions,
int32 indices and float32 records: numba specialises :func:`spring_pass` per dtype.)"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from leafsim.base.cache import configure_numba_cache
from leafsim.sim.kernels.scalar import spring_pass

configure_numba_cache()  # before the first @njit(cache=True): the cache folder keyed to the kernel sources


@njit(cache=True, nogil=True, parallel=True)
def coloured_passes(q, ij, rec, lam, cs, nthreads, npass):
    """``npass`` sweeps, colour after colour, each colour cut into ``nthreads`` chunks run in
    parallel (no two springs of one colour share a particle)."""
    big = np.zeros(nthreads)
    for _ in range(npass):
        big[:] = 0.0
        for c in range(cs.shape[0] - 1):
            lo = cs[c]
            n = cs[c + 1] - lo
            for k in prange(nthreads):
                ch = spring_pass(q, ij, rec, lam, lo + n * k // nthreads, lo + n * (k + 1) // nthreads)
                if ch > big[k]:
                    big[k] = ch
    return big.max()


@njit(cache=True, nogil=True, parallel=True)
def block_passes(q, ij, rec, lam, bs, npass):
    """``npass`` sweeps over springs stored as [inside block 0 | inside block 1 | across]
    (``bs`` = their 4 offsets): the two blocks in parallel, then the cut."""
    big = np.zeros(2)
    cut = 0.0
    for _ in range(npass):
        for k in prange(2):
            big[k] = spring_pass(q, ij, rec, lam, bs[k], bs[k + 1])
        cut = spring_pass(q, ij, rec, lam, bs[2], bs[3])
    return max(big.max(), cut)


def block_order(ij: np.ndarray, rest: np.ndarray, axis: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Permutation of springs ``ij`` (in their sweep order) into [inside the lower half along
    ``axis`` of the rest positions | inside the upper half | across the cut], each part keeping
    its order, and the 4 offsets."""
    side = rest[:, axis] > np.median(rest[:, axis])
    a, b = side[ij[:, 0]], side[ij[:, 1]]
    parts = [np.flatnonzero(~a & ~b), np.flatnonzero(a & b), np.flatnonzero(a != b)]
    bs = np.cumsum([0] + [len(p) for p in parts]).astype(np.int64)
    return np.concatenate(parts).astype(np.int64), bs
