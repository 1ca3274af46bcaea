"""numba kernels: plain arrays in, arrays out (no Model/State objects)."""
