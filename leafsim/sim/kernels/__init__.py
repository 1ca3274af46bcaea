"""numba kernels: plain arrays in, arrays out (no Model/State objects).

:data:`FASTMATH` is the fast-math subset every kernel that writes simulation state compiles
with: no NaN/Inf and no signed-zero bookkeeping, but neither reassociation nor FMA contraction
nor approximate reciprocals.  Those three let LLVM round differently depending on what it
inlined, and what it inlines depends on whether a callee was compiled in this process or
loaded from numba's cache: a run on a fresh machine (everything compiled) and the same run
resumed later (everything cached) then differed in the 17th digit from the 6th frame on,
which broke bit-identical resume (measured on a clean clone; tests/test_interrupt.py)."""

from leafsim.base.cache import configure_numba_cache

configure_numba_cache()  # before any kernel module below is decorated

FASTMATH = {"nnan", "ninf", "nsz"}  # (numba wants a set; never mutated)
