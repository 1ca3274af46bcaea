"""The sub-grid mottle field (``colour.mottle``): what the mesh cannot carry of senescence.

A senescing leaf turns areole by areole and cell group by cell group: under a hand lens an
autumn leaf is flecked at a fraction of a millimetre, finer than any mesh we simulate on. The
pigment state at a point of the blade is the mesh's (interpolated) state pushed a little
ahead or behind: each reaction's progress p goes to p + a·n·p(1 − p), with n a seeded field.
This module makes n: a periodic square of band-limited noise (white noise under a Gaussian
filter, so its correlation length is :data:`TEXELS_PER_LENGTH` texels), mapped by rank to an
exactly uniform distribution over 256 levels in (−1, 1), symmetric, with mean exactly zero (the
renderer samples it as an 8-bit texture, a quarter of a float one's memory, drawn within a few
per cent of a float one's time).  The renderer samples it at the
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


def mottle_levels(size: int = FIELD_SIZE, seed: int = FIELD_SEED) -> np.ndarray:
    """(size, size) uint8 periodic field of levels k, each level on the same number of texels
    (size² a multiple of 256), with a Gaussian correlation of 1/e length
    :data:`TEXELS_PER_LENGTH` texels (before the rank map); the field's value is
    n = (2k + 1)/256 − 1 (:func:`mottle_field`)."""
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
    if (size * size) % 256:
        raise ValueError(f"mottle_levels: size² = {size * size} is not a multiple of 256")
    rank = np.empty(size * size, np.int64)
    rank[np.argsort(smooth, axis=None, kind="stable")] = np.arange(size * size)
    levels = (rank * 256 // (size * size)).astype(np.uint8).reshape(size, size)
    _CACHE[key] = levels
    return levels


def mottle_field(size: int = FIELD_SIZE, seed: int = FIELD_SEED) -> np.ndarray:
    """(size, size) float32: the field's values n = (2k + 1)/256 − 1 of :func:`mottle_levels`,
    uniform over 256 levels in [−255/256, 255/256], mean exactly 0."""
    return ((2.0 * mottle_levels(size, seed).astype(np.float32) + 1.0) / 256.0 - 1.0).astype(np.float32)


def mottle_scale(size_m: float, size: int = FIELD_SIZE) -> float:
    """Texture coordinates per metre for a correlation length of ``size_m`` metres."""
    return TEXELS_PER_LENGTH / (float(size_m) * size)


def leaf_offset(seed: int) -> np.ndarray:
    """(2,) float32 metres added to a leaf's rest positions, drawn from its seed, so leaves of
    a scene (and seeds of one species) are not flecked alike."""
    return np.random.default_rng([int(seed) & 0xFFFFFFFF, 0x6D6F74]).uniform(0.0, 0.5, 2).astype(np.float32)


#: where the crinkle samples the field, in texture coordinates added to the mottle's: far from
#: the mottle's own samples (the field's period is 256 correlation lengths), so the two are
#: not alike where their scales meet
CRINKLE_OFFSET = (0.3719, 0.6113)


def crinkle_gradient(size: int = FIELD_SIZE, seed: int = FIELD_SEED) -> np.ndarray:
    """(size, size, 2) float32: the field's central difference ½ (n(i + 1) − n(i − 1)) along x
    and y at every texel, periodic (:func:`mottle_field`'s values).  The crinkle reads its
    gradient from this, one bilinear fetch per pixel, instead of four fetches of the field."""
    key = ("gradfield", int(size), int(seed))
    hit = _CACHE.get(key)
    if hit is None:
        f = mottle_field(size, seed).astype(np.float64)
        gx = 0.5 * (np.roll(f, -1, 1) - np.roll(f, 1, 1))
        gy = 0.5 * (np.roll(f, -1, 0) - np.roll(f, 1, 0))
        hit = _CACHE[key] = np.ascontiguousarray(np.stack([gx, gy], 2), dtype=np.float32)
    return hit


def crinkle_gradient_rms(size: int = FIELD_SIZE, seed: int = FIELD_SEED) -> float:
    """RMS of one component of :func:`crinkle_gradient` where the fragment shader and the bake
    read it: bilinearly interpolated at any point, averaged over sub-texel offsets on a
    quarter-texel grid (at texel centres alone it reads 4 % high: 0.199 against 0.191).  The
    crinkle divides its gradient by this, so each direction's slope has the RMS the vertex asks
    for (``render.crinkle``, :mod:`leafsim.sim.crinkle`).  About 0.3 s, once per process."""
    key = ("grad", int(size), int(seed))
    hit = _CACHE.get(key)
    if hit is None:
        g = crinkle_gradient(size, seed).astype(np.float64)
        g1, g2 = np.roll(g, -1, 1), np.roll(g, -1, 0)
        g12 = np.roll(g2, -1, 1)
        total = 0.0
        offsets = (0.0, 0.25, 0.5, 0.75)
        for ox in offsets:
            for oy in offsets:
                b = (1 - ox) * (1 - oy) * g + ox * (1 - oy) * g1 + (1 - ox) * oy * g2 + ox * oy * g12
                total += 0.5 * (np.mean(b[..., 0] ** 2) + np.mean(b[..., 1] ** 2))
        hit = _CACHE[key] = float(np.sqrt(total / len(offsets) ** 2))
    return hit
