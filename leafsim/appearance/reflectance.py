"""Pigments → colour: a Beer–Lambert reflectance model per particle (absorption of each pigment
per RGB band over pigment-free tissue, plus the cuticle's surface reflection), the photo's own
colour fitted as the young state, and the sRGB curve.  The pigment kinetics are
:mod:`leafsim.sim.pigments`."""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np
from numba import njit

from leafsim.base.cache import configure_numba_cache
from leafsim.sim.pigments import FASTMATH_FLAGS, ONE32, ZERO32, PigmentState, exp_neg_any

configure_numba_cache()  # before the first @njit(cache=True): the cache folder keyed to the kernel sources


#: Absorption coefficients k_p (rows: chlorophyll, carotenoid, anthocyanin, browning, necrosis; cols: R, G, B).
ABSORPTION = np.array(
    [
        [3.20, 1.15, 3.00],  # chlorophyll
        [0.02, 0.45, 3.50],  # carotenoid
        [0.25, 2.60, 0.50],  # anthocyanin
        [1.15, 1.85, 3.30],  # browning
        [2.40, 2.40, 2.60],  # necrosis (pheophytins and oxidised phenolics of tissue that died green)
    ],
    dtype=np.float32,
)


#: Reflectance of pigment-free leaf tissue (linear RGB).
BASE_REFLECTANCE = np.array([0.82, 0.80, 0.72], dtype=np.float32)


#: Unabsorbed first-surface (cuticle) reflectance added to every band.
SURFACE_REFLECTANCE = np.float32(0.03)


@njit(cache=True, fastmath=FASTMATH_FLAGS, nogil=True, error_model="numpy")
def _rgb_kernel(C, K, A, B, N, vein, s_chl, s_car, s_ant, s_brn, s_nec, pallor, vbrown, absorb, base, surface, out):  # pragma: no cover
    """out[i] = surface + base·exp(−Σ c_p k_p) for every particle (vectorised, float32)."""
    k00, k01, k02 = absorb[0, 0], absorb[0, 1], absorb[0, 2]
    k10, k11, k12 = absorb[1, 0], absorb[1, 1], absorb[1, 2]
    k20, k21, k22 = absorb[2, 0], absorb[2, 1], absorb[2, 2]
    k30, k31, k32 = absorb[3, 0], absorb[3, 1], absorb[3, 2]
    k40, k41, k42 = absorb[4, 0], absorb[4, 1], absorb[4, 2]
    b0, b1, b2 = base[0], base[1], base[2]
    n = C.shape[0]
    planar = np.empty((3, n), np.float32)
    o0, o1, o2 = planar[0], planar[1], planar[2]
    for i in range(n):
        tissue = ONE32 - pallor * vein[i]
        c_chl = s_chl * tissue * C[i]
        c_car = s_car * K[i]
        c_ant = s_ant * A[i]
        c_brn = s_brn * B[i] * (ONE32 - vbrown * vein[i])
        c_nec = s_nec * tissue * N[i]
        x0 = c_chl * k00 + c_car * k10 + c_ant * k20 + c_brn * k30 + c_nec * k40
        x1 = c_chl * k01 + c_car * k11 + c_ant * k21 + c_brn * k31 + c_nec * k41
        x2 = c_chl * k02 + c_car * k12 + c_ant * k22 + c_brn * k32 + c_nec * k42
        o0[i] = surface + b0 * exp_neg_any(max(x0, ZERO32))
        o1[i] = surface + b1 * exp_neg_any(max(x1, ZERO32))
        o2[i] = surface + b2 * exp_neg_any(max(x2, ZERO32))
    for i in range(n):  # interleave separately: strided stores would stop the loop above vectorising
        out[i, 0] = o0[i]
        out[i, 1] = o1[i]
        out[i, 2] = o2[i]


