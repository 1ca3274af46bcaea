"""Model against photograph (``leafsim compare``): alignment and metrics, no OpenGL here.

Both sides are brought into one *comparison frame*: world metres of the model (base at the
origin, apex on +y) mapped to canvas pixels, apex up, at the photo's own resolution (the
photo's traced leaf length in pixels per ``length_m``), so the photo is only turned and
shifted, never resampled in scale.  A photo enters the frame through its traced outline's
similarity transform (:func:`leafsim.outline.trace.to_leaf_shape`); a second photo of another leaf
(a senescent reference) is aligned base→apex and scaled to the same leaf length.

Metrics (:func:`compare_images`):

* **IoU** of the silhouettes, holes (closed sinuses) counted as background on both sides and
  a petiole cut off / lying on the blade not counted as blade.
* **Margin length** (:func:`margin_length`): the length of the 50 % iso-line of the
  silhouette after a Gaussian blur of σ = 0.2 % of the leaf length (at least 0.7 px), traced
  on a 2× upsampled grid and simplified by ½ px, outer margin plus the hole margins; the same
  definition on both masks, at the same resolution.  The ratio is model / photo.
* **Colour** (:func:`colour_classes`): every blade pixel's CIE Lab colour (sRGB, D65) is put
  in one of eight classes — dark (L* < 18, or L* < 35 with chroma C* < 12: necrotic), grey
  (C* < 8 or a bluish hue 200–270°), brown (hue 45–105° with L* < 52 or C* < 0.45 L*), then
  by hue angle green (105–200°), yellow (70–105°), orange (45–70°), red (0–45°) and purple
  (270–360°: red and purple part at 0°, about halfway between sRGB red, 40°, and magenta, 328°).  The class fractions of photo and model and their total-variation
  distance ½ Σ |p − q| (0 = same mix, 1 = nothing in common); also the total-variation
  distances of the L* histogram (10 bins) and of the hue histogram (18 bins of 20°, pixels
  with C* ≥ 8).
* **Spread** (:func:`colour_spread`): the within-leaf variation — circular spread of the hue,
  spread of L*, and the dark spots (count, median diameter / L, share of the blade) — of photo and model, and
  the model / photo ratios.
* **Vein offset** (:func:`vein_offset`): the photo's own veins traced
  (:mod:`leafsim.outline.venation`) against the model's: how far, along every traced midrib,
  main vein and lateral, the nearest model vein is (mean, 90th percentile; px and × L).
* **Veins** (:func:`vein_agreement`): light or dark lines of the photo's lightness at the
  scale of the main and lateral veins (Hessian eigenvalue across the line less the one along
  it, σ = 0.4 % of the leaf length, so that spots and speckles are no ridge), as
  many ridge pixels as the model's main and lateral veins cover; precision = share of model
  vein pixels within 1.5 % of the leaf length of a photo ridge, recall = share of photo ridge
  pixels that close to a model vein, each with its chance level (the share of the blade that
  close to the other pattern: what randomly placed veins would score).  Not measurable (None)
  when the photo shows no ridges (the strongest ridge pixels under 3× the blade's mean
  response).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from leafsim.base.geometry import LeafShape

#: colour classes, in the order of every fraction array
CLASSES = ("green", "yellow", "orange", "red", "purple", "brown", "dark", "grey")
#: display colour (RGB) of each class in montages
CLASS_RGB = np.array([(70, 150, 60), (230, 205, 40), (240, 140, 30), (200, 30, 30), (150, 50, 160),
                      (120, 80, 45), (25, 25, 25), (170, 170, 170)], np.uint8)


# ----------------------------------------------------------------------------- frame

@dataclass(frozen=True)
class Frame:
    """World metres → canvas pixels: ``u = (x − x0)·scale``, ``v = (y1 − y)·scale``."""

    scale: float
    x0: float
    y1: float
    width: int
    height: int

    def to_px(self, pts) -> np.ndarray:
        p = np.asarray(pts, float).reshape(-1, 2)
        return np.column_stack([(p[:, 0] - self.x0) * self.scale, (self.y1 - p[:, 1]) * self.scale])

    @property
    def centre(self) -> np.ndarray:
        """World point at the canvas centre."""
        return np.array([self.x0 + 0.5 * self.width / self.scale, self.y1 - 0.5 * self.height / self.scale])

    def photo_affine(self, shape: LeafShape) -> np.ndarray:
        """(2, 3) affine map from ``shape``'s photo pixels to canvas pixels."""
        A = np.asarray(shape.px_to_world, float)
        S = np.array([[self.scale, 0.0, -self.x0 * self.scale], [0.0, -self.scale, self.y1 * self.scale]])
        return S[:, :2] @ A[:, :2], S[:, :2] @ A[:, 2] + S[:, 2]


