"""Synthetic leaf photos drawn with cv2 for the outline tests (no binary test files).

Every drawing is defined in units of the image size, so the same leaf can be drawn at any
resolution; :func:`leaf_polygon` gives the blade outline (pixels) to compare against.
"""

from __future__ import annotations

import cv2
import numpy as np

GREEN = (40, 140, 60)  # BGR
PAPER = (235, 240, 245)


def leaf_polygon(size: int, centre=(0.5, 0.45), length=0.62, width=0.36, angle=0.0, obovate=False, n=360) -> np.ndarray:
    """(n, 2) pixel outline of an ovate blade: base at the bottom, apex at the top (angle 0).

    ``centre``, ``length`` and ``width`` are fractions of ``size``; ``angle`` in degrees
    rotates the leaf about its centre (counter-clockwise as seen); ``obovate``: widest toward
    the apex, tapering into the petiole (its shape alone suggests the wrong end as base).
    """
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    y = -np.cos(t)  # -1 base ... +1 apex
    g = (1 + (0.5 if obovate else -0.35) * y) * (1 - y**8) ** 0.5
    x = np.sin(t) * g / g.max() * 0.5 * width
    pts = np.column_stack([x, 0.5 * length * y])
    a = np.radians(angle)
    R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    pts = pts @ R.T
    pts[:, 1] *= -1  # y down
    return (pts + np.asarray(centre)) * size


def petiole_line(size: int, centre=(0.5, 0.45), length=0.62, angle=0.0, petiole=0.16, width=0.012):
    """(junction, tip, thickness) of the petiole in pixels, continuing the axis below the base."""
    a = np.radians(angle)
    down = np.array([np.sin(a), np.cos(a)])  # toward the base, y down
    base = (np.asarray(centre) + down * 0.5 * length) * size
    tip = base + down * petiole * size
    return base, tip, max(1, int(round(width * size)))


def draw_leaf(img: np.ndarray, colour=GREEN, petiole=0.16, petiole_width=0.012, **kw) -> np.ndarray:
    """Draw one leaf (blade + petiole) into ``img`` in place; returns the blade polygon."""
    size = img.shape[0]
    poly = leaf_polygon(size, **kw)
    cv2.fillPoly(img, [np.round(poly * 16).astype(np.int32)], colour, cv2.LINE_AA, shift=4)
    if petiole > 0:
        geo = {k: v for k, v in kw.items() if k in ("centre", "length", "angle")}
        b, t, th = petiole_line(size, petiole=petiole, width=petiole_width, **geo)
        b = b + (t - b) * -0.05  # start a little inside the blade
        cv2.line(img, tuple(np.round(b * 16).astype(int)), tuple(np.round(t * 16).astype(int)), colour, th, cv2.LINE_AA, shift=4)
    return poly


def photo(size: int, bg=PAPER, shadow: float = 0.0, **kw) -> tuple[np.ndarray, np.ndarray]:
    """A square photo of one leaf on a plain background; returns (BGR image, blade polygon).

    ``shadow`` > 0 casts the leaf's shadow (offset by that fraction of the size, down-right)
    onto the background first: the background colour darker and less saturated, soft-edged.
    """
    img = np.zeros((size, size, 3), np.uint8)
    img[:] = bg
    if shadow > 0:
        poly = leaf_polygon(size, **{k: v for k, v in kw.items() if k in ("centre", "length", "width", "angle", "obovate")})
        cast_shadow(img, poly + shadow * size * np.array([1.0, 0.8]), bg)
    return img, draw_leaf(img, **kw)


def cast_shadow(img: np.ndarray, poly: np.ndarray, bg=PAPER, darken=0.55, blur=0.012) -> None:
    """Darken the background under ``poly`` in place as a soft shadow (lower value and
    saturation: the background colour mixed toward its grey, times ``darken``)."""
    size = img.shape[0]
    m = np.zeros(img.shape[:2], np.uint8)
    cv2.fillPoly(m, [np.round(poly * 16).astype(np.int32)], 255, cv2.LINE_AA, shift=4)
    k = max(3, int(blur * size) | 1)
    a = cv2.GaussianBlur(m, (k, k), 0).astype(np.float32)[..., None] / 255.0
    bgf = np.asarray(bg, np.float32)
    shade = darken * (0.6 * bgf + 0.4 * bgf.mean())
    img[:] = np.clip(img.astype(np.float32) * (1 - a) + shade * a, 0, 255).astype(np.uint8)


def mask_of(poly: np.ndarray, shape) -> np.ndarray:
    m = np.zeros(shape[:2], np.uint8)
    cv2.fillPoly(m, [np.round(poly * 16).astype(np.int32)], 255, cv2.LINE_8, shift=4)
    return m


def iou(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a > 0, b > 0
    return float(np.count_nonzero(a & b) / max(np.count_nonzero(a | b), 1))