def pigments_to_rgb(pig: PigmentState, params: Mapping[str, Any], contents: tuple | None = None,
                    vein: np.ndarray | None = None) -> np.ndarray:
    """(n, 3) float32 linear-RGB reflectance ``surface + base·exp(−Σ c_p k_p)`` (module docstring).

    Concentrations are ``c_chl = colour.chlorophyll·leaf_chl·(1 − vein_pallor·m̂)·C``,
    ``c_car = colour.carotenoid·leaf_car·K``, ``c_ant = colour.anthocyanin·leaf_ant·A``,
    ``c_brn = colour.brown_level·(1 − colour.vein_browning·m̂)·B``, ``c_nec = colour.necrosis·(chlorophyll content)·(1 − vein_pallor·m̂)·N``;
    all palette values act live.  ``contents`` = (chlorophyll, carotenoid, extra surface
    reflectance) replaces the palette's contents and the per-leaf factors (a leaf whose
    young colour was fitted to its photo, :func:`fit_photo_contents`).  ``vein`` (n,) float32
    replaces the tissue's m̂ (``pig.vein``): ones give the colour of pure vein tissue, which the
    drawn veins show.
    """
    leaf = pig.leaf
    out = np.empty((pig.n, 3), np.float32)
    if contents is None:
        chl = float(params["colour.chlorophyll"]) * leaf[0]
        car = float(params["colour.carotenoid"]) * leaf[1]
        surface = SURFACE_REFLECTANCE
    else:
        chl, car = float(contents[0]), float(contents[1])
        surface = np.float32(SURFACE_REFLECTANCE + float(contents[2]))
    _rgb_kernel(pig.chlorophyll, pig.carotenoid, pig.anthocyanin, pig.browning, pig.necrosis,
                pig.vein if vein is None else np.ascontiguousarray(vein, np.float32),
                np.float32(chl), np.float32(car), np.float32(float(params["colour.anthocyanin"]) * leaf[2]),
                np.float32(params["colour.brown_level"]),
                np.float32(float(params["colour.necrosis"]) * max(chl, 1.0)),
                np.float32(params["colour.vein_pallor"]), np.float32(params["colour.vein_browning"]),
                ABSORPTION, BASE_REFLECTANCE, surface, out)
    return out


#: columns of :func:`mottle_pigments`: the five pigments' concentrations c_p (as
#: :func:`pigments_to_rgb` weights them), the four reactions' states in [0, 1] (chlorophyll and
#: carotenoids left, browning and necrosis made), and the surface reflectance
MOTTLE_COLUMNS = ("c_chl", "c_car", "c_ant", "c_brn", "C", "K", "B", "N", "c_nec", "surface")


@njit(cache=True, fastmath=FASTMATH_FLAGS, nogil=True, error_model="numpy")
def _mottle_kernel(C, K, A, B, N, vein, s_chl, s_car, s_ant, s_brn, s_nec, pallor, vbrown, surface, out):  # pragma: no cover
    """out[i] = (c_chl, c_car, c_ant, c_brn, C, K, B, N clamped to [0, 1], c_nec, surface)."""
    for i in range(C.shape[0]):
        tissue = ONE32 - pallor * vein[i]
        out[i, 0] = s_chl * tissue * C[i]
        out[i, 1] = s_car * K[i]
        out[i, 2] = s_ant * A[i]
        out[i, 3] = s_brn * B[i] * (ONE32 - vbrown * vein[i])
        out[i, 4] = min(max(C[i], ZERO32), ONE32)
        out[i, 5] = min(max(K[i], ZERO32), ONE32)
        out[i, 6] = min(max(B[i], ZERO32), ONE32)
        out[i, 7] = min(max(N[i], ZERO32), ONE32)
        out[i, 8] = s_nec * tissue * N[i]
        out[i, 9] = surface


def mottle_pigments(pig: PigmentState, params: Mapping[str, Any], contents: tuple | None = None) -> np.ndarray:
    """(n, 10) float32 for the renderer's sub-grid mottle (``colour.mottle``; columns
    :data:`MOTTLE_COLUMNS`), with the concentrations of :func:`pigments_to_rgb` (same
    ``contents``).  The renderer interpolates them across a triangle as the pigments themselves
    and, per pixel, moves each reaction's progress p (chlorophyll and carotenoids lost, browning,
    necrosis) to p + a·n·p(1 − p) for the field n at that point: every pigment's amount changes by
    a·n·(1 − state)·c_p (its state C, K, B or N; lost pigments with the opposite sign), which
    changes the optical depth x = Σ c_p k_p by n·g; the albedo is multiplied by
    ``(surface + base·exp(−(x + n·g))) / (surface + base·exp(−x))``
    (:func:`mottle_ratio` is that formula on the CPU).  With n in [−1, 1], zero mean, and
    a ≤ 1 every local progress stays in [0, 1] and the pigment amounts keep their mean; fresh
    (p = 0) and finished (p = 1) tissue is uniform."""
    leaf = pig.leaf
    if contents is None:
        chl = float(params["colour.chlorophyll"]) * leaf[0]
        car = float(params["colour.carotenoid"]) * leaf[1]
        surface = float(SURFACE_REFLECTANCE)
    else:
        chl, car = float(contents[0]), float(contents[1])
        surface = float(SURFACE_REFLECTANCE) + float(contents[2])
    out = np.empty((pig.n, len(MOTTLE_COLUMNS)), np.float32)
    _mottle_kernel(pig.chlorophyll, pig.carotenoid, pig.anthocyanin, pig.browning, pig.necrosis, pig.vein,
                   np.float32(chl), np.float32(car), np.float32(float(params["colour.anthocyanin"]) * leaf[2]),
                   np.float32(params["colour.brown_level"]), np.float32(float(params["colour.necrosis"]) * max(chl, 1.0)),
                   np.float32(params["colour.vein_pallor"]), np.float32(params["colour.vein_browning"]),
                   np.float32(surface), out)
    return out


