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
#: a one-way crinkle's crests are this many times longer than they are apart (tension-field
#: wrinkles run long across the compression; the field is read stretched this much along them)
CRINKLE_CREST = 3.0
#: the oriented fields: compression along k·45°, k = 0..3, each read at its own offset
CRINKLE_ORIENTATIONS = 4
CRINKLE_ORIENTED_OFFSETS = ((0.1287, 0.8431), (0.7052, 0.2219), (0.5546, 0.9378), (0.8913, 0.4467))


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


def crinkle_height_gradient(S: np.ndarray, rest: np.ndarray, scale: float, fetch) -> np.ndarray:
    """(k, 2) the crinkle's height gradient dh/d(rest) at rest positions ``rest`` (k, 2) for
    slope tensors ``S`` (k, 3: xx, xy, yy, rad²; :func:`leafsim.sim.crinkle.crinkle_slopes`), as
    the blade shader computes it (shaders/blade.frag; the bake's normal map uses this).
    ``fetch(u, v)`` returns the field's gradient (:func:`crinkle_gradient`) at texture
    coordinates, (k, 2), divided by its RMS (:func:`crinkle_gradient_rms`).

    The pattern mixes the isotropic field with fields read stretched :data:`CRINKLE_CREST` times
    along the crests (the two of the :data:`CRINKLE_ORIENTATIONS` fixed orientations nearest the
    tensor's larger eigenvector d, weights cos 2δ and sin 2δ with δ d's angle past the lower of
    the two, so their variance is kept), the oriented share growing with how one-sided the compression is,
    a = (λ₁ − λ₂)/(λ₁ + λ₂).  The mix's covariance Σ over (d, t ⊥ d) is known in closed form
    (unit-RMS, uncorrelated components; the fields independent); its components are mapped by
    diag(√λ₁, √λ₂) Σ^(−1/2), so the drawn gradient's covariance is S itself: along any rest
    direction u the mean squared slope is uᵀSu."""
    S = np.asarray(S, np.float64)
    rest = np.asarray(rest, np.float64)
    half = 0.5 * (S[:, 0] + S[:, 2])
    dev = np.sqrt(0.25 * (S[:, 0] - S[:, 2]) ** 2 + S[:, 1] ** 2)
    l1, l2 = np.maximum(half + dev, 0.0), np.maximum(half - dev, 0.0)
    ang = 0.5 * np.arctan2(2.0 * S[:, 1], S[:, 0] - S[:, 2])
    d = np.stack([np.cos(ang), np.sin(ang)], 1)
    t = np.stack([-d[:, 1], d[:, 0]], 1)
    tot = l1 + l2
    a = np.clip(np.where(tot > 0.0, (l1 - l2) / np.where(tot > 0.0, tot, 1.0), 0.0), 0.0, 1.0)
    g_iso = fetch(rest[:, 0] * scale + CRINKLE_OFFSET[0], rest[:, 1] * scale + CRINKLE_OFFSET[1])
    step = np.pi / CRINKLE_ORIENTATIONS
    x = np.mod(ang, np.pi) / step
    ka = np.floor(x).astype(np.int64) % CRINKLE_ORIENTATIONS
    f = (x - np.floor(x))
    rho = CRINKLE_CREST
    g_or = np.zeros_like(rest)
    Ed, Et, Edt = 1.0 - a, 1.0 - a, np.zeros_like(a)
    for which, w, delta in ((ka, np.cos(0.5 * np.pi * f), f * step),
                            ((ka + 1) % CRINKLE_ORIENTATIONS, np.sin(0.5 * np.pi * f), (f - 1.0) * step)):
        psi = which * step
        dk = np.stack([np.cos(psi), np.sin(psi)], 1)
        tk = np.stack([-dk[:, 1], dk[:, 0]], 1)
        off = np.asarray(CRINKLE_ORIENTED_OFFSETS, np.float64)[which]
        u = np.einsum("ij,ij->i", rest, dk) * scale + off[:, 0]
        v = np.einsum("ij,ij->i", rest, tk) / rho * scale + off[:, 1]
        g = fetch(u, v)
        g_or += w[:, None] * (g[:, 0:1] * dk + g[:, 1:2] / rho * tk)
        c, s_ = np.cos(delta), np.sin(delta)
        Ed = Ed + a * w * w * (c * c + s_ * s_ / rho ** 2)
        Et = Et + a * w * w * (s_ * s_ + c * c / rho ** 2)
        Edt = Edt + a * w * w * s_ * c * (1.0 / rho ** 2 - 1.0)
    G = np.sqrt(1.0 - a)[:, None] * g_iso + np.sqrt(a)[:, None] * g_or
    xd, xt = np.einsum("ij,ij->i", G, d), np.einsum("ij,ij->i", G, t)
    # Σ^(−1/2) of [[Ed, Edt], [Edt, Et]]: √Σ = (Σ + r I) / n, r = √det, n = √(tr + 2r)
    r = np.sqrt(np.maximum(Ed * Et - Edt * Edt, 0.0))
    n = np.sqrt(Ed + Et + 2.0 * r)
    m11, m12, m22 = Ed + r, Edt, Et + r
    det = m11 * m22 - m12 * m12
    yd = n * (m22 * xd - m12 * xt) / det
    yt = n * (-m12 * xd + m11 * xt) / det
    return (np.sqrt(l1) * yd)[:, None] * d + (np.sqrt(l2) * yt)[:, None] * t