def frame_for(shape: LeafShape, pad: float = 0.06, max_side: int = 1400, scale: float | None = None) -> Frame:
    """A frame holding ``shape``'s outline with ``pad`` × length of room on every side, at the
    photo's resolution (or ``scale`` px/m), shrunk so that no side exceeds ``max_side``."""
    if scale is None:
        if shape.image_size is not None:
            scale = 1.0 / math.sqrt(abs(np.linalg.det(np.asarray(shape.px_to_world, float)[:, :2])))
        else:
            scale = 900.0 / shape.length
    lo = shape.contour.min(0) - pad * shape.length
    hi = shape.contour.max(0) + pad * shape.length
    scale = min(scale, max_side / float(max(hi - lo)))
    w, h = int(math.ceil((hi[0] - lo[0]) * scale)), int(math.ceil((hi[1] - lo[1]) * scale))
    return Frame(float(scale), float(lo[0]), float(hi[1]), w, h)


# ----------------------------------------------------------------------------- photo side

@dataclass
class Reference:
    """A photo in the comparison frame.

    rgb : (H, W, 3) uint8 the photo (RGB; white where the photo has no pixels or is transparent).
    blade : (H, W) bool the blade silhouette: holes are background, a petiole is no blade.
    colour : (H, W) bool pixels for the colour statistics (the blade 2 px inside its margin,
        without a petiole lying on it).
    shape : the photo's own traced outline in metres.
    path : the photo.
    """

    rgb: np.ndarray
    blade: np.ndarray
    colour: np.ndarray
    shape: LeafShape
    path: str


def _warp_mask(mask: np.ndarray, M: np.ndarray, frame: Frame, work_scale: float) -> np.ndarray:
    """A working-size mask (0/255) warped into the frame (bool), by area coverage ≥ ½."""
    f = float(work_scale)
    W = np.array([[1.0 / f, 0.0, 0.5 / f - 0.5], [0.0, 1.0 / f, 0.5 / f - 0.5], [0.0, 0.0, 1.0]])  # working → photo px
    Mw = np.vstack([M, [0.0, 0.0, 1.0]]) @ W
    out = cv2.warpAffine(mask.astype(np.float32) / 255.0, Mw[:2], (frame.width, frame.height), flags=cv2.INTER_LINEAR,
                         borderValue=0.0)
    return out >= 0.5


