"""The species photo as a texture: RGB with the traced blade as alpha (holes transparent, a
petiole lying on the blade inpainted), downscaled to the image limit."""

from __future__ import annotations

import numpy as np

from leafsim.config.params import ParamSet
from leafsim.config.species import Species
from leafsim.pipeline import species_trace


def load_photo_rgba(path, max_pixels: int | None = None, traced=None) -> np.ndarray:
    """The species photo as (H, W, 4) uint8 RGB with alpha = leaf mask (textures, the GUI's
    photo panel), downscaled to at most ``max_pixels`` (default ``limits.image_pixels``;
    texture coordinates are relative, so any size fits).  With ``traced`` (its
    :class:`~leafsim.outline.trace.TracedOutline`) the alpha is the traced blade — holes (closed
    sinuses) transparent, a petiole cut off — and a petiole lying on the blade is inpainted
    from the blade around it (it is no blade colour).  Raises LeafsimError naming the file
    when it cannot be read."""
    import cv2

    from leafsim.config.params import PARAMS
    from leafsim.outline.image import load_image, working_image
    from leafsim.outline.segment import segment_leaf

    if max_pixels is None:
        max_pixels = PARAMS["limits.image_pixels"].default
    img, _ = working_image(load_image(path), int(max_pixels))
    rgb = cv2.cvtColor(np.ascontiguousarray(img[:, :, :3]), cv2.COLOR_BGR2RGB)
    if traced is None:
        return np.ascontiguousarray(np.dstack([rgb, segment_leaf(img, str(path))]))
    size = (img.shape[1], img.shape[0])
    fit = lambda m: cv2.resize(m, size, interpolation=cv2.INTER_NEAREST)  # noqa: E731  (working → texture size)
    mask = fit(traced.mask)
    if traced.hole_mask is not None:
        mask = cv2.bitwise_and(mask, cv2.bitwise_not(fit(traced.hole_mask)))
    if traced.petiole_mask is not None:
        band = cv2.dilate(fit(traced.petiole_mask), np.ones((5, 5), np.uint8))
        rgb = cv2.inpaint(rgb, band, max(3.0, 0.01 * max(size)), cv2.INPAINT_TELEA)
    return np.ascontiguousarray(np.dstack([rgb, mask]))


def species_photo_rgba(sp: Species, params: ParamSet | None = None) -> np.ndarray:
    """The species photo as a texture: :func:`load_photo_rgba` with its traced blade."""
    params = params if params is not None else sp.params
    return load_photo_rgba(sp.image, params["limits.image_pixels"], species_trace(sp, params))
