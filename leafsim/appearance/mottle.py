"""The sub-grid mottle field (``colour.mottle``): what the mesh cannot carry of senescence.

A senescing leaf turns areole by areole and cell group by cell group: under a hand lens an
autumn leaf is flecked at a fraction of a millimetre, finer than any mesh we simulate on. The
pigment state at a point of the blade is the mesh's (interpolated) state pushed a little
ahead or behind: each reaction's progress p goes to p + a·n·p(1 − p), with n a seeded field.
This module makes n: a periodic square of band-limited noise (white noise under a Gaussian
filter, so its correlation length is :data:`TEXELS_PER_LENGTH` texels), mapped by rank to an
exactly uniform distribution on [−1, 1] with mean zero.  The renderer samples it at the
particles' rest positions over ``colour.mottle_size``, so the flecks move with the tissue and
keep their size at any mesh spacing.  Imports no OpenGL.
"""

from __future__ import annotations

import numpy as np

#: texels per correlation length of the field
TEXELS_PER_LENGTH = 4.0
#: side of the periodic square, texels (a period of 256 correlation lengths: 154 mm at 0.6 mm)
FIELD_SIZE = 1024
#: seed of the field itself (each leaf samples it at its own offset)
FIELD_SEED = 20261206

_CACHE: dict = {}


def mottle_field(size: int = FIELD_SIZE, seed: int = FIELD_SEED) -> np.ndarray:
    """(size, size) float32 periodic field, uniform on [−1, 1] (rank-mapped), mean 0, with a
    Gaussian correlation of 1/e length :data:`TEXELS_PER_LENGTH` texels (before the rank map)."""
    key = (int(size), int(seed))
    hit = _CACHE.get(key)
    if hit is not None:
        return hit
    rng = np.random.default_rng(seed)
    white = rng.standard_normal((size, size))
    # a Gaussian filter of σ = ℓ/2 gives the correlation exp(−r²/ℓ²) (1/e at ℓ), periodic by the FFT
    sigma = TEXELS_PER_LENGTH / 2.0
    f = np.fft.fftfreq(size)
    gain = np.exp(-2.0 * (np.pi * sigma) ** 2 * (f[:, None] ** 2 + f[None, :] ** 2))
    smooth = np.fft.ifft2(np.fft.fft2(white) * gain).real
    rank = np.empty(size * size, np.float64)
    rank[np.argsort(smooth, axis=None, kind="stable")] = np.arange(size * size)
    field = ((rank + 0.5) / (size * size) * 2.0 - 1.0).reshape(size, size).astype(np.float32)
    field -= np.float32(field.mean(dtype=np.float64))  # exactly zero mean in float32 too
    _CACHE[key] = field
    return field


def mottle_scale(size_m: float, size: int = FIELD_SIZE) -> float:
    """Texture coordinates per metre for a correlation length of ``size_m`` metres."""
    return TEXELS_PER_LENGTH / (float(size_m) * size)


def leaf_offset(seed: int) -> np.ndarray:
    """(2,) float32 metres added to a leaf's rest positions, drawn from its seed, so leaves of
    a scene (and seeds of one species) are not flecked alike."""
    return np.random.default_rng([int(seed) & 0xFFFFFFFF, 0x6D6F74]).uniform(0.0, 0.5, 2).astype(np.float32)
