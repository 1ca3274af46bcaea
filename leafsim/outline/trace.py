"""Leaf outline from a photo or scan (SPEC §1).

Pipeline: :func:`load_image` → :func:`segment_leaf` (alpha, or colour distance to the border
background in Lab + Otsu, morphological clean-up, the largest leaf-like component, holes
filled) → :func:`trace_outline` (outer contour on the pixel edges, Douglas–Peucker, resampling that keeps its corners,
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
from typing import Any, Mapping

import cv2
import numpy as np

from leafsim.base.errors import LeafsimError
from leafsim.base.geometry import LeafShape, polygon_area, resample_closed, resample_closed_keeping
from leafsim.config.params import ParamSet
from leafsim.outline.checks import leafness, problems
from leafsim.outline.holes import hole_polygons, kept_holes, petiole_band, sinus_junction, without_band
from leafsim.outline.image import _disk, _fill_holes, _largest_component, edge_contours, load_image, working_image
from leafsim.outline.landmarks import VEINS_AGAINST, _base_from_shape, _find_petiole, _lobe_tips, vein_direction
from leafsim.outline.segment import HOLE_MIN_FRACTION, segment_with_holes

__all__ = ["TracedOutline", "trace_outline", "to_leaf_shape"]


@dataclass
class TracedOutline:
    """Result of :func:`trace_outline` (all coordinates in photo pixels, y down).

    Attributes
    ----------
    mask : (h, w) uint8 0/255 — the traced leaf region (holes filled, petiole cut off).
    contour_px : (n, 2) float64 — closed outline (first point not repeated) along the mask's
        pixel edges: the Douglas–Peucker corners (tooth tips, notches) kept and the edges
        between them split evenly, starting at the point nearest the base, counter-clockwise *as the photo is seen*
        (i.e. negative signed area in y-down pixel coordinates).
    area_px : float — area of ``mask`` in pixels.
    base_px : (2,) float64 — petiole junction (given, or detected).
    apex_px : (2,) float64 — apex (given, or the contour point farthest from the base).
    lobes_px : (k, 2) float64 — detected lobe tips (the apex tip included), may be empty.
    iou : float — IoU of the rasterised ``contour_px`` polygon with ``mask``.
    image_size : (w, h) of the photo.
    path : str — the photo path as given.
    petiole_px : (2, 2) float64 [junction, tip] of the detected petiole, or None.
    base_method : "given", "petiole", "apex", "shape" or "veins" (how the base was found: given,
        the stalk's junction, the end opposite a given apex, the shape's guess, or that guess
        turned end for end because the photo's side veins open towards the other end:
        :func:`~leafsim.outline.landmarks.vein_direction`).
    vein_direction : that score for the shape's guess (None: not asked, the base was given or found).
    seconds : wall-clock time of the trace.
    work_scale : the photo was traced downscaled by this factor (1.0: at full size); ``mask``
        has the working size, every coordinate is in full-photo pixels.
    border_fraction : share of the image border the traced leaf covers (> 0: the leaf runs
        off the photo and the frame's straight edge is part of the outline).
    border_sides : {"top", "bottom", "left", "right"} → share of that side the leaf covers.
    leafness : the measures of :func:`leafsim.outline.checks.leafness` (is it a whole leaf?).
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
    vein_direction: float | None = None
    seconds: float = 0.0
    work_scale: float = 1.0
    border_fraction: float = 0.0
    border_sides: dict = field(default_factory=dict)
    leafness: dict = field(default_factory=dict)
    holes_px: list = field(default_factory=list)
    hole_mask: np.ndarray | None = None
    petiole_mask: np.ndarray | None = None

    @property
    def length_px(self) -> float:
        """Base–apex distance in pixels."""
        return float(np.linalg.norm(self.apex_px - self.base_px))


# ----------------------------------------------------------------------------- loading


# ----------------------------------------------------------------------------- segmentation


# ----------------------------------------------------------------------------- geometry helpers


# ----------------------------------------------------------------------------- petiole / base


# ----------------------------------------------------------------------------- tracing

def _params(params: Mapping[str, Any] | None) -> ParamSet:
    if params is None:
        return ParamSet()
    if isinstance(params, ParamSet):
        return params
    return ParamSet(params)


def _outer_contour(mask: np.ndarray) -> np.ndarray:
    return max(edge_contours(mask), key=lambda c: abs(polygon_area(c)))


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


#: given base / apex points may lie this far outside the photo, × its larger side (a base just
#: past a cut edge); beyond it they are a typo, not a leaf's base
HINT_SLACK = 0.1
#: given base and apex closer than this [px] name no leaf axis
HINT_MIN_PX = 5.0


class HintError(LeafsimError):
    """A given base / apex point that cannot be the leaf's (``key`` names which, ``detail``
    says why without the photo's path: a species config names its own key)."""

    def __init__(self, where: str, key: str, detail: str):
        super().__init__(f"{where}: {key} {detail}")
        self.key, self.detail = key, detail


def _check_hints(where: str, w: int, h: int, base_px, apex_px) -> None:
    """One line when a given ``base_px`` / ``apex_px`` cannot be the leaf's base and tip in a
    ``w`` × ``h`` photo: far outside it, or the two (nearly) the same point."""
    slack = HINT_SLACK * max(w, h)
    pts = {}
    for name, q in (("base_px", base_px), ("apex_px", apex_px)):
        if q is None:
            continue
        q = np.asarray(q, float).reshape(2)
        if not (np.isfinite(q).all() and -slack <= q[0] <= w - 1 + slack and -slack <= q[1] <= h - 1 + slack):
            raise HintError(where, name, f"({q[0]:g}, {q[1]:g}) lies outside the photo ({w} × {h} px; expected a pixel "
                                         "on the leaf's margin)")
        pts[name] = q
    if len(pts) == 2 and float(np.linalg.norm(pts["base_px"] - pts["apex_px"])) < HINT_MIN_PX:
        raise HintError(where, "apex_px", f"lies {float(np.linalg.norm(pts['base_px'] - pts['apex_px'])):.3g} px from base_px "
                                          "(expected the leaf's tip, away from its base)")


def trace_outline(path: str | os.PathLike, params: Mapping[str, Any] | None = None,
                  base_px=None, apex_px=None) -> TracedOutline:
    """Trace the outline of the one leaf in the photo at ``path`` (with the leafness measures
    of :mod:`leafsim.outline.checks`; :func:`refuse_non_leaf` turns them into an error).

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
    _check_hints(where, w, h, base_px, apex_px)
    img, f = working_image(full, int(p["limits.image_pixels"]))
    del full
    to_work = lambda q: None if q is None else (np.asarray(q, float).reshape(2) + 0.5) * f - 0.5  # noqa: E731
    t = _trace(img, p, where, to_work(base_px), to_work(apex_px))
    t.leafness = leafness(t, img)
    t.leafness["size_px"] /= f  # the leaf's length in the photo's own pixels
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
    method = ("given" if base_px is not None else "petiole" if b.junction is not None
              else "apex" if apex_px is not None else "shape")
    if base_px is not None:
        base = np.asarray(base_px, float).reshape(2)
    elif b.junction is not None:
        near = dense[int(np.argmin(np.linalg.norm(dense - b.junction, axis=1)))]
        # on the margin, or on a sinus behind overlapping lobes (inside the silhouette)
        base = near.copy() if np.linalg.norm(near - b.junction) < 2.0 * (b.width or 1.0) + 2.0 else b.junction.copy()
    elif apex_px is not None:  # the end opposite the given apex (the shape's guess could be the apex itself)
        base = dense[int(np.argmax(np.linalg.norm(dense - np.asarray(apex_px, float).reshape(2), axis=1)))].copy()
    else:
        base = _base_from_shape(dense, b.mask, L_est)
    apex0 = np.asarray(apex_px, float).reshape(2) if apex_px is not None else dense[int(np.argmax(np.linalg.norm(dense - base, axis=1)))]
    veins_say = None
    if method == "shape":  # the shape's guess (the blunter end) turns an obovate leaf upside down: ask the veins
        veins_say = vein_direction(img, b.mask, base, apex0)
        if veins_say < VEINS_AGAINST:
            base, method = apex0.copy(), "veins"
            apex0 = dense[int(np.argmax(np.linalg.norm(dense - base, axis=1)))]
    _lay_petiole_off(b, lab, base, apex0)
    if b.band is not None:
        simp, dense = _polygon(b.mask, eps)
    n = int(p["outline.points"])
    contour = resample_closed_keeping(_start_at(simp, base), n)
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
        path=where, petiole_px=b.petiole, base_method=method, vein_direction=veins_say,
        border_fraction=float(np.mean(np.concatenate([mask[0], mask[-1], mask[1:-1, 0], mask[1:-1, -1]]) > 0)),
        border_sides={side: float(np.mean(edge > 0)) for side, edge in
                      (("top", mask[0]), ("bottom", mask[-1]), ("left", mask[:, 0]), ("right", mask[:, -1]))},
        holes_px=hole_polygons(b.holes, eps, perim / n), hole_mask=b.holes, petiole_mask=b.band,
    )


def refuse_non_leaf(traced: TracedOutline) -> list[str]:
    """LeafsimError (one line naming the photo) when the traced object is not a whole leaf (cut
    by the image border, the background, a rectangle); returns the warnings of the checks that
    only warn."""
    found = problems(traced.leafness) if traced.leafness else []
    for level, text in found:
        if level == "refuse":
            raise LeafsimError(f"{traced.path}: {text}")
    return [text for level, text in found]


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