def reference(traced, shape: LeafShape, frame: Frame) -> Reference:
    """The photo of ``traced`` (a :class:`~leafsim.outline.trace.TracedOutline`) and its masks in
    ``frame``; ``shape`` is its outline in metres (``to_leaf_shape(traced, length)``)."""
    from leafsim.outline.image import load_image

    img = load_image(traced.path)
    if img.shape[2] == 4:
        a = img[..., 3:4].astype(np.float32) / 255.0
        img = (img[..., :3].astype(np.float32) * a + 255.0 * (1.0 - a)).astype(np.uint8)
    A, t = frame.photo_affine(shape)
    M = np.hstack([A, t[:, None]])
    rgb = cv2.warpAffine(cv2.cvtColor(np.ascontiguousarray(img[..., :3]), cv2.COLOR_BGR2RGB), M, (frame.width, frame.height),
                         flags=cv2.INTER_AREA, borderValue=(255, 255, 255))
    blade_work = traced.mask if traced.hole_mask is None else cv2.bitwise_and(traced.mask, cv2.bitwise_not(traced.hole_mask))
    blade = _warp_mask(blade_work, M, frame, traced.work_scale)
    colour = cv2.erode(blade.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    if traced.petiole_mask is not None:
        colour &= ~_warp_mask(cv2.dilate(traced.petiole_mask, np.ones((5, 5), np.uint8)), M, frame, traced.work_scale)
    return Reference(rgb, blade, colour, shape, str(traced.path))


# ----------------------------------------------------------------------------- metrics

def silhouette_iou(a: np.ndarray, b: np.ndarray) -> float:
    a, b = np.asarray(a, bool), np.asarray(b, bool)
    union = np.count_nonzero(a | b)
    return float(np.count_nonzero(a & b) / union) if union else 0.0


def margin_length(mask: np.ndarray, length_px: float) -> float:
    """Length [px] of the silhouette's margin, outer and hole margins (module docstring)."""
    sigma = max(0.002 * float(length_px), 0.7)
    f = cv2.GaussianBlur(np.asarray(mask, np.float32), (0, 0), sigma)
    up = cv2.resize(f, None, fx=2, fy=2, interpolation=cv2.INTER_LINEAR) >= 0.5
    cnts, _ = cv2.findContours(up.astype(np.uint8), cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    total = 0.0
    for c in cnts:
        if cv2.contourArea(c) >= (0.02 * length_px) ** 2:  # specks are no margin
            total += cv2.arcLength(cv2.approxPolyDP(c, 1.0, True), True)
    return total / 2.0


def _lab(rgb: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(np.ascontiguousarray(rgb, np.uint8).astype(np.float32) / 255.0, cv2.COLOR_RGB2Lab)


def classify_lab(lab: np.ndarray) -> np.ndarray:
    """Class index (into :data:`CLASSES`) of every Lab colour (module docstring)."""
    L, a, b = lab[..., 0], lab[..., 1], lab[..., 2]
    C = np.hypot(a, b)
    h = np.degrees(np.arctan2(b, a)) % 360.0
    out = np.full(L.shape, 7, np.int8)
    dark = (L < 18) | ((L < 35) & (C < 12))
    grey = ~dark & ((C < 8) | ((h >= 200) & (h < 270)))
    rest = ~dark & ~grey
    brown = rest & (h >= 45) & (h < 105) & ((L < 52) | (C < 0.45 * L))
    hue = rest & ~brown
    out[hue & (h >= 105) & (h < 200)] = 0
    out[hue & (h >= 70) & (h < 105)] = 1
    out[hue & (h >= 45) & (h < 70)] = 2
    out[hue & (h < 45)] = 3
    out[hue & (h >= 270)] = 4
    out[brown] = 5
    out[dark] = 6
    return out


def colour_classes(rgb: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(8,) fractions of the masked pixels in each of :data:`CLASSES`."""
    m = np.asarray(mask, bool)
    if not m.any():
        return np.zeros(len(CLASSES))
    c = classify_lab(_lab(rgb)[m])
    return np.bincount(c, minlength=len(CLASSES)) / float(m.sum())


def colour_histograms(rgb: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(L* histogram, 10 bins over 0–100; hue histogram, 18 bins of 20°, pixels with C* ≥ 8),
    each normalised to sum 1 (zeros when empty)."""
    lab = _lab(rgb)[np.asarray(mask, bool)]
    hl = np.histogram(lab[:, 0], bins=10, range=(0, 100))[0].astype(float)
    C = np.hypot(lab[:, 1], lab[:, 2])
    h = np.degrees(np.arctan2(lab[:, 2], lab[:, 1])) % 360.0
    hh = np.histogram(h[C >= 8], bins=18, range=(0, 360))[0].astype(float)
    return hl / max(hl.sum(), 1.0), hh / max(hh.sum(), 1.0)


def total_variation(p, q) -> float:
    """½ Σ |p − q| of two distributions."""
    return 0.5 * float(np.abs(np.asarray(p, float) - np.asarray(q, float)).sum())


def colour_spread(rgb: np.ndarray, mask: np.ndarray, length_px: float) -> dict:
    """Within-leaf colour variation of the masked pixels: the circular spread of the CIELAB hue
    (degrees, pixels with C* ≥ 8), the spread of L*, and the dark spots — connected regions at
    least 15 L* darker than the blade's median and at least (0.01 L)² large: their count,
    median equivalent diameter over L, and the share of the blade they cover (``dark_share``:
    steadier than the count, which a streak broken in two doubles)."""
    m = np.asarray(mask, bool)
    if not m.any():
        return {"hue_sd_deg": None, "lightness_sd": None, "spots": 0, "spot_diameter_L": None, "dark_share": None}
    lab = _lab(rgb)
    px = lab[m]
    C = np.hypot(px[:, 1], px[:, 2])
    z = np.exp(1j * np.arctan2(px[C >= 8, 2], px[C >= 8, 1]))
    R = float(abs(z.mean())) if z.size else 0.0
    hue_sd = float(np.degrees(np.sqrt(-2.0 * np.log(min(max(R, 1e-12), 1.0))))) if z.size else None
    dark = (m & (lab[..., 0] < float(np.median(px[:, 0])) - 15.0)).astype(np.uint8)
    n, _, stats, _ = cv2.connectedComponentsWithStats(dark, connectivity=8)
    areas = stats[1:, cv2.CC_STAT_AREA] if n > 1 else np.zeros(0)
    areas = areas[areas >= (0.01 * length_px) ** 2]
    return {"hue_sd_deg": None if hue_sd is None else round(hue_sd, 2), "lightness_sd": round(float(px[:, 0].std()), 2),
            "spots": int(areas.size),
            "spot_diameter_L": round(float(np.median(np.sqrt(4.0 * areas / np.pi))) / length_px, 4) if areas.size else None,
            "dark_share": round(float(areas.sum()) / float(m.sum()), 4)}


def mean_lab(rgb: np.ndarray, mask: np.ndarray) -> np.ndarray:
    return _lab(rgb)[np.asarray(mask, bool)].mean(axis=0)


def ridges(rgb: np.ndarray, mask: np.ndarray, sigma: float) -> np.ndarray:
    """Ridge strength (light or dark lines, whichever the photo shows more of) of the
    lightness at scale ``sigma`` px, 0 outside ``mask``; outside the mask the lightness is
    the blade's median, so the margin itself is no ridge.  The curvature along a ridge is
    taken off the one across it: a spot, curved both ways, is no line (the hornbeam photo's
    dark speckles and the aspen photo's light ones counted as veins before)."""
    m = np.asarray(mask, bool)
    L = _lab(rgb)[..., 0]
    L = cv2.GaussianBlur(np.where(m, L, float(np.median(L[m])) if m.any() else 0.0).astype(np.float32), (0, 0), sigma)
    xx = cv2.Sobel(L, cv2.CV_32F, 2, 0, ksize=3)
    yy = cv2.Sobel(L, cv2.CV_32F, 0, 2, ksize=3)
    xy = cv2.Sobel(L, cv2.CV_32F, 1, 1, ksize=3)
    root = np.sqrt(0.25 * (xx - yy) ** 2 + xy ** 2)
    lo, hi = 0.5 * (xx + yy) - root, 0.5 * (xx + yy) + root
    light = np.where(m, np.maximum(-lo - np.abs(hi), 0), 0)
    dark = np.where(m, np.maximum(hi - np.abs(lo), 0), 0)
    return light if light.sum() >= dark.sum() else dark


def vein_agreement(photo_rgb: np.ndarray, blade: np.ndarray, model_veins: np.ndarray, length_px: float) -> dict | None:
    """Overlap of the model's main and lateral veins (``model_veins``, 1-px lines in the frame)
    with the photo's ridges (module docstring), or None when the photo shows none."""
    sigma = max(0.004 * length_px, 1.2)
    e = 2 * int(math.ceil(3 * sigma)) + 1
    inner = cv2.erode(np.asarray(blade, np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (e, e))) > 0
    mv = np.asarray(model_veins, bool) & inner
    k = int(np.count_nonzero(mv))
    if k < 20 or not inner.any():
        return None
    R = ridges(photo_rgb, inner, sigma)
    vals = R[inner]
    thr = np.partition(vals, len(vals) - k)[len(vals) - k]
    pv = inner & (R >= thr) & (R > 0)
    # a blade without ridges: the line measure is 0 on most of a blade, so the strongest pixels
    # are held against its mean, not its median (top pixels / blade mean: 6.2 hornbeam to 17.9
    # grapevine on the shipped photos, 5.5 on pure noise; a weak guard, for featureless blades)
    if not pv.any() or float(R[pv].mean()) < 3.0 * max(float(vals.mean()), 1e-9):
        return None
    tol = 0.015 * length_px
    d_photo = cv2.distanceTransform(np.where(pv, 0, 255).astype(np.uint8), cv2.DIST_L2, 5)
    d_model = cv2.distanceTransform(np.where(mv, 0, 255).astype(np.uint8), cv2.DIST_L2, 5)
    prec = float(np.mean(d_photo[mv] <= tol))
    rec = float(np.mean(d_model[pv] <= tol))
    return {
        "precision": round(prec, 3), "recall": round(rec, 3),
        "f1": round(2 * prec * rec / max(prec + rec, 1e-9), 3),
        "chance_precision": round(float(np.mean(d_photo[inner] <= tol)), 3),
        "chance_recall": round(float(np.mean(d_model[inner] <= tol)), 3),
        "tolerance_px": round(tol, 1), "veins": "main+lateral",
    }


def vein_offset(photo_lines, model_lines, frame: Frame, length_px: float) -> dict | None:
    """How far the model's veins sit from the photo's traced veins (both lists of world
    polylines, the midrib first): along every photo vein, the distance to the nearest model vein
    of the same kind (main or lateral) — mean and 90th percentile in px and over L — and the
    midrib's mean distance alone.  None without traced veins."""
    if not photo_lines or not model_lines:
        return None
    dt = cv2.distanceTransform(np.where(vein_mask(model_lines, frame), 0, 255).astype(np.uint8), cv2.DIST_L2, 5)

    def along(lines):
        out = []
        for pts in lines:
            q = frame.to_px(pts)
            seg = np.linalg.norm(np.diff(q, axis=0), axis=1)
            s = np.r_[0.0, np.cumsum(seg)]
            t = np.arange(0.0, s[-1], 1.0)
            x, y = np.interp(t, s, q[:, 0]), np.interp(t, s, q[:, 1])
            ok = (x >= 0) & (y >= 0) & (x < frame.width - 0.5) & (y < frame.height - 0.5)
            out.append(dt[np.round(y[ok]).astype(int), np.round(x[ok]).astype(int)])
        return np.concatenate(out) if out else np.zeros(0)

    d, mid = along(photo_lines), along(photo_lines[:1])
    if not d.size:
        return None
    L = max(float(length_px), 1e-9)
    return {"mean_px": round(float(d.mean()), 2), "p90_px": round(float(np.percentile(d, 90)), 2),
            "mean_L": round(float(d.mean()) / L, 4), "p90_L": round(float(np.percentile(d, 90)) / L, 4),
            "midrib_mean_px": round(float(mid.mean()), 2) if mid.size else None,
            "midrib_mean_L": round(float(mid.mean()) / L, 4) if mid.size else None}


def vein_mask(lines, frame: Frame) -> np.ndarray:
    """1-px lines (bool, frame size) of world polylines ``lines`` ((k, 2) arrays)."""
    out = np.zeros((frame.height, frame.width), np.uint8)
    for pts in lines:
        if len(pts) > 1:
            q = np.round(frame.to_px(pts) * 16).astype(np.int32).reshape(-1, 1, 2)
            cv2.polylines(out, [q], False, 255, 1, cv2.LINE_8, shift=4)
    return out > 0


def compare_images(ref: Reference, model_rgb: np.ndarray, model_mask: np.ndarray, model_veins: np.ndarray | None,
                   length_px: float) -> dict:
    """Every metric of the module docstring for one photo and one model picture (both in the
    same frame); JSON-serialisable."""
    model_colour = cv2.erode(np.asarray(model_mask, np.uint8), np.ones((5, 5), np.uint8)) > 0
    fp, fm = colour_classes(ref.rgb, ref.colour), colour_classes(model_rgb, model_colour)
    (lp, hp), (lm, hm) = colour_histograms(ref.rgb, ref.colour), colour_histograms(model_rgb, model_colour)
    mp, mm = margin_length(ref.blade, length_px), margin_length(model_mask, length_px)
    de = float(np.linalg.norm(mean_lab(ref.rgb, ref.colour) - mean_lab(model_rgb, model_colour))) \
        if model_colour.any() and ref.colour.any() else None
    sp, sm = colour_spread(ref.rgb, ref.colour, length_px), colour_spread(model_rgb, model_colour, length_px)

    def ratio(key):
        return round(sm[key] / sp[key], 3) if sp[key] and sm[key] is not None else None
    return {
        "iou": round(silhouette_iou(ref.blade, model_mask), 4),
        "margin_photo_px": round(mp, 1), "margin_model_px": round(mm, 1),
        "margin_ratio": round(mm / mp, 4) if mp > 0 else None,
        "colour_photo": {c: round(float(v), 4) for c, v in zip(CLASSES, fp)},
        "colour_model": {c: round(float(v), 4) for c, v in zip(CLASSES, fm)},
        "colour_tv": round(total_variation(fp, fm), 4),
        "lightness_tv": round(total_variation(lp, lm), 4),
        "hue_tv": round(total_variation(hp, hm), 4),
        "mean_delta_e": None if de is None else round(de, 2),
        "spread_photo": sp, "spread_model": sm,
        "spread_ratio": {"hue": ratio("hue_sd_deg"), "lightness": ratio("lightness_sd")},
        "veins": None if model_veins is None else vein_agreement(ref.rgb, ref.blade, model_veins, length_px),
    }


# ----------------------------------------------------------------------------- montage

def _bar(fr: np.ndarray, width: int, height: int) -> np.ndarray:
    """A horizontal stacked bar of class fractions (RGB)."""
    bar = np.full((height, width, 3), 255, np.uint8)
    x = 0.0
    for k, f in enumerate(fr):
        x1 = x + float(f) * width
        bar[:, int(round(x)):int(round(x1))] = CLASS_RGB[k]
        x = x1
    return bar


def _text(img: np.ndarray, lines, x: int, y: int, scale: float = 0.5) -> None:
    for i, line in enumerate(lines):
        cv2.putText(img, line, (x, y + i * int(22 * scale / 0.5)), cv2.FONT_HERSHEY_SIMPLEX, scale, (20, 20, 20), 1, cv2.LINE_AA)


def _wrap(lines, width: int, scale: float = 0.5) -> list[str]:
    """``lines`` broken at spaces so that each fits ``width`` pixels (the montage's long notes ran
    off its right edge: "...model magent", "...frame 4100, top-")."""
    out = []
    for line in lines:
        words, cur = line.split(" "), ""
        for w in words:
            trial = w if not cur else f"{cur} {w}"
            if cur and cv2.getTextSize(trial, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)[0][0] > width:
                out.append(cur)
                cur = "  " + w
            else:
                cur = trial
        out.append(cur)
    return out


def _overlay(ref: Reference, picture: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Photo and model half and half, the photo's margin in cyan, the model's in magenta."""
    out = (0.5 * ref.rgb.astype(np.float32) + 0.5 * picture.astype(np.float32)).astype(np.uint8)
    for m, col in ((ref.blade, (0, 170, 230)), (mask, (230, 0, 200))):
        cnts, _ = cv2.findContours(np.asarray(m, np.uint8), cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
        cv2.drawContours(out, cnts, -1, col, max(1, out.shape[0] // 400), cv2.LINE_AA)
    return out


def _row_lines(row: dict) -> list[str]:
    st = row["stage"]
    v = row["veins"]
    veins = (f"veins (main+lateral) precision {v['precision']:.2f} (chance {v['chance_precision']:.2f}), recall "
             f"{v['recall']:.2f} (chance {v['chance_recall']:.2f})") if v else "veins: not measurable"
    ratio = "n/a" if row["margin_ratio"] is None else f"{row['margin_ratio']:.3f}"
    return [f"{row['kind']}: model frame {st['frame']} ({st['water'] * 100:.0f} % water) vs {Path(row['reference']).name}",
            f"IoU {row['iou']:.4f}   margin model/photo {ratio}   colour TV {row['colour_tv']:.3f}   "
            f"lightness TV {row['lightness_tv']:.3f}   hue TV {row['hue_tv']:.3f}   mean dE {row['mean_delta_e']}",
            veins, row.get("note") or ""]


def montage(report: dict, rows, height: int = 460) -> np.ndarray:
    """The comparison as one RGB picture: per row photo | model | overlay, the metrics and the
    colour classes of photo and model as stacked bars (legend at the bottom)."""
    blocks = []
    for row, meta in zip(rows, report["rows"]):
        panels = [row.ref.rgb, row.picture, _overlay(row.ref, row.picture, row.mask)]
        f = height / float(panels[0].shape[0])
        panels = [cv2.resize(p, (int(round(p.shape[1] * f)), height), interpolation=cv2.INTER_AREA) for p in panels]
        gap = np.full((height, 10, 3), 255, np.uint8)
        pics = np.hstack([panels[0], gap, panels[1], gap, panels[2]])
        W = pics.shape[1]
        lines = _wrap(_row_lines(meta), W - 16)
        top = 22 * len(lines) + 12  # the bars below the text, however many lines it took
        info = np.full((top + 50, W, 3), 255, np.uint8)
        _text(info, lines, 8, 22)
        fp = np.array([meta["colour_photo"][c] for c in CLASSES])
        fm = np.array([meta["colour_model"][c] for c in CLASSES])
        bw = W - 90
        info[top:top + 14, 80:80 + bw] = _bar(fp, bw, 14)
        info[top + 22:top + 36, 80:80 + bw] = _bar(fm, bw, 14)
        _text(info, ["photo", "model"], 8, top + 12, 0.42)
        blocks.append(np.vstack([pics, info]))
    W = max(b.shape[1] for b in blocks)
    blocks = [np.hstack([b, np.full((b.shape[0], W - b.shape[1], 3), 255, np.uint8)]) for b in blocks]
    legend = np.full((40, W, 3), 255, np.uint8)
    x = 8
    for k, c in enumerate(CLASSES):
        legend[12:28, x:x + 16] = CLASS_RGB[k]
        _text(legend, [c], x + 20, 25, 0.45)
        x += 30 + 11 * len(c)
    title = _wrap([f"leafsim compare --species {report['species']} (seed {report['seed']}): photo | model top-down | overlay "
                   "(photo margin cyan, model magenta)"], W - 16, 0.55)
    head = np.full((12 + 24 * len(title), W, 3), 255, np.uint8)
    _text(head, title, 8, 24, 0.55)
    return np.vstack([head, *blocks, legend])
