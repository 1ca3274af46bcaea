"""Closed sinuses and a petiole lying on the blade, for the outline tracer (:mod:`leafsim.outline.trace`).

Where two lobes overlap, the background shows through the sinus they close: a *hole* of the
blade, which the model keeps (nothing grows or is meshed inside it).  A petiole lying over
the blade is not blade: its pixels are found by colour (far from the blade's colour, as
wide as a petiole, running from the base away from the apex — a midrib runs toward it);
where blade lies on both sides of it the blade continues under it (its texture is then
inpainted), where it crosses a sinus or sticks out over the background it is background.
A petiole that disappears under overlapping basal lobes is followed into the closed sinus
behind them: its junction with the blade is at the far side of that hole.

All masks are uint8 0/255 in the working image's pixels; points are ``(x, y)``, y down.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from leafsim.base.geometry import polygon_area, resample_closed_keeping
from leafsim.outline.image import edge_contours


def _disk(d: int) -> np.ndarray:
    d = max(1, int(d) | 1)
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (d, d))


def kept_holes(filled: np.ndarray, clean: np.ndarray, min_fraction: float) -> np.ndarray:
    """Holes of the cleaned foreground ``clean`` inside the leaf ``filled`` that cover at least
    ``min_fraction`` of the leaf's area (uint8 0/255 mask)."""
    holes = cv2.bitwise_and(filled, cv2.bitwise_not(clean))
    out = np.zeros_like(filled)
    if not holes.any():
        return out
    n, lab, stats, _ = cv2.connectedComponentsWithStats(holes, connectivity=4)
    big = np.flatnonzero(stats[1:, cv2.CC_STAT_AREA] >= min_fraction * max(np.count_nonzero(filled), 1)) + 1
    if len(big):
        out[np.isin(lab, big)] = 255
    return out


def hole_polygons(holes: np.ndarray, eps: float, spacing: float) -> list[np.ndarray]:
    """Closed polygons (x, y) of the holes, clockwise as seen (positive signed area with y
    down), simplified by Douglas–Peucker ``eps`` and resampled at about ``spacing`` pixels."""
    out = []
    for raw in edge_contours(holes):
        if abs(polygon_area(raw)) < 4.0:
            continue
        simp = cv2.approxPolyDP(raw.astype(np.float32).reshape(-1, 1, 2), eps, True).reshape(-1, 2).astype(np.float64) \
            if eps > 0 else raw
        if len(simp) < 3:
            simp = raw
        perim = float(np.linalg.norm(np.diff(np.vstack([simp, simp[:1]]), axis=0), axis=1).sum())
        poly = resample_closed_keeping(simp, max(12, int(round(perim / max(spacing, 1e-9)))))
        if polygon_area(poly) < 0:
            poly = poly[::-1].copy()
        out.append(poly)
    return out


