"""A photo made fit to be a texture (OpenGL-free: the renderer and the exports both use it)."""

from __future__ import annotations

import numpy as np

#: texels of the leaf this close to its mask's edge [px] mix the leaf with the photo's background
#: (a pale or paper-coloured fringe): they take the colour of the nearest texel further in
FRINGE_PX = 2.5


def clean_texture(rgba: np.ndarray) -> np.ndarray:
    """(H, W, 4) uint8: ``rgba`` with the nearest clean leaf texel's colour copied into the
    masked-out area (no dark or paper-coloured border when a renderer filters or mipmaps across
    the mask) and over the leaf's outermost ``FRINGE_PX`` (no pale or background-tinted fringe).
    The mask (alpha) is kept. A leaf structure thinner than about twice ``FRINGE_PX`` (a tooth's
    very tip) takes the colour of the blade behind it."""
    from scipy.ndimage import distance_transform_edt

    out = np.array(rgba, dtype=np.uint8, copy=True)
    outside = out[:, :, 3] < 128
    if outside.any() and not outside.all():
        clean = distance_transform_edt(~outside) >= FRINGE_PX
        source = clean if clean.any() else ~outside
        _, (iy, ix) = distance_transform_edt(~source, return_indices=True)
        out[:, :, :3] = out[iy, ix, :3]
    return out
