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
    if img.shape[2] < 4 or bool((img[:, :, 3] == 255).all()):  # a cut-out photo has no background to show
        mask[background_specks(rgb, mask > 0)] = 0
    if traced.petiole_mask is not None:
        band = cv2.dilate(fit(traced.petiole_mask), np.ones((5, 5), np.uint8))
        smooth = cv2.inpaint(rgb, band, max(3.0, 0.01 * max(size)), cv2.INPAINT_TELEA)
        k = size[0] / float(traced.image_size[0])  # full-photo pixels → texture pixels
        rgb = mirrored_detail(rgb, smooth, band > 0, mask > 0, k * np.asarray(traced.base_px, float),
                              k * np.asarray(traced.apex_px, float))
    return np.ascontiguousarray(np.dstack([rgb, mask]))


#: background specks: within this share of the photo's larger side of the blade's edge ...
SPECK_REACH = 0.015
#: ... within this much L* of the background's lightness and this chroma distance of its (a, b)
SPECK_L = 15.0
SPECK_CHROMA = 10.0
#: ... and grown by this many pixels within the blade (their anti-aliased rims, a grid line)
SPECK_GROW = 2
#: only on a light background (paper: L* 88-100 on the shipped scans), lighter than any leaf tissue
SPECK_MIN_L = 70.0


def background_specks(rgb: np.ndarray, blade: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels of the ``blade`` mask that show the background — openings too thin or
    small for the tracer to keep as holes, such as the wedge where a closed sinus narrows
    between two overlapping lobes (grapevine: the paper in 7 specks of up to 78 px): the
    background's colour (the median outside the mask, CIELAB; :data:`SPECK_L`,
    :data:`SPECK_CHROMA`) within :data:`SPECK_REACH` of the mask's edge (an outline or a hole),
    grown by :data:`SPECK_GROW` px.  The texture takes them out of the blade (alpha 0), so
    :func:`~leafsim.appearance.texture.clean_texture` gives them the nearest leaf colour and no
    mean or sampled photo colour counts them; the mesh's outline does not change.  Tissue is
    not the paper's colour (a pale vein is green, a lesion dark)."""
    import cv2
    from scipy.ndimage import distance_transform_edt

    blade = np.asarray(blade, bool)
    if not blade.any() or blade.all():
        return np.zeros(blade.shape, bool)
    lab = cv2.cvtColor(np.ascontiguousarray(rgb, np.uint8), cv2.COLOR_RGB2LAB).astype(np.float32)
    lab[..., 0] *= 100.0 / 255.0
    lab[..., 1:] -= 128.0
    bg = np.median(lab[~blade], axis=0)
    if bg[0] < SPECK_MIN_L:  # a dark background: dark tissue by the margin (a necrotic rim) is not it
        return np.zeros(blade.shape, bool)
    near = distance_transform_edt(blade) <= SPECK_REACH * max(blade.shape)
    like = (np.abs(lab[..., 0] - bg[0]) <= SPECK_L) & (np.hypot(lab[..., 1] - bg[1], lab[..., 2] - bg[2]) <= SPECK_CHROMA)
    specks = blade & near & like
    if not specks.any():
        return specks
    grown = cv2.dilate(specks.astype(np.uint8), np.ones((3, 3), np.uint8), iterations=SPECK_GROW) > 0
    return grown & blade


def mirrored_detail(rgb: np.ndarray, smooth: np.ndarray, band: np.ndarray, blade: np.ndarray, base, apex) -> np.ndarray:
    """``smooth`` (an inpainting of ``rgb`` over ``band``) with the fine detail of the blade
    mirrored across the base → apex axis laid on the band: an inpainting is smooth over the
    band's width, a blade is not (its finer veins, its grain), and a leaf is nearly symmetric
    about its midrib, so the other half's detail is the likeliest. Detail is the high-pass of
    ``rgb`` finer than the band's half-width; band pixels whose mirror image falls off the blade
    or on the band keep the smooth fill, and the detail fades in over the band's edge pixels."""
    import cv2

    if not band.any():
        return smooth
    inside = cv2.distanceTransform(band.astype(np.uint8), cv2.DIST_L2, 5)
    sigma = max(1.0, float(inside.max()))
    h, w = band.shape
    img = rgb.astype(np.float32)
    clean = blade & ~band
    num = cv2.GaussianBlur(np.where(clean[..., None], img, 0.0), (0, 0), sigma)
    den = cv2.GaussianBlur(clean.astype(np.float32), (0, 0), sigma)
    detail = np.where(clean[..., None], img - num / np.maximum(den[..., None], 1e-3), 0.0)
    d = np.asarray(apex, float) - np.asarray(base, float)
    d /= max(float(np.hypot(*d)), 1e-9)
    ys, xs = np.nonzero(band)
    p = np.stack([xs, ys], 1).astype(float) - base
    q = base + 2.0 * (p @ d)[:, None] * d - p  # the reflection across the axis
    mx, my = np.rint(q[:, 0]).astype(int), np.rint(q[:, 1]).astype(int)
    ok = (mx >= 0) & (mx < w) & (my >= 0) & (my < h)
    ok[ok] &= clean[my[ok], mx[ok]]
    out = smooth.astype(np.float32)
    fade = np.clip(inside[ys[ok], xs[ok]] / 2.0, 0.0, 1.0)[:, None]
    out[ys[ok], xs[ok]] += fade * detail[my[ok], mx[ok]]
    return np.clip(out + 0.5, 0, 255).astype(np.uint8)


def species_photo_rgba(sp: Species, params: ParamSet | None = None) -> np.ndarray:
    """The species photo as a texture: :func:`load_photo_rgba` with its traced blade."""
    params = params if params is not None else sp.params
    return load_photo_rgba(sp.image, params["limits.image_pixels"], species_trace(sp, params))