def mottle_ratio(m: np.ndarray, n, amount: float) -> np.ndarray:
    """(k, 3) the factor the renderer multiplies the albedo by at field value(s) ``n`` for
    :func:`mottle_pigments` rows ``m`` (k, 10) and ``colour.mottle`` ``amount`` (the fragment
    shader's ``mottle_ratio``, in float64)."""
    m = np.asarray(m, np.float64)
    k = ABSORPTION.astype(np.float64)
    conc = m[:, [0, 1, 2, 3, 8]]
    x = np.maximum(conc @ k, 0.0)
    d = amount * np.stack([-(1 - m[:, 4]) * m[:, 0], -(1 - m[:, 5]) * m[:, 1], np.zeros(len(m)),
                           (1 - m[:, 6]) * m[:, 3], (1 - m[:, 7]) * m[:, 8]], 1)
    g = d @ k
    n = np.asarray(n, np.float64).reshape(-1, 1)
    b = BASE_REFLECTANCE.astype(np.float64)
    return (m[:, 9:10] + b * np.exp(-np.maximum(x + n * g, 0.0))) / np.maximum(m[:, 9:10] + b * np.exp(-x), 1e-4)


def fit_photo_contents(young: np.ndarray, pig0: PigmentState, params: Mapping[str, Any],
                       weights: np.ndarray | None = None, select: np.ndarray | None = None) -> tuple[float, float, float]:
    """Pigment contents that make the model's young leaf the photo's colour: (chlorophyll,
    carotenoid, extra surface reflectance — hairs and wax that scatter white light, the
    grey-green of a vine's underside; down to −0.03, no surface reflection at all).

    Least squares in log reflectance against the mean photo colour of the particles
    ``select`` (weights: their areas; ``young``: the photo's linear RGB at each particle of
    the young state ``pig0``).  A dark green photo is a leaf with much chlorophyll (so it
    turns bright yellow when the chlorophyll goes), a pale one with little.  The carotenoids
    are the species' (colour.carotenoid × the leaf's factor: they set its autumn yellow, and
    a camera's white balance in the blue should not become pigment); what the contents cannot
    explain stays in the photo's own colour (the young colour is the photo's whatever the
    fit).  Bounds: chlorophyll 0.02–4, surface −0.03–0.4."""
    from scipy.optimize import least_squares

    sel = np.ones(pig0.n, bool) if select is None else np.asarray(select, bool)
    wt = np.ones(pig0.n) if weights is None else np.asarray(weights, float)
    wt = wt[sel] / max(float(wt[sel].sum()), 1e-300)
    target = np.log(np.maximum(wt @ np.asarray(young, float)[sel], 1e-4))
    car = float(params["colour.carotenoid"]) * float(pig0.leaf[1])

    def contents(x):
        return x[0], car, x[1]

    def resid(x):
        rgb = pigments_to_rgb(pig0, params, contents(x)).astype(np.float64)[sel]
        return np.log(np.maximum(wt @ rgb, 1e-6)) - target

    x0 = (float(params["colour.chlorophyll"]), 0.0)
    lo, hi = [0.02, -float(SURFACE_REFLECTANCE)], [4.0, 0.4]
    r = least_squares(resid, x0, bounds=(lo, hi), x_scale=(1.0, 0.05), diff_step=1e-3)
    return tuple(float(v) for v in contents(r.x))


def tint_for_texture(pig: PigmentState, pig0: PigmentState, params: Mapping[str, Any]) -> np.ndarray:
    """(n, 3) float32 multiplicative tint ``rgb(pig) / rgb(pig0)`` for a photo used as albedo.

    Multiply the young leaf's photo (linear RGB, sampled at the particle's rest position) by
    the tint to shift it by the pigment state while keeping its detail.  The tint is 1 where
    nothing changed; values above 1 (a green photo turning yellow brightens red ~10×) may
    need clamping after the multiply.
    """
    if pig.n != pig0.n:
        raise ValueError(f"tint_for_texture: {pig.n} particles now but {pig0.n} in the young state")
    return (pigments_to_rgb(pig, params) / pigments_to_rgb(pig0, params)).astype(np.float32)


def linear_to_srgb(rgb: np.ndarray) -> np.ndarray:
    """Encode linear RGB in [0, 1] with the sRGB transfer curve (same shape, float32)."""
    x = np.clip(np.asarray(rgb, dtype=np.float32), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055).astype(np.float32)
