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


def lit_unevenly(img: np.ndarray, low: float, direction=(1.0, 0.0), blue_shadow: bool = False) -> None:
    """Scale the image's brightness in place from ``low`` to 1 along ``direction`` (x, y),
    like a phone photo of a sheet lit from one side; with ``blue_shadow`` the darker side is
    also bluer (lit by the sky)."""
    h, w = img.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    d = np.asarray(direction, np.float32) / np.linalg.norm(direction)
    t = xx / max(w - 1, 1) * d[0] + yy / max(h - 1, 1) * d[1]
    t = (t - t.min()) / max(float(t.max() - t.min()), 1e-6)
    g = (low + (1.0 - low) * t)[..., None]
    tint = np.array([1.0, 0.92, 0.85], np.float32) if blue_shadow else np.ones(3, np.float32)  # BGR
    f = g * (tint + (1.0 - tint) * t[..., None])
    img[:] = np.clip(img.astype(np.float32) * f, 0, 255).astype(np.uint8)


def mask_of(poly: np.ndarray, shape) -> np.ndarray:
    m = np.zeros(shape[:2], np.uint8)
    cv2.fillPoly(m, [np.round(poly * 16).astype(np.int32)], 255, cv2.LINE_8, shift=4)
    return m


def iou(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a > 0, b > 0
    return float(np.count_nonzero(a & b) / max(np.count_nonzero(a | b), 1))


PETIOLE = (120, 150, 200)  # BGR: a pale pinkish petiole, as on the grapevine photo


def _band(img, a, c, b, r0, r1, colour, n=80):
    """A tapering band along the quadratic Bézier a→c→b (radius r0 → r1), drawn as discs."""
    t = np.linspace(0, 1, n)[:, None]
    pts = (1 - t) ** 2 * np.asarray(a, float) + 2 * (1 - t) * t * np.asarray(c, float) + t ** 2 * np.asarray(b, float)
    for p, tt in zip(pts, t[:, 0]):
        r = r0 + (r1 - r0) * tt
        cv2.circle(img, (int(round(p[0] * 16)), int(round(p[1] * 16))), int(round(r * 16)), colour, -1, cv2.LINE_AA, shift=4)


def palmate_fan(base, length, open_deg=150.0, n=400) -> np.ndarray:
    """A five-lobed palmate blade (pixels, y down) whose margin runs into the base from both
    sides: the petiolar sinus ends at the petiole junction."""
    th = np.radians(np.linspace(-open_deg, open_deg, n))
    r = length * (0.6 + 0.4 * np.abs(np.cos(2.5 * th)) ** 2.5) * np.clip((np.radians(open_deg) - np.abs(th)) / 0.5, 0, 1) ** 0.5
    return np.vstack([base, base + np.column_stack([r * np.sin(th), -r * np.cos(th)])])


def overlapping_lobes_photo(size=800, petiole_over=False, flip=False):
    """A grapevine-like leaf whose basal lobes sweep down past the petiole and overlap: the
    petiolar sinus is closed (the paper shows through it, a hole of the blade) and the petiole
    leaves the silhouette far from its junction, under the lobes (``petiole_over`` False) or
    lying on them (True).  ``flip``: base up, as the grapevine photo is stored.

    Returns (BGR image, junction (x, y), apex (x, y), hole centre (x, y))."""
    img = np.zeros((size, size, 3), np.uint8)
    img[:] = PAPER
    base = np.array([0.5, 0.52]) * size
    L = 0.44 * size
    tip = base + np.array([0.0, 0.42]) * size

    def petiole():
        cv2.line(img, tuple(np.round(base * 16).astype(int)), tuple(np.round(tip * 16).astype(int)), PETIOLE,
                 max(2, int(0.016 * size)), cv2.LINE_AA, shift=4)

    if not petiole_over:
        petiole()
    cv2.fillPoly(img, [np.round(palmate_fan(base, L) * 16).astype(np.int32)], (60, 120, 70), cv2.LINE_AA, shift=4)
    for s in (1, -1):  # basal lobes: from the blade's lower margins down across the midline
        th = np.radians(s * 128)
        a = base + 0.30 * L * np.array([np.sin(th), -np.cos(th)])
        _band(img, a, base + np.array([s * 0.32, 0.22]) * L, base + np.array([-s * 0.12, 0.34]) * L, 0.11 * L, 0.07 * L,
              (60, 120, 70))
    if petiole_over:
        petiole()
    apex = base - np.array([0.0, L])
    hole = base + np.array([0.0, 0.15]) * L
    if flip:
        img = np.ascontiguousarray(img[::-1])
        flip_y = lambda q: np.array([q[0], size - 1 - q[1]])  # noqa: E731
        base, apex, hole = flip_y(base), flip_y(apex), flip_y(hole)
    return img, base, apex, hole
