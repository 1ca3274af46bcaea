"""A photo made fit to be a texture (OpenGL-free: the renderer and the exports both use it)."""

from __future__ import annotations

import numpy as np

#: texels of the leaf this close to its mask's edge [px] mix the leaf with the photo's background
#: (a pale or paper-coloured fringe): they take the colour of the nearest texel further in
FRINGE_PX = 2.5
#: ... and further in where the photo's blur carries the background's lightness deeper (up to
#: this far [px]): going in by 1 px bands, the fringe ends at the first band whose mean lightness
#: is within FRINGE_SETTLED of the edge's step (or 2 levels) of the blade's 10-20 px in, or
#: changes from the band before by less than FRINGE_FLAT of that step (the blur has decayed)
MAX_FRINGE_PX = 8
FRINGE_SETTLED, FRINGE_FLAT = 0.1, 0.05


def fringe_width(rgba: np.ndarray, dist: np.ndarray | None = None) -> float:
    """How far in from the mask's edge the photo's leaf is tinted by its background [px]: at
    least ``FRINGE_PX``, at most ``MAX_FRINGE_PX`` (module constants).  ``dist``: the distance of
    every texel to the masked-out area, when already computed."""
    from scipy.ndimage import distance_transform_edt

    outside = np.asarray(rgba)[:, :, 3] < 128
    if not outside.any() or outside.all():
        return FRINGE_PX  # no margin in the picture to measure
    d = distance_transform_edt(~outside) if dist is None else dist
    lum = np.asarray(rgba)[:, :, :3].astype(np.float64) @ np.array([0.2126, 0.7152, 0.0722])
    ref_band, edge_band = (d > 10) & (d <= 20), (d > 0) & (d <= 1)
    if ref_band.sum() < 100 or not edge_band.any():
        return FRINGE_PX
    ref = float(np.median(lum[ref_band]))
    step = abs(float(lum[edge_band].mean()) - ref)
    width = FRINGE_PX
    before = None
    for k in range(int(FRINGE_PX) - 1, MAX_FRINGE_PX):
        band = (d > k) & (d <= k + 1)
        if not band.any():
            break
        mean = float(lum[band].mean())
        if before is not None:
            if abs(mean - ref) <= max(FRINGE_SETTLED * step, 2.0) or abs(before - mean) <= FRINGE_FLAT * step:
                break
            width = float(k + 1)
        before = mean
    return width


def clean_texture(rgba: np.ndarray) -> np.ndarray:
    """(H, W, 4) uint8: ``rgba`` with the nearest clean leaf texel's colour copied into the
    masked-out area (no dark or paper-coloured border when a renderer filters or mipmaps across
    the mask) and over the leaf's outermost :func:`fringe_width` (no pale or background-tinted
    fringe: 2.5 px on the oak and hornbeam photos, 5-6 px on the aspen and grapevine scans,
    whose blurred margins lit a lime or grey rim round the whole leaf).  The mask (alpha) is
    kept. A leaf structure thinner than about twice the fringe (a tooth's very tip) takes the
    colour of the blade behind it."""
    from scipy.ndimage import distance_transform_edt

    out = np.array(rgba, dtype=np.uint8, copy=True)
    outside = out[:, :, 3] < 128
    if outside.any() and not outside.all():
        d = distance_transform_edt(~outside)
        clean = d > fringe_width(out, d)  # a band (k, k + 1] found tinted is cleaned whole
        source = clean if clean.any() else ~outside
        _, (iy, ix) = distance_transform_edt(~source, return_indices=True)
        out[:, :, :3] = out[iy, ix, :3]
    return out
