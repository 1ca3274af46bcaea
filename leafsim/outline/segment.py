"""Segmenting one leaf from its background: alpha when it is informative, else colour against
the background estimated from the border (cast shadows count as background), holes filled
or kept as closed sinuses, one leaf-sized region picked (two are refused)."""

from __future__ import annotations

import math

import cv2
import numpy as np

from leafsim.base.errors import LeafsimError
from leafsim.outline.holes import kept_holes
from leafsim.outline.image import _disk, _fill_holes

#: A component smaller than this fraction of the image is not a leaf.
MIN_LEAF_FRACTION = 0.005


#: A second region at least this fraction of the leaf's area makes the photo ambiguous.
SECOND_LEAF_FRACTION = 0.25


#: A hole in the blade at least this fraction of the leaf's area is kept (a closed sinus).
HOLE_MIN_FRACTION = 0.001


def _alpha_informative(a: np.ndarray) -> bool:
    transparent = float(np.count_nonzero(a < 128)) / a.size
    return 0.01 < transparent < 0.99


#: Lab distance under which two colours count as the same background
_SAME_COLOUR = 12.0


#: a border strip with more than this share of pixels off the background colour is "mixed"
_MIXED_BORDER = 0.25


def _border_strip(a: np.ndarray, b: int) -> np.ndarray:
    return np.concatenate([a[:b].reshape(-1, 3), a[-b:].reshape(-1, 3),
                           a[b:-b, :b].reshape(-1, 3), a[b:-b, -b:].reshape(-1, 3)])


def _border_mask(h: int, w: int, b: int) -> np.ndarray:
    m = np.zeros((h, w), bool)
    m[:b] = m[-b:] = True
    m[:, :b] = m[:, -b:] = True
    return m


#: inlier share of the border a smooth background field must explain to be used
_FIELD_INLIERS = 1.0 - _MIXED_BORDER


