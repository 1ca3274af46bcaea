"""Leaf outline from a photo or scan (SPEC §1).

Pipeline: :func:`load_image` → :func:`segment_leaf` (alpha, or colour distance to the border
background in Lab + Otsu, morphological clean-up, the largest leaf-like component, holes
filled) → :func:`trace_outline` (outer contour, Douglas–Peucker, equal-arc-length resampling,
petiole junction = base, apex, lobe tips) → :func:`to_leaf_shape` (similarity transform to
world metres).  :func:`outline_report` and :func:`draw_outline` serve ``leafsim outline``.

Pixel coordinates are ``(x, y)`` with y pointing down, as in the photo.

Example
-------
>>> t = trace_outline("images/quercus_01.png")            # doctest: +SKIP
>>> shape = to_leaf_shape(t, 0.12)                         # doctest: +SKIP
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import cv2
import numpy as np

from .errors import LeafsimError
from .fileio import write_png_atomic
from .geometry import LeafShape, polygon_area, resample_closed
from .outline_holes import hole_polygons, kept_holes, petiole_band, sinus_junction, without_band
from .params import ParamSet

__all__ = [
    "TracedOutline",
    "load_image",
    "segment_leaf",
    "working_image",
    "trace_outline",
    "to_leaf_shape",
    "outline_report",
    "draw_outline",
]

#: A component smaller than this fraction of the image is not a leaf.
MIN_LEAF_FRACTION = 0.005
#: A second region at least this fraction of the leaf's area makes the photo ambiguous.
SECOND_LEAF_FRACTION = 0.25
#: A hole in the blade at least this fraction of the leaf's area is kept (a closed sinus).
HOLE_MIN_FRACTION = 0.001
_DEBUG = False


@dataclass
class TracedOutline:
    """Result of :func:`trace_outline` (all coordinates in photo pixels, y down).

    Attributes
    ----------
    mask : (h, w) uint8 0/255 — the traced leaf region (holes filled, petiole cut off).
    contour_px : (n, 2) float64 — closed outline (first point not repeated), equal arc length,
        starting at the point nearest the base, counter-clockwise *as the photo is seen*
        (i.e. negative signed area in y-down pixel coordinates).
    area_px : float — area of ``mask`` in pixels.
    base_px : (2,) float64 — petiole junction (given, or detected).
    apex_px : (2,) float64 — apex (given, or the contour point farthest from the base).
    lobes_px : (k, 2) float64 — detected lobe tips (the apex tip included), may be empty.
    iou : float — IoU of the rasterised ``contour_px`` polygon with ``mask``.
    image_size : (w, h) of the photo.
    path : str — the photo path as given.
    petiole_px : (2, 2) float64 [junction, tip] of the detected petiole, or None.
    base_method : "given", "petiole" or "shape" (how the base was found).
    seconds : wall-clock time of the trace.
    work_scale : the photo was traced downscaled by this factor (1.0: at full size); ``mask``
        has the working size, every coordinate is in full-photo pixels.
    border_fraction : share of the image border the traced leaf covers (> 0: the leaf runs
        off the photo and the frame's straight edge is part of the outline).
    holes_px : list of (k, 2) float64 — closed holes of the blade (sinuses closed by
        overlapping lobes), clockwise as seen; ``hole_mask`` the same at the working size.
    petiole_mask : (h, w) uint8 0/255 or None — pixels of a petiole lying on the blade (its
        colour is no blade's: inpaint it in a texture), at the working size.
    """

    mask: np.ndarray
    contour_px: np.ndarray
    area_px: float
    base_px: np.ndarray
    apex_px: np.ndarray
    lobes_px: np.ndarray
    iou: float
    image_size: tuple[int, int]
    path: str
    petiole_px: np.ndarray | None = None
    base_method: str = "shape"
    seconds: float = 0.0
    work_scale: float = 1.0
    border_fraction: float = 0.0
    holes_px: list = field(default_factory=list)
    hole_mask: np.ndarray | None = None
    petiole_mask: np.ndarray | None = None

    @property
    def length_px(self) -> float:
        """Base–apex distance in pixels."""
        return float(np.linalg.norm(self.apex_px - self.base_px))


# ----------------------------------------------------------------------------- loading

def load_image(path: str | os.PathLike) -> np.ndarray:
    """Read a photo as uint8 BGR (h, w, 3) or BGRA (h, w, 4).

    Raises LeafsimError ``<path>: cannot read image (<reason>)`` for a missing, unreadable,
    empty or corrupt file.
    """
    p = Path(path)
    where = str(path)
    if not p.exists():
        raise LeafsimError(f"{where}: cannot read image (file not found)")
    if p.is_dir():
        raise LeafsimError(f"{where}: cannot read image (is a folder, expected an image file)")
    try:
        data = np.fromfile(str(p), dtype=np.uint8)
    except OSError as exc:
        raise LeafsimError(f"{where}: cannot read image ({exc.strerror or exc})") from None
    if data.size == 0:
        raise LeafsimError(f"{where}: cannot read image (empty file)")
    img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise LeafsimError(f"{where}: cannot read image (not a PNG/JPEG/TIFF/BMP image or corrupt data)")
    if img.size == 0 or img.shape[0] == 0 or img.shape[1] == 0:
        raise LeafsimError(f"{where}: cannot read image (image has no pixels)")
    if img.dtype != np.uint8:
        if img.dtype == np.uint16:
            img = (img >> 8).astype(np.uint8)
        elif np.issubdtype(img.dtype, np.floating):
            img = np.clip(np.nan_to_num(img) * 255.0, 0, 255).astype(np.uint8)
        else:
            img = cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    elif img.shape[2] == 2:  # grey + alpha
        g, a = img[..., 0], img[..., 1]
        img = np.dstack([g, g, g, a])
    elif img.shape[2] > 4:
        img = img[..., :4]
    if min(img.shape[:2]) < 8:
        raise LeafsimError(f"{where}: cannot read image (too small: {img.shape[1]}×{img.shape[0]} pixels)")
    return np.ascontiguousarray(img)


# ----------------------------------------------------------------------------- segmentation

def _disk(d: int) -> np.ndarray:
    d = max(1, int(d) | 1)
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (d, d))


def _fill_holes(mask: np.ndarray) -> np.ndarray:
    cnts, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    out = np.zeros_like(mask)
    if cnts:
        cv2.drawContours(out, cnts, -1, 255, thickness=cv2.FILLED)
    return out


def _largest_component(mask: np.ndarray) -> np.ndarray:
    n, lab, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if n <= 1:
        return np.zeros_like(mask)
    k = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    return np.where(lab == k, 255, 0).astype(np.uint8)


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


def _background_lab(lab: np.ndarray, path: str) -> np.ndarray:
    """Background colour (Lab) of a photo: the median of a border strip.

    When the leaf covers much of the border (it touches the frame), the strip's median can be
    the leaf's colour; the background is then the colour the four corners agree on.
    """
    h, w = lab.shape[:2]
    b = max(2, int(round(0.03 * min(h, w))))
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
                           "corners show one background colour; expected a leaf on a plain background)")
    return np.median(np.concatenate([corners[i].reshape(-1, 3) for i in np.flatnonzero(agree[k])]), axis=0)


def _shadow(lab: np.ndarray, bg: np.ndarray) -> np.ndarray:
    """Pixels that look like the background in shadow: darker, with the background's hue and
    no more of its saturation (chroma (a, b) on the segment from grey to the background's)."""
    ab = lab[..., 1:]
    g = bg[1:]
    gg = float(g @ g)
    s = np.clip((ab @ g) / gg, 0.0, 1.15) if gg > 1e-6 else np.zeros(lab.shape[:2], np.float32)
    off = np.linalg.norm(ab - s[..., None] * g, axis=2)
    return (lab[..., 0] < bg[0] - 3.0) & (off < 8.0)


def _colour_foreground(bgr: np.ndarray, path: str = "image") -> tuple[np.ndarray, float, np.ndarray]:
    """Foreground = pixels whose Lab colour is far from the background (Otsu), cast shadows
    (darker, less saturated background) excluded unless they would be most of it.
    Returns (mask, 99.5th percentile of the colour distance, Lab image)."""
    h, w = bgr.shape[:2]
    lab = cv2.cvtColor(bgr.astype(np.float32) * (1.0 / 255.0), cv2.COLOR_BGR2Lab)
    bg = _background_lab(lab, path)
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
        fg, spread, lab = _colour_foreground(np.ascontiguousarray(img[..., :3]), path)
        if not fg.any():
            raise LeafsimError(f"{path}: no leaf found (the image is blank: nothing differs from the background colour)")
        k_open = max(3, int(round(0.005 * diag)))
    k_close = max(3, int(round(0.006 * diag)))
    opened = cv2.morphologyEx(fg, cv2.MORPH_OPEN, _disk(k_open))
    leaf = _pick_leaf(cv2.morphologyEx(opened, cv2.MORPH_CLOSE, _disk(k_close)), path)
    filled = _fill_holes(_restore_petiole(fg, opened, leaf, lab))
    return filled, kept_holes(filled, leaf, HOLE_MIN_FRACTION)


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


# ----------------------------------------------------------------------------- geometry helpers

def _hull_pockets(P: np.ndarray, closed: bool = True):
    """Concave pockets of polygon P: (i, j, f, depth) — hull edge P[i]→P[j] (indices in P's
    order, j may exceed len(P) when it wraps), deepest chain point f, its depth.

    With ``closed=False`` the edge from the last back to the first point is an artificial
    closing chord: pockets spanning it are skipped.
    """
    m = len(P)
    if m < 4:
        return []
    hull = cv2.convexHull(P.astype(np.float32), returnPoints=False)
    if hull is None or len(hull) < 3:
        return []
    h = np.sort(hull.ravel().astype(int))
    out = []
    for k in range(len(h)):
        i = int(h[k])
        j = int(h[k + 1]) if k + 1 < len(h) else int(h[0]) + m
        if j - i < 2:
            continue
        if not closed and j >= m:
            continue
        chain = np.arange(i + 1, j) % m
        a, b = P[i], P[j % m]
        ab = b - a
        L = float(np.hypot(*ab))
        if L < 1e-9:
            dep = np.linalg.norm(P[chain] - a, axis=1)
        else:
            dep = np.abs((P[chain, 0] - a[0]) * ab[1] - (P[chain, 1] - a[1]) * ab[0]) / L
        q = int(np.argmax(dep))
        out.append((i, j, int(chain[q]), float(dep[q])))
    return out


def _sinuses(P: np.ndarray, thr: float) -> list[int]:
    """Indices of sinus bottoms deeper than ``thr`` (recursively, so a lobe hidden below the
    hull of its neighbours still separates its sinuses)."""
    found: list[int] = []

    def rec(idx: np.ndarray, closed: bool, depth_left: int):
        if depth_left <= 0 or len(idx) < 5:
            return
        for i, j, f, d in _hull_pockets(P[idx], closed):
            if d < thr:
                continue
            m = len(idx)
            found.append(int(idx[f]))
            # sub-polygons hull-vertex → sinus and sinus → hull-vertex (in contour order)
            left = idx[np.arange(i, f + (m if f < i else 0) + 1) % m]
            right = idx[np.arange(f, j + (m if j < f else 0) + 1) % m]
            rec(left, False, depth_left - 1)
            rec(right, False, depth_left - 1)

    rec(np.arange(len(P)), True, 6)
    return sorted(set(found))


def _reflect_iou(small: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """IoU of a mask with its mirror image about the line through a and b."""
    d = b - a
    n = float(np.hypot(*d))
    if n < 1e-9:
        return 0.0
    u = d / n
    R = 2.0 * np.outer(u, u) - np.eye(2)
    t = a - R @ a
    M = np.hstack([R, t[:, None]]).astype(np.float32)
    ref = cv2.warpAffine(small, M, (small.shape[1], small.shape[0]), flags=cv2.INTER_NEAREST)
    inter = np.count_nonzero(ref & small)
    union = np.count_nonzero(ref | small)
    return inter / union if union else 0.0


def _width_across(P: np.ndarray, b: np.ndarray, a: np.ndarray, frac: float) -> float:
    """Width of the polygon across the b→a axis at ``frac`` of the way from b."""
    d = a - b
    L = float(np.hypot(*d))
    u = d / L
    v = np.array([-u[1], u[0]])
    s = (P - b) @ u
    t = (P - b) @ v
    target = frac * L
    Q = np.roll(np.arange(len(P)), -1)
    cross = (s - target) * (s[Q] - target) <= 0
    if not cross.any():
        return 0.0
    i = np.nonzero(cross)[0]
    j = Q[i]
    ds = s[j] - s[i]
    w = np.where(np.abs(ds) > 1e-12, (target - s[i]) / np.where(np.abs(ds) > 1e-12, ds, 1), 0.0)
    tt = t[i] + w * (t[j] - t[i])
    return float(tt.max() - tt.min())


# ----------------------------------------------------------------------------- petiole / base

def _petiole_candidates(sm: np.ndarray, sscale: float):
    """Thin protrusions of a leaf mask (scaled to a leaf size ``sscale`` ≈ 320 px) that an
    opening with a disk of ≈ 6 % of the leaf size removes: attached to the opened blade,
    sticking out at least one disk diameter, ≥ 2.5× longer than wide.

    Returns (labels of the removed pieces, [(score, label, tip_xy, width, bbox), ...]).
    """
    d = int(np.clip(0.06 * sscale, 7, 301))
    blade = _largest_component(cv2.morphologyEx(sm, cv2.MORPH_OPEN, _disk(d)))
    removed = cv2.bitwise_and(sm, cv2.bitwise_not(blade))
    if not blade.any() or not removed.any():
        return None, []
    dist_out = cv2.distanceTransform(cv2.bitwise_not(blade), cv2.DIST_L2, 5)
    n, lab, stats, _ = cv2.connectedComponentsWithStats(removed, connectivity=8)
    found = []
    half = 0.5 * d
    for k in range(1, n):
        if stats[k, cv2.CC_STAT_AREA] < 6:
            continue
        x0, y0 = stats[k, cv2.CC_STAT_LEFT], stats[k, cv2.CC_STAT_TOP]
        x1, y1 = x0 + stats[k, cv2.CC_STAT_WIDTH], y0 + stats[k, cv2.CC_STAT_HEIGHT]
        sub = lab[y0:y1, x0:x1] == k
        ys, xs = np.nonzero(sub)
        ys = ys + y0
        xs = xs + x0
        dv = dist_out[ys, xs]
        if dv.min() > 2.0:  # not attached to the blade
            continue
        prot = float(dv.max())
        if prot < max(0.05 * sscale, d):
            continue
        far = dv > half
        piece_k = np.where(sub, 255, 0).astype(np.uint8)
        inner = cv2.distanceTransform(np.pad(piece_k, 1), cv2.DIST_L2, 5)[1:-1, 1:-1]
        width = max(2.0 * float(inner[ys[far] - y0, xs[far] - x0].max()), 1.0)
        elong = prot / width
        if _DEBUG:
            print("petiole candidate", k, "prot", round(prot, 1), "width", round(width, 1), "elong", round(elong, 2))
        if elong < 2.5:
            continue
        q = int(np.argmax(dv))
        found.append((prot * min(elong, 10.0), k, (xs[q], ys[q]), width, (x0, y0, x1, y1)))
    return lab, found


def _find_petiole(mask: np.ndarray, scale: float, where: str = "image"):
    """Detect the petiole as the longest thin protrusion that an opening removes.

    Candidates come from :func:`_petiole_candidates` on a copy of the mask scaled to a leaf
    size of ~320 px (so detection does not depend on the photo's resolution); the
    longest/thinnest wins.  Two strong candidates (the second scoring ≥ 30 % of the first) are
    two petioles: overlapping leaves, refused with a LeafsimError.  The winner is then cut at
    full resolution with a finer opening just wider than the petiole.

    Returns (blade_mask, junction_xy, tip_xy, width_px) or None.
    """
    H, W = mask.shape
    f = min(1.0, 320.0 / max(scale, 1.0))
    sm = mask if f >= 1.0 else np.where(
        cv2.resize(mask, (max(1, round(W * f)), max(1, round(H * f))), interpolation=cv2.INTER_AREA) >= 128, 255, 0
    ).astype(np.uint8)
    lab, cands = _petiole_candidates(sm, scale * f)
    if not cands:
        return None
    cands.sort(key=lambda c: -c[0])
    best = cands[0]
    strong = [c for c in cands if c[0] >= 0.3 * best[0]]
    if len(strong) > 1:
        h, w = sm.shape
        at = " and ".join(f"({100 * c[2][0] / w:.0f} %, {100 * c[2][1] / h:.0f} %)" for c in strong[:3])
        raise LeafsimError(f"{where}: found {len(strong)} petioles, tips at {at} of the image width, height: "
                           "overlapping leaves? (expected one leaf per photo)")
    _, k, (tx, ty), width, (x0, y0, x1, y1) = best
    tip = (np.array([tx, ty], float) + 0.5) / f - 0.5
    width_full = width / f
    # --- precise cut at full resolution, inside a window around the piece
    fine_d = int(max(3, round(1.6 * width_full + 3)))
    pad = 2 * fine_d + 4
    X0, Y0 = max(0, int(x0 / f) - pad), max(0, int(y0 / f) - pad)
    X1, Y1 = min(W, int(np.ceil(x1 / f)) + pad), min(H, int(np.ceil(y1 / f)) + pad)
    roi = mask[Y0:Y1, X0:X1]
    piece_small = np.where(lab == k, 255, 0).astype(np.uint8)
    piece_up = cv2.resize(piece_small, (W, H), interpolation=cv2.INTER_NEAREST)[Y0:Y1, X0:X1] if f < 1.0 else piece_small[Y0:Y1, X0:X1]
    piece_up = cv2.dilate(piece_up, _disk(max(3, int(2 / f) | 1)))
    fine_removed = cv2.bitwise_and(cv2.bitwise_and(roi, cv2.bitwise_not(cv2.morphologyEx(roi, cv2.MORPH_OPEN, _disk(fine_d)))), piece_up)
    m2, lab2, st2, _ = cv2.connectedComponentsWithStats(fine_removed, connectivity=8)
    cut_roi = None
    if m2 > 1:
        # the removed piece nearest the detected tip
        yy, xx = np.nonzero(lab2)
        dd = (xx + X0 - tip[0]) ** 2 + (yy + Y0 - tip[1]) ** 2
        tk = lab2[yy[int(np.argmin(dd))], xx[int(np.argmin(dd))]]
        cut_roi = np.where(lab2 == tk, 255, 0).astype(np.uint8)
    if cut_roi is None:
        cut_roi = cv2.bitwise_and(piece_up, roi)
    cut = np.zeros_like(mask)
    cut[Y0:Y1, X0:X1] = cut_roi
    blade_mask = _fill_holes(_largest_component(cv2.bitwise_and(mask, cv2.bitwise_not(cut))))
    # junction: where the cut petiole touches the blade; tip: cut pixel farthest from it
    touch = cv2.bitwise_and(cv2.dilate(cut_roi, _disk(3)), blade_mask[Y0:Y1, X0:X1])
    ys, xs = np.nonzero(touch)
    if not len(xs):
        return None
    junction = np.array([xs.mean() + X0, ys.mean() + Y0])
    ys, xs = np.nonzero(cut_roi)
    dd = (xs + X0 - junction[0]) ** 2 + (ys + Y0 - junction[1]) ** 2
    q = int(np.argmax(dd))
    tip = np.array([xs[q] + X0, ys[q] + Y0], float)
    return blade_mask, junction, tip, float(width_full)


def _base_from_shape(P: np.ndarray, mask: np.ndarray, L: float) -> np.ndarray:
    """Base of a leaf without a visible petiole.

    A leaf is mirror-symmetric about its base→apex axis, and the apex is the contour point
    farthest from the base.  Candidate bases (points spread along the contour and the bottoms
    of hull concavities) are scored by how symmetric the mask is about the axis to their
    farthest point; the best are refined locally.  Of the axis' two ends, the base is the one
    sitting deeper in a notch (petiolar sinus) or, failing that, the blunter one.
    """
    m = len(P)
    sc_f = min(1.0, 160.0 / max(mask.shape))
    small = cv2.resize(mask, None, fx=sc_f, fy=sc_f, interpolation=cv2.INTER_AREA)
    small = np.where(small >= 128, 255, 0).astype(np.uint8)
    to_small = lambda q: (q + 0.5) * sc_f - 0.5  # noqa: E731
    hull_pts = cv2.convexHull(P.astype(np.float32))
    cache: dict[int, float] = {}

    def score(i: int) -> float:
        if i not in cache:
            b = P[i]
            dist = np.linalg.norm(P - b, axis=1)
            a = P[int(np.argmax(dist))]
            dep = max(0.0, cv2.pointPolygonTest(hull_pts, (float(b[0]), float(b[1])), True))
            cache[i] = _reflect_iou(small, to_small(b), to_small(a)) + 0.5 * min(dep / L, 0.3)
        return cache[i]

    cand = set(np.linspace(0, m, 72, endpoint=False).astype(int).tolist())
    for _, _, f, d in _hull_pockets(P, True):
        if d >= 0.01 * L:
            cand.add(int(f))
    ranked = sorted(cand, key=score, reverse=True)
    best = ranked[0]
    seeds: list[int] = []
    for i in ranked:
        if all(min(abs(i - j), m - abs(i - j)) > m // 20 for j in seeds):
            seeds.append(i)
        if len(seeds) == 3:
            break
    win = max(2, m // 30)
    for s0 in seeds:
        cur = s0
        for step in (max(1, win // 4), 1):
            improved = True
            while improved:
                improved = False
                for j in (cur - step, cur + step):
                    j %= m
                    if score(j) > score(cur):
                        cur, improved = j, True
        if score(cur) > score(best):
            best = cur
    b = P[best]
    a = P[int(np.argmax(np.linalg.norm(P - b, axis=1)))]

    def end_score(x: np.ndarray, y: np.ndarray) -> float:
        dep = max(0.0, cv2.pointPolygonTest(hull_pts, (float(x[0]), float(x[1])), True))
        Lxy = float(np.linalg.norm(y - x))
        return 2.0 * min(dep / L, 0.3) + _width_across(P, x, y, 0.1) / max(Lxy, 1e-9)

    if end_score(a, b) > end_score(b, a):
        b = a
    return b.copy()


def _lobe_tips(P: np.ndarray, base: np.ndarray, apex: np.ndarray, thr: float) -> np.ndarray:
    """Lobe tips (the apex included).

    The contour is cut at the sinuses deeper than ``thr`` and at the base; each stretch that
    protrudes at least ``thr`` beyond the chord between its two ends is a lobe, its tip the
    point farthest from the base — a contour extremum — or, when that is an end of the
    stretch (a lobe pointing back toward the base), its point farthest from the chord; the
    stretch holding the apex has the apex as its tip.
    """
    m = len(P)
    ib = int(np.argmin(np.linalg.norm(P - base, axis=1)))
    ia = int(np.argmin(np.linalg.norm(P - apex, axis=1)))
    bounds = sorted(set(_sinuses(P, thr)) | {ib})
    # merge boundaries closer than 2 % of the contour (keep the base)
    gap = max(2, int(0.02 * m))
    merged: list[int] = []
    for b in bounds:
        if merged and b - merged[-1] < gap:
            if b == ib:
                merged[-1] = b
            continue
        merged.append(b)
    if len(merged) > 1 and merged[0] + m - merged[-1] < gap:
        if merged[0] == ib:
            merged.pop()
        else:
            merged.pop(0)
    tips = []
    edge = max(1, int(0.005 * m))
    for k, b0 in enumerate(merged):
        b1 = merged[k + 1] if k + 1 < len(merged) else merged[0] + m
        if b1 - b0 < 3:
            continue
        idx = np.arange(b0, b1 + 1) % m
        a, c = P[idx[0]], P[idx[-1]]
        ac = c - a
        La = float(np.hypot(*ac))
        if La < 1e-9:
            off = np.linalg.norm(P[idx] - a, axis=1)
        else:
            off = np.abs((P[idx, 0] - a[0]) * ac[1] - (P[idx, 1] - a[1]) * ac[0]) / La
        if float(off.max()) < thr:
            continue
        hit = np.nonzero(idx == ia)[0]
        if len(hit) and edge <= hit[0] <= len(idx) - 1 - edge:
            tips.append(apex)
            continue
        q = int(np.argmax(np.linalg.norm(P[idx] - base, axis=1)))
        if not edge <= q <= len(idx) - 1 - edge:
            q = int(np.argmax(off))  # a lobe pointing back toward the base: its most protruding point
        if edge <= q <= len(idx) - 1 - edge:
            tips.append(P[idx[q]])
    return np.array(tips, float).reshape(-1, 2)


# ----------------------------------------------------------------------------- tracing

def _params(params: Mapping[str, Any] | None) -> ParamSet:
    if params is None:
        return ParamSet()
    if isinstance(params, ParamSet):
        return params
    return ParamSet(params)


def _outer_contour(mask: np.ndarray) -> np.ndarray:
    cnts, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    c = max(cnts, key=cv2.contourArea)
    return c.reshape(-1, 2).astype(np.float64)


def _start_at(poly: np.ndarray, point: np.ndarray) -> np.ndarray:
    """Rotate a closed polygon to start at the projection of ``point`` onto its nearest edge."""
    Q = np.roll(poly, -1, axis=0)
    d = Q - poly
    L2 = np.maximum((d * d).sum(1), 1e-30)
    t = np.clip(((point - poly) * d).sum(1) / L2, 0, 1)
    proj = poly + t[:, None] * d
    k = int(np.argmin(np.linalg.norm(proj - point, axis=1)))
    p = proj[k]
    rest = np.roll(poly, -(k + 1), axis=0)  # starts at poly[k+1], ends at poly[k]
    if np.linalg.norm(rest[0] - p) < 1e-9:
        return rest
    if np.linalg.norm(rest[-1] - p) < 1e-9:
        return np.roll(rest, 1, axis=0)
    return np.vstack([p, rest])


def _iou(poly: np.ndarray, mask: np.ndarray) -> float:
    r = np.zeros_like(mask)
    cv2.fillPoly(r, [np.round(poly * 16).astype(np.int32).reshape(-1, 1, 2)], 255, lineType=cv2.LINE_8, shift=4)
    inter = np.count_nonzero(r & mask)
    union = np.count_nonzero(r | mask)
    return inter / union if union else 0.0


def working_image(img: np.ndarray, max_pixels: int) -> tuple[np.ndarray, float]:
    """``img`` downscaled (area averaging) to at most ``max_pixels`` pixels, and the factor f
    (working = photo × f; 1.0 when it is small enough).  Segmenting a 20000×20000 photo at full
    size takes minutes and >10 GB; the outline's accuracy needs far fewer pixels."""
    h, w = img.shape[:2]
    if h * w <= max_pixels:
        return img, 1.0
    f = math.sqrt(max_pixels / float(h * w))
    size = (max(8, int(w * f)), max(8, int(h * f)))
    small = cv2.resize(img, size, interpolation=cv2.INTER_AREA)
    return small, size[0] / float(w)


def trace_outline(path: str | os.PathLike, params: Mapping[str, Any] | None = None,
                  base_px=None, apex_px=None) -> TracedOutline:
    """Trace the outline of the one leaf in the photo at ``path``.

    ``params`` (a ParamSet or a mapping of overrides) supplies ``outline.simplify``
    (Douglas–Peucker tolerance × image diagonal), ``outline.points`` (resample count),
    ``outline.lobe_depth`` (× leaf length) and ``limits.image_pixels`` (larger photos are
    traced on a downscaled copy; every coordinate returned is in photo pixels, the mask is at
    the working resolution, ``work_scale`` says which).  ``base_px`` / ``apex_px`` (photo
    pixels, e.g. from the species config) override detection.  A petiole sticking out of the
    blade is detected; the base is its junction with the blade and it is cut off the outline.
    """
    import time

    t0 = time.perf_counter()
    p = _params(params)
    where = str(path)
    full = load_image(path)
    h, w = full.shape[:2]
    img, f = working_image(full, int(p["limits.image_pixels"]))
    del full
    to_work = lambda q: None if q is None else (np.asarray(q, float).reshape(2) + 0.5) * f - 0.5  # noqa: E731
    t = _trace(img, p, where, to_work(base_px), to_work(apex_px))
    if f != 1.0:
        back = lambda q: None if q is None else (np.asarray(q, float) + 0.5) / f - 0.5  # noqa: E731
        t.contour_px, t.lobes_px, t.petiole_px = back(t.contour_px), back(t.lobes_px), back(t.petiole_px)
        t.holes_px = [back(hp) for hp in t.holes_px]
        t.base_px = np.asarray(base_px, float).reshape(2) if base_px is not None else back(t.base_px)
        t.apex_px = np.asarray(apex_px, float).reshape(2) if apex_px is not None else back(t.apex_px)
        t.area_px /= f * f
    t.image_size, t.work_scale = (int(w), int(h)), f
    t.seconds = time.perf_counter() - t0
    return t


@dataclass
class _Blade:
    """Masks and petiole of one traced leaf while :func:`_trace` works on them."""

    mask: np.ndarray            # filled blade silhouette (petiole cut off)
    holes: np.ndarray           # kept holes (closed sinuses)
    petiole: np.ndarray | None  # [junction, tip] of a petiole sticking out, or None
    width: float | None         # its width [px]
    band: np.ndarray | None     # pixels of a petiole lying on the blade (over blade or a sinus)
    junction: np.ndarray | None


def _petiole(lab, mask, holes, where, base_given: bool) -> _Blade:
    """Cut a petiole sticking out of the blade (also when the base is given: it never becomes
    blade); without a given base, follow it into a sinus closed by overlapping basal lobes."""
    area = float(np.count_nonzero(mask))
    found = _find_petiole(mask, math.sqrt(area), where)
    out = _Blade(mask, holes, None, None, None, None)
    if found is None or np.count_nonzero(found[0]) <= 0.8 * area:
        return out
    blade, junction, tip, width = found
    piece = (mask > 0) & (blade == 0)
    colour = np.median(lab[piece], axis=0) if piece.any() else None
    out.mask, out.petiole, out.width, out.junction = blade, np.array([junction, tip], float), width, junction
    if not base_given:
        length = float(max(np.ptp(np.nonzero(blade)[0]), np.ptp(np.nonzero(blade)[1]), 1))
        behind = sinus_junction(lab, blade, holes, junction, tip, width, length, colour)
        if behind is not None:
            out.junction = behind
    return out


def _lay_petiole_off(b: _Blade, lab, base, apex) -> None:
    """A petiole lying on the blade is no blade: under it the blade continues where blade lies
    on both of its sides, elsewhere (a sinus, the background) it is background."""
    band = petiole_band(lab, b.mask, b.holes, base, apex, b.width)
    if band is None:
        return
    width = b.width or 0.016 * float(np.linalg.norm(np.asarray(apex) - base))
    leaf, _ = without_band(b.mask, b.holes, band, width, base)
    # the pale petiole base where it joins the blade is no sinus: close gaps around the base
    near = np.zeros_like(leaf)
    cv2.circle(near, (int(round(base[0])), int(round(base[1]))), int(round(2.0 * width)) + 2, 255, -1)
    leaf = cv2.bitwise_or(leaf, cv2.bitwise_and(cv2.morphologyEx(leaf, cv2.MORPH_CLOSE, _disk(int(round(1.2 * width)))), near))
    filled = _fill_holes(_largest_component(leaf))
    b.mask, b.holes, b.band = filled, kept_holes(filled, leaf, HOLE_MIN_FRACTION), band


def _polygon(mask: np.ndarray, eps: float) -> tuple[np.ndarray, np.ndarray]:
    """(simplified outer contour counter-clockwise as seen, dense resampling of it)."""
    raw = _outer_contour(mask)
    simp = cv2.approxPolyDP(raw.astype(np.float32).reshape(-1, 1, 2), eps, True).reshape(-1, 2).astype(np.float64) if eps > 0 else raw
    if len(simp) < 3:
        simp = raw
    if polygon_area(simp) > 0:  # counter-clockwise as seen (negative signed area with y down)
        simp = simp[::-1].copy()
    perim = float(np.linalg.norm(np.diff(np.vstack([simp, simp[:1]]), axis=0), axis=1).sum())
    return simp, resample_closed(simp, int(np.clip(perim / 2.0, 200, 4000)))


def _trace(img: np.ndarray, p: ParamSet, where: str, base_px, apex_px) -> TracedOutline:
    """:func:`trace_outline` on an image in memory (all coordinates in its pixels)."""
    h, w = img.shape[:2]
    eps = float(p["outline.simplify"]) * math.hypot(w, h)
    mask, holes = segment_with_holes(img, where)
    lab = cv2.cvtColor(np.ascontiguousarray(img[..., :3]).astype(np.float32) * (1.0 / 255.0), cv2.COLOR_BGR2Lab)
    b = _petiole(lab, mask, holes, where, base_px is not None)
    simp, dense = _polygon(b.mask, eps)
    L_est = float(max(np.ptp(dense[:, 0]), np.ptp(dense[:, 1]), 1.0))
    method = "given" if base_px is not None else ("petiole" if b.junction is not None else "shape")
    if base_px is not None:
        base = np.asarray(base_px, float).reshape(2)
    elif b.junction is not None:
        near = dense[int(np.argmin(np.linalg.norm(dense - b.junction, axis=1)))]
        # on the margin, or on a sinus behind overlapping lobes (inside the silhouette)
        base = near.copy() if np.linalg.norm(near - b.junction) < 2.0 * (b.width or 1.0) + 2.0 else b.junction.copy()
    else:
        base = _base_from_shape(dense, b.mask, L_est)
    apex0 = np.asarray(apex_px, float).reshape(2) if apex_px is not None else dense[int(np.argmax(np.linalg.norm(dense - base, axis=1)))]
    _lay_petiole_off(b, lab, base, apex0)
    if b.band is not None:
        simp, dense = _polygon(b.mask, eps)
    n = int(p["outline.points"])
    contour = resample_closed(_start_at(simp, base), n)
    apex = np.asarray(apex_px, float).reshape(2) if apex_px is not None else contour[int(np.argmax(np.linalg.norm(contour - base, axis=1)))].copy()
    length = float(np.linalg.norm(apex - base))
    if length < 1e-6:
        raise LeafsimError(f"{where}: base and apex coincide at {base.tolist()} (expected distinct points)")
    thr = float(p["outline.lobe_depth"]) * length
    tips = _lobe_tips(dense, base, apex, thr) if thr > 0 else apex[None, :].copy()
    if len(tips):  # snap onto the output contour
        k = np.argmin(np.linalg.norm(contour[None, :, :] - tips[:, None, :], axis=2), axis=1)
        tips = contour[np.unique(k)]
    perim = float(np.linalg.norm(np.diff(np.vstack([contour, contour[:1]]), axis=0), axis=1).sum())
    mask = b.mask
    return TracedOutline(
        mask=mask, contour_px=contour, area_px=float(np.count_nonzero(mask)), base_px=base, apex_px=apex,
        lobes_px=np.asarray(tips, float).reshape(-1, 2), iou=_iou(contour, mask), image_size=(int(w), int(h)),
        path=where, petiole_px=b.petiole, base_method=method,
        border_fraction=float(np.mean(np.concatenate([mask[0], mask[-1], mask[1:-1, 0], mask[1:-1, -1]]) > 0)),
        holes_px=hole_polygons(b.holes, eps, perim / n), hole_mask=b.holes, petiole_mask=b.band,
    )


# ----------------------------------------------------------------------------- world frame

def to_leaf_shape(traced: TracedOutline, length_m: float) -> LeafShape:
    """Map the traced outline to world metres: base → (0, 0), apex → (0, length_m).

    A similarity transform (uniform scale, rotation, translation) after flipping the photo's
    y axis, so the leaf looks as in the photo when plotted with y up (it is not mirrored).
    The contour comes out counter-clockwise.
    """
    length_m = float(length_m)
    if not (length_m > 0 and math.isfinite(length_m)):
        raise LeafsimError(f"{traced.path}: leaf length {length_m!r}: expected a positive number of metres")
    F = np.array([[1.0, 0.0], [0.0, -1.0]])
    b = F @ traced.base_px
    a = F @ traced.apex_px
    v = a - b
    L = float(np.hypot(*v))
    if L < 1e-9:
        raise LeafsimError(f"{traced.path}: base and apex coincide (expected distinct points)")
    s = length_m / L
    # rotation taking v/|v| onto (0, 1)
    ang = math.atan2(v[0], v[1])  # angle from +y to v, clockwise positive
    c, sn = math.cos(ang), math.sin(ang)
    R = np.array([[c, -sn], [sn, c]])
    A = s * R @ F
    t = -A @ traced.base_px
    M = np.hstack([A, t[:, None]])

    def tf(pts):
        pts = np.asarray(pts, float).reshape(-1, 2)
        return pts @ A.T + t

    contour = tf(traced.contour_px)
    if polygon_area(contour) < 0:
        contour = np.vstack([contour[:1], contour[:0:-1]])
    holes = tuple(hw if polygon_area(hw) < 0 else hw[::-1].copy() for hw in (tf(hp) for hp in traced.holes_px))
    return LeafShape(
        contour=contour,
        base=np.zeros(2),
        apex=np.array([0.0, length_m]),
        lobes=tf(traced.lobes_px),
        length=length_m,
        px_to_world=M,
        image=traced.path,
        image_size=tuple(traced.image_size),
        holes=holes,
    )


# ----------------------------------------------------------------------------- report / drawing

def outline_report(traced: TracedOutline) -> dict:
    """Plain-Python, JSON-serialisable summary (``leafsim outline --json``)."""
    r2 = lambda v: [round(float(v[0]), 2), round(float(v[1]), 2)]  # noqa: E731
    return {
        "image": traced.path,
        "size": [int(traced.image_size[0]), int(traced.image_size[1])],
        "points": int(len(traced.contour_px)),
        "area_px": float(traced.area_px),
        "area_fraction": round(float(traced.area_px) / float(traced.image_size[0] * traced.image_size[1]), 5),
        "base": r2(traced.base_px),
        "apex": r2(traced.apex_px),
        "length_px": round(traced.length_px, 2),
        "lobes": [r2(q) for q in traced.lobes_px],
        "base_method": traced.base_method,
        "petiole": None if traced.petiole_px is None else [r2(q) for q in traced.petiole_px],
        "iou": round(float(traced.iou), 5),
        "holes": [round(abs(polygon_area(hp)), 1) for hp in traced.holes_px],
        "petiole_on_blade": traced.petiole_mask is not None,
        "work_scale": round(float(traced.work_scale), 6),
        "border_fraction": round(float(traced.border_fraction), 5),
        "seconds": round(float(traced.seconds), 4),
    }


def draw_outline(traced: TracedOutline, img: np.ndarray, out_png: str | os.PathLike) -> None:
    """Write the photo with the traced contour, base, apex and lobe tips drawn on it.

    The PNG is written atomically (temporary file in the same folder, then ``os.replace``).
    Raises LeafsimError naming ``out_png`` if it cannot be written.
    """
    out = Path(out_png)
    if img.ndim == 2:
        canvas = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    elif img.shape[2] == 4:
        a = img[..., 3:4].astype(np.float32) / 255.0
        canvas = (img[..., :3].astype(np.float32) * a + 128.0 * (1 - a)).astype(np.uint8)
    else:
        canvas = img[..., :3].copy()
    canvas = np.ascontiguousarray(canvas)
    w, h = traced.image_size
    th = max(1, int(round(math.hypot(w, h) / 600)))
    r = 3 * th + 2
    S = 16
    fp = lambda q: (int(round(q[0] * S)), int(round(q[1] * S)))  # noqa: E731
    pts = np.round(traced.contour_px * S).astype(np.int32).reshape(-1, 1, 2)
    cv2.polylines(canvas, [pts], True, (255, 255, 0), th, cv2.LINE_AA, shift=4)
    for hp in traced.holes_px:
        cv2.polylines(canvas, [np.round(hp * S).astype(np.int32).reshape(-1, 1, 2)], True, (255, 0, 255), th, cv2.LINE_AA, shift=4)
    if traced.petiole_px is not None:
        cv2.line(canvas, fp(traced.petiole_px[0]), fp(traced.petiole_px[1]), (255, 0, 255), th, cv2.LINE_AA, shift=4)
    for q in traced.lobes_px:
        cv2.circle(canvas, fp(q), r * S, (0, 200, 255), th + 1, cv2.LINE_AA, shift=4)
    cv2.line(canvas, fp(traced.base_px), fp(traced.apex_px), (255, 255, 255), max(1, th // 2), cv2.LINE_AA, shift=4)
    cv2.circle(canvas, fp(traced.apex_px), (r + 2) * S, (0, 255, 0), -1, cv2.LINE_AA, shift=4)
    cv2.circle(canvas, fp(traced.base_px), (r + 2) * S, (0, 0, 255), -1, cv2.LINE_AA, shift=4)
    write_png_atomic(out, canvas)