def _colour_stats(lab: np.ndarray, region: np.ndarray) -> np.ndarray:
    sel = lab[region]
    return np.median(sel[:: max(1, len(sel) // 50000)], axis=0)


def _component_shape(pts: np.ndarray) -> tuple[float, float]:
    """(long, short) side of the minimum-area rectangle around (k, 2) points."""
    (_, _), (a, b), _ = cv2.minAreaRect(pts.astype(np.float32))
    return max(a, b), max(min(a, b), 1.0)


def petiole_band(lab: np.ndarray, filled: np.ndarray, holes: np.ndarray, base, apex, width: float | None) -> np.ndarray | None:
    """Pixels of a petiole lying on the leaf, or None.

    Candidates are leaf pixels whose Lab colour is far from the blade's (more than 3× the
    blade's median spread, at least 10), opened by a disk of 0.7× the petiole width (veins
    are thinner); a candidate component counts when it starts within 6 % of the leaf length
    of the base, is at least 12 % of the leaf length long and 3× longer than wide, and points
    away from the apex (at least 45° off the base→apex direction: a band toward the apex is
    the midrib).  The band is grown back to its full width within the candidates.
    """
    base = np.asarray(base, float)
    apex = np.asarray(apex, float)
    L = float(np.linalg.norm(apex - base))
    if L < 10:
        return None
    inside = filled > 0
    leaf = inside & (holes == 0)
    if np.count_nonzero(leaf) < 100:
        return None
    d = np.linalg.norm(lab - _colour_stats(lab, leaf), axis=2)
    spread = float(np.median(d[leaf]))
    cand = np.where(inside & (holes == 0) & (d > max(10.0, 3.0 * spread)), 255, 0).astype(np.uint8)
    w = float(width) if width else 0.016 * L
    k = max(3, int(round(0.7 * w)))
    core = cv2.morphologyEx(cand, cv2.MORPH_OPEN, _disk(k))
    n, labels, stats, _ = cv2.connectedComponentsWithStats(core, connectivity=8)
    axis = (apex - base) / L
    best, best_area = 0, 0
    for c in range(1, n):
        x, y, bw, bh, area = stats[c]
        if area < 10:
            continue
        ys, xs = np.nonzero(labels[y : y + bh, x : x + bw] == c)
        pts = np.column_stack([xs + x, ys + y]).astype(np.float64)
        r = np.linalg.norm(pts - base, axis=1)
        if r.min() > 0.06 * L:
            continue
        long, short = _component_shape(pts)
        if long < 0.12 * L or long < 3.0 * short:
            continue
        far = pts[int(np.argmax(r))] - base
        if float(far @ axis) > math.cos(math.radians(45.0)) * float(np.linalg.norm(far)):
            continue  # runs toward the apex: the midrib
        if area > best_area:
            best, best_area = c, area
    if not best:
        return None
    band = cv2.bitwise_and(cv2.dilate(np.where(labels == best, 255, 0).astype(np.uint8), _disk(k + 2)), cand)
    return cv2.morphologyEx(band, cv2.MORPH_CLOSE, _disk(3))


def without_band(filled: np.ndarray, holes: np.ndarray, band: np.ndarray, width: float, base) -> tuple[np.ndarray, np.ndarray]:
    """The leaf without a petiole lying on it: (leaf under the band, band pixels that are
    background).  Under the band the blade continues where the first pixel off the band on
    both sides across it (perpendicular to its main direction, within four widths) is blade,
    and within three widths of the base (where the petiole joins the blade, the blade's base
    lies under it); where the band crosses a sinus or the background it is background."""
    leaf = cv2.bitwise_and(filled, cv2.bitwise_not(holes))
    on = band > 0
    rest = (leaf > 0) & ~on
    ys, xs = np.nonzero(on)
    if not len(xs):
        return leaf, np.zeros_like(band)
    pts = np.column_stack([xs, ys]).astype(np.float64)
    c = pts - pts.mean(0)
    n = np.linalg.eigh(c.T @ c)[1][:, 0]  # across the band (its least spread direction)
    H, W = band.shape
    sides = []
    for sgn in (1.0, -1.0):
        found = np.zeros(len(xs), np.int8)  # 0 nothing yet, 1 blade, 2 background
        for k in range(1, int(4 * width) + 2):
            q = np.round(pts + sgn * k * n).astype(int)
            ok = (q[:, 0] >= 0) & (q[:, 0] < W) & (q[:, 1] >= 0) & (q[:, 1] < H)
            qx, qy = np.clip(q[:, 0], 0, W - 1), np.clip(q[:, 1], 0, H - 1)
            todo = found == 0
            found[todo & ok & rest[qy, qx]] = 1
            found[todo & (~ok | (~on[qy, qx] & ~rest[qy, qx]))] = 2
        sides.append(found == 1)
    under = np.zeros_like(band)
    under[ys[sides[0] & sides[1]], xs[sides[0] & sides[1]]] = 255
    near = np.zeros_like(band)
    cv2.circle(near, (int(round(base[0])), int(round(base[1]))), int(round(3.0 * width)) + 2, 255, -1)
    under = cv2.bitwise_or(under, cv2.bitwise_and(band, near))
    out = np.where(rest, 255, 0).astype(np.uint8)
    return cv2.bitwise_or(out, under), cv2.bitwise_and(band, cv2.bitwise_not(under))


def sinus_junction(lab: np.ndarray, filled: np.ndarray, holes: np.ndarray, entry, tip, width: float,
                   length: float, petiole_colour: np.ndarray | None) -> np.ndarray | None:
    """The petiole junction behind overlapping basal lobes, or None.

    The petiole enters the leaf's silhouette at ``entry`` (coming from ``tip``).  When its
    line, continued into the leaf within a corridor of 1.5 petiole widths, reaches a closed
    sinus (a hole) within 35 % of the leaf length, the petiole runs on under the lobes that
    close it: the junction is the farthest pixel of the petiole's colour (``petiole_colour``,
    Lab) along the corridor up to the sinus' far side, or that far side itself when the
    petiole is hidden there too.
    """
    entry = np.asarray(entry, float)
    tip = np.asarray(tip, float)
    v = entry - tip
    if np.linalg.norm(v) < 1e-9 or not holes.any():
        return None
    u = v / np.linalg.norm(v)
    reach, half = 0.35 * length, max(1.5 * width, 3.0)
    end = entry + u * reach
    H, W = filled.shape
    x0, x1 = int(max(0, min(entry[0], end[0]) - half)), int(min(W, max(entry[0], end[0]) + half + 1))
    y0, y1 = int(max(0, min(entry[1], end[1]) - half)), int(min(H, max(entry[1], end[1]) + half + 1))
    if x1 <= x0 or y1 <= y0:
        return None
    ys, xs = np.mgrid[y0:y1, x0:x1]
    rel = np.stack([xs - entry[0], ys - entry[1]], axis=-1)
    s = rel @ u
    corridor = (s >= 0) & (s <= reach) & (np.abs(rel @ np.array([-u[1], u[0]])) <= half)
    hole = holes[y0:y1, x0:x1] > 0
    if not (corridor & hole).any():
        return None
    s_far = float(s[corridor & hole].max())
    if petiole_colour is not None:
        blade = _colour_stats(lab, (filled > 0) & (holes == 0))
        gap = float(np.linalg.norm(np.asarray(petiole_colour) - blade))
        like = np.linalg.norm(lab[y0:y1, x0:x1] - petiole_colour, axis=2) < max(6.0, 0.5 * gap)
        hit = corridor & like & (filled[y0:y1, x0:x1] > 0) & ~hole & (s <= s_far + 1.5 * width)
        if hit.any():
            s_far = max(s_far, float(s[hit].max()))
    return entry + u * s_far
