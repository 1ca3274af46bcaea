"""The heat-map colour maps of ``shaders/common.glsl`` in numpy (for legends). No OpenGL."""

from __future__ import annotations

import numpy as np

_TURBO = (np.array([[0.13572138, 4.61539260, -42.66032258, 132.13108234, -152.94239396, 59.28637943],
                    [0.09140261, 2.19418839, 4.84296658, -14.18503333, 4.27729857, 2.82956604],
                    [0.10667330, 12.64194608, -60.58204836, 110.36276771, -89.90310912, 27.34824973]]))
_VIRIDIS = np.array([[0.2777273272234177, 0.005407344544966578, 0.3340998053353061],
                     [0.1050930431085774, 1.404613529898575, 1.384590162594685],
                     [-0.3308618287255563, 0.214847559468213, 0.09509516302823659],
                     [-4.634230498983486, -5.799100973351585, -19.33244095627987],
                     [6.228269936347081, 14.17993336680509, 56.69055260068105],
                     [4.776384997670288, -13.74514537774601, -65.35303263337234],
                     [-5.435455855934631, 4.645852612178535, 26.3124352495832]])


def colormap(name: str, t) -> np.ndarray:
    """sRGB colours (..., 3) float in [0, 1] of ``t`` (clamped to [0, 1]); name turbo|viridis."""
    t = np.clip(np.asarray(t, dtype=np.float64), 0.0, 1.0)[..., None]
    if name == "turbo":
        powers = t ** np.arange(6)
        return np.clip(powers @ _TURBO.T, 0.0, 1.0)
    if name == "viridis":
        return np.clip((t ** np.arange(7)) @ _VIRIDIS, 0.0, 1.0)
    raise ValueError(f"unknown colour map {name!r}")