def _smooth_background(lab: np.ndarray) -> np.ndarray | None:
    """A background whose brightness or tint drifts across the sheet (a phone photo lit from one
    side, a vignette): a quadratic in (x, y) per Lab channel fitted to the border strip,
    refitted on its inliers (a leaf touching the border is an outlier).  Returns the (h, w, 3)
    field, or None when it does not explain the border."""
    h, w = lab.shape[:2]
    ys, xs = np.nonzero(_border_mask(h, w, _border_width(h, w)))
    step = max(1, len(xs) // 40000)
    ys, xs = ys[::step], xs[::step]
    u, v = xs / max(w - 1, 1), ys / max(h - 1, 1)
    A = np.stack([np.ones_like(u), u, v, u * u, u * v, v * v], 1)
    y = lab[ys, xs].astype(np.float64)
    inl = np.ones(len(u), bool)
    for _ in range(6):
        coef = np.linalg.lstsq(A[inl], y[inl], rcond=None)[0]
        res = np.linalg.norm(A @ coef - y, axis=1)
        new = res < _SAME_COLOUR
        if new.sum() < 6 or (new == inl).all():
            inl = new
            break
        inl = new
    if inl.mean() < _FIELD_INLIERS:
        return None
    U, V = np.meshgrid(np.linspace(0.0, 1.0, w), np.linspace(0.0, 1.0, h))
    basis = np.stack([np.ones_like(U), U, V, U * U, U * V, V * V], -1)
    return (basis @ coef).astype(np.float32)


def _background_lab(lab: np.ndarray, path: str) -> np.ndarray:
    """Background colour (Lab) of a photo: the median of a border strip.

    When the leaf covers much of the border (it touches the frame), the strip's median can be
    the leaf's colour; the background is then the colour the four corners agree on.
    """
    h, w = lab.shape[:2]
    b = _border_width(h, w)
    strip = _border_strip(lab, b)
    bg = np.median(strip, axis=0)
    if np.mean(np.linalg.norm(strip - bg, axis=1) > _SAME_COLOUR) <= _MIXED_BORDER:
        return bg
    corners = [lab[:b, :b], lab[:b, -b:], lab[-b:, :b], lab[-b:, -b:]]
    med = np.array([np.median(c.reshape(-1, 3), axis=0) for c in corners])
    agree = np.linalg.norm(med[:, None] - med[None], axis=2) < _SAME_COLOUR
    k = int(np.argmax(agree.sum(1)))
    if agree[k].sum() < 2:
        raise LeafsimError(f"{path}: cannot tell the background from the leaf (neither the image border nor its "
                           "corners show one background colour or a smooth shading of one; expected a leaf on a "
                           "plain background)")
    return np.median(np.concatenate([corners[i].reshape(-1, 3) for i in np.flatnonzero(agree[k])]), axis=0)


def _border_width(h: int, w: int) -> int:
    return max(2, int(round(0.03 * min(h, w))))


def _inner_region(fg: np.ndarray) -> bool:
    """Whether a leaf-sized foreground region lies away from the image border (as
    :func:`_pick_leaf` prefers); when none does, the background estimate may be what failed."""
    h, w = fg.shape
    n, lab, stats, _ = cv2.connectedComponentsWithStats(fg, connectivity=8)
    if n <= 1:
        return False
    border = np.concatenate([lab[0, :], lab[-1, :], lab[1:-1, 0], lab[1:-1, -1]])
    border_frac = np.bincount(border, minlength=n)[1:].astype(float) / border.size
    return bool(np.any((stats[1:, cv2.CC_STAT_AREA] >= MIN_LEAF_FRACTION * h * w) & (border_frac < 0.08)))


#: a shadow lit by the sky is bluer than the lit sheet: a shift to blue (b* down) counts this much
_SKY_BLUE = 0.35


def _off_chroma(ab: np.ndarray, s: np.ndarray, g: np.ndarray) -> np.ndarray:
    d = ab - s[..., None] * g
    d[..., 1] = np.where(d[..., 1] < 0.0, _SKY_BLUE * d[..., 1], d[..., 1])
    return np.linalg.norm(d, axis=-1)


def _shadow(lab: np.ndarray, bg: np.ndarray) -> np.ndarray:
    """Pixels that look like the background in shadow: darker, with the background's hue and
    no more of its saturation (chroma (a, b) on the segment from grey to the background's, a
    shift towards blue discounted by :data:`_SKY_BLUE`)."""
    ab = lab[..., 1:]
    if bg.ndim > 1:  # a smooth background field: the same test pixel by pixel
        g = bg[..., 1:]
        gg = (g * g).sum(-1)
        s = np.where(gg > 1e-6, np.clip((ab * g).sum(-1) / np.maximum(gg, 1e-6), 0.0, 1.15), 0.0)
        return (lab[..., 0] < bg[..., 0] - 3.0) & (_off_chroma(ab, s, g) < 8.0)
    g = bg[1:]
    gg = float(g @ g)
    s = np.clip((ab @ g) / gg, 0.0, 1.15) if gg > 1e-6 else np.zeros(lab.shape[:2], np.float32)
    return (lab[..., 0] < bg[0] - 3.0) & (_off_chroma(ab, s, g) < 8.0)


def _colour_foreground(bgr: np.ndarray, path: str = "image", shading: bool = False):
    """Foreground = pixels whose Lab colour is far from the background (Otsu), cast shadows
    (darker, less saturated background) excluded unless they would be most of it.
    Returns (mask, 99.5th percentile of the colour distance, Lab image).  ``shading``: the
    background is a smooth field fitted to the border (:func:`_smooth_background`); returns
    None when no field explains the border."""
    h, w = bgr.shape[:2]
    lab = cv2.cvtColor(bgr.astype(np.float32) * (1.0 / 255.0), cv2.COLOR_BGR2Lab)
    bg = _smooth_background(lab) if shading else _background_lab(lab, path)
    if bg is None:
        return None
    dist = np.sqrt(((lab - bg) ** 2).sum(axis=2))
    hi = float(np.percentile(dist, 99.5))
    if hi < 8.0:  # nothing stands out from the background by more than a faint shade
        return np.zeros((h, w), np.uint8), hi, lab
    d8 = np.clip(dist * (255.0 / hi), 0, 255).astype(np.uint8)
    t8, _ = cv2.threshold(d8, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    thr = max(t8 * hi / 255.0, 6.0)
    fg = dist > thr
    shade = fg & _shadow(lab, bg)
    if np.count_nonzero(shade) < 0.5 * np.count_nonzero(fg):  # a grey leaf is not its own shadow
        fg &= ~shade
    return np.where(fg, 255, 0).astype(np.uint8), hi, lab


def _restore_petiole(raw: np.ndarray, opened: np.ndarray, leaf: np.ndarray, lab: np.ndarray | None) -> np.ndarray:
    """Give back thin pieces the clean-up opening cut off the leaf (a petiole thinner than the
    opening disk): a removed piece touching the leaf, away from the image border, at least 3×
    longer than wide, longer than 5 % of the leaf size and (in a colour photo) of the leaf's
    colour — a grid line of graph paper touching the margin is not a petiole."""
    removed = cv2.bitwise_and(raw, cv2.bitwise_not(opened))
    if not removed.any():
        return leaf
    n, lab, stats, _ = cv2.connectedComponentsWithStats(removed, connectivity=8)
    ring = cv2.dilate(leaf, _disk(5))
    size = math.sqrt(max(np.count_nonzero(leaf), 1))
    H, W = leaf.shape
    out = leaf.copy()
    leaf_colour = None if lab is None else np.median(lab[leaf > 0][:: max(1, np.count_nonzero(leaf) // 20000)], axis=0)
    for k in range(1, n):
        x, y, w, h, area = stats[k]
        if x == 0 or y == 0 or x + w >= W or y + h >= H or area < 6:
            continue
        piece = lab[y : y + h, x : x + w] == k
        if not np.any(piece & (ring[y : y + h, x : x + w] > 0)):
            continue
        (_, _), (a, b), _ = cv2.minAreaRect(np.column_stack(np.nonzero(piece)[::-1]).astype(np.float32))
        long, short = max(a, b), max(min(a, b), 1.0)
        if long < 3.0 * short or long < 0.05 * size:
            continue
        if leaf_colour is not None and np.linalg.norm(np.median(lab[y : y + h, x : x + w][piece], axis=0) - leaf_colour) > 25.0:
            continue
        out[y : y + h, x : x + w][piece] = 255
    return out


def _colour_segments(bgr: np.ndarray, path: str):
    """:func:`_colour_foreground` against one background colour; when that leaves no
    leaf-sized region away from the border (a sheet lit from one side: its darker half joins
    the leaf and runs off the frame) or finds no background colour at all, against a smooth
    shading of the background instead, if that gives a region away from the border."""
    try:
        first, err = _colour_foreground(bgr, path), None
    except LeafsimError as e:
        first, err = None, e
    if first is None or not _inner_region(first[0]):
        shaded = _colour_foreground(bgr, path, shading=True)
        if shaded is not None and _inner_region(shaded[0]):
            return shaded
    if err is not None:
        raise err
    return first


def segment_leaf(img: np.ndarray, path: str = "image") -> np.ndarray:
    """Binary mask (uint8 0/255) of the one leaf in ``img`` (BGR or BGRA uint8).

    Uses the alpha channel when it is informative, else the Lab colour distance to the
    background (estimated from a border strip, or from the corners when the leaf touches the
    frame), thresholded with Otsu; cast shadows are background.  Thin clutter (graph paper
    grid lines, specks) is removed by a small opening (a petiole it cuts off is given back),
    small gaps are closed, the largest component that does not run along the image border wins
    (a ruler or colour chart lying at the edge loses), and its holes are filled.

    Raises LeafsimError ``<path>: no leaf found (...)`` when nothing leaf-sized stands out, and
    ``<path>: ... leaf-sized regions`` when there is more than one leaf.
    """
    return segment_with_holes(img, path)[0]


def segment_with_holes(img: np.ndarray, path: str = "image") -> tuple[np.ndarray, np.ndarray]:
    """:func:`segment_leaf` and the holes it filled that are real openings of the blade:
    (filled mask, hole mask), both uint8 0/255.  A hole is kept when the cleaned foreground
    (thin clutter removed, small gaps closed) leaves it open and it covers at least
    ``HOLE_MIN_FRACTION`` of the leaf (closed sinuses where lobes overlap; specks and glints
    are filled)."""
    if img is None or img.ndim != 3 or img.shape[2] not in (3, 4):
        raise LeafsimError(f"{path}: no leaf found (expected a colour image)")
    h, w = img.shape[:2]
    diag = math.hypot(w, h)
    fg = lab = None
    if img.shape[2] == 4 and _alpha_informative(img[..., 3]):
        fg = np.where(img[..., 3] >= 128, 255, 0).astype(np.uint8)
        k_open = max(3, int(round(0.003 * diag)))
    if fg is None:
        fg, spread, lab = _colour_segments(np.ascontiguousarray(img[..., :3]), path)
        if not fg.any():
            raise LeafsimError(f"{path}: no leaf found (the image is blank: nothing differs from the background colour)")
        k_open = max(3, int(round(0.005 * diag)))
    k_close = max(3, int(round(0.006 * diag)))
    opened = cv2.morphologyEx(fg, cv2.MORPH_OPEN, _disk(k_open))
    leaf = _pick_leaf(cv2.morphologyEx(opened, cv2.MORPH_CLOSE, _disk(k_close)), path)
    filled = _fill_holes(_restore_petiole(fg, opened, leaf, lab))
    holes = kept_holes(filled, leaf, HOLE_MIN_FRACTION)
    return filled, (holes if lab is None else background_holes(holes, filled, lab))


#: an opening shows the background when its median is within this much L* darker than the
#: background's (the lobes around a closed sinus shade the sheet under it) ...
HOLE_DARKER_L = 30.0
#: ... and within this chroma distance (a, b) of it
HOLE_CHROMA = 20.0


def background_holes(holes: np.ndarray, filled: np.ndarray, lab: np.ndarray) -> np.ndarray:
    """The holes that look like the background through the blade — its colour, at most a little
    shaded — and not dark or brown lesions inside it (a necrotic spot, a tar spot, an insect's
    dark feeding mark are tissue: they darken the blade, they do not open it).  ``lab``: the
    photo in CIELAB; the background is the median of everything outside the leaf."""
    if not holes.any():
        return holes
    outside = filled == 0
    if not outside.any():
        return holes
    bg = np.median(lab[outside], axis=0)
    n, labels = cv2.connectedComponents(holes, connectivity=4)
    out = np.zeros_like(holes)
    for i in range(1, n):
        px = lab[labels == i]
        med = np.median(px, axis=0)
        if med[0] >= bg[0] - HOLE_DARKER_L and float(np.hypot(*(med[1:] - bg[1:]))) <= HOLE_CHROMA:
            out[labels == i] = 255
    return out


def _pick_leaf(fg: np.ndarray, path: str) -> np.ndarray:
    """The leaf component of a cleaned foreground mask (see :func:`segment_leaf`)."""
    h, w = fg.shape
    n, lab, stats, _ = cv2.connectedComponentsWithStats(fg, connectivity=8)
    if n <= 1:
        raise LeafsimError(f"{path}: no leaf found (no region stands out from the background)")
    areas = stats[1:, cv2.CC_STAT_AREA].astype(float)
    min_area = MIN_LEAF_FRACTION * h * w
    # share of the image border each component covers
    border = np.concatenate([lab[0, :], lab[-1, :], lab[1:-1, 0], lab[1:-1, -1]])
    border_frac = np.bincount(border, minlength=n)[1:].astype(float) / border.size
    big = areas >= min_area
    if not big.any():
        raise LeafsimError(
            f"{path}: no leaf found (largest region covers {100 * areas.max() / (h * w):.2f} % of the image, "
            f"expected at least {100 * MIN_LEAF_FRACTION:g} %)")
    inner = big & (border_frac < 0.08)
    pool = inner if inner.any() else big
    ranked = np.argsort(np.where(pool, -areas, np.inf), kind="stable")
    k = 1 + int(ranked[0])
    if pool.sum() > 1 and areas[ranked[1]] >= SECOND_LEAF_FRACTION * areas[ranked[0]]:
        raise LeafsimError(
            f"{path}: found {int(np.count_nonzero(pool & (areas >= SECOND_LEAF_FRACTION * areas[ranked[0]])))} leaf-sized "
            f"regions ({areas[ranked[0]]:.0f} and {areas[ranked[1]]:.0f} px); expected one leaf per photo (crop it to one leaf)")
    return np.where(lab == k, 255, 0).astype(np.uint8)
