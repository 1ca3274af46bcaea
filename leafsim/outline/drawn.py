"""Outlines drawn in a species config (leaf-normalised points): Chaikin smoothing and margin
teeth, for species without a licensed photo."""

from __future__ import annotations

import numpy as np

from leafsim.config.species import Species


def chaikin(pts: np.ndarray, passes: int, pin: np.ndarray | None = None) -> np.ndarray:
    """Chaikin corner cutting of a closed polygon (rounds corners, keeps the shape).

    A vertex equal to ``pin`` (the petiole junction) is kept exactly, so the base stays on
    the contour.
    """
    for _ in range(passes):
        q = np.roll(pts, -1, axis=0)
        a = 0.75 * pts + 0.25 * q
        b = 0.25 * pts + 0.75 * q
        out = np.empty((2 * len(a), 2))
        out[0::2] = a
        out[1::2] = b
        if pin is not None:
            hit = np.flatnonzero(np.linalg.norm(pts - pin, axis=1) < 1e-12)
            for i in hit[::-1]:
                # vertex i's corner is cut by b[i-1] and a[i]; put the pinned vertex between them
                out = np.insert(out, 2 * i, pin, axis=0)
        pts = out
    return pts


def add_teeth(pts: np.ndarray, count: int, depth: float, skip_base: float = 0.15) -> np.ndarray:
    """Serrate a closed leaf-normalised polygon: ``count`` teeth of ``depth`` along the margin.

    Teeth are saw-shaped (pointing toward the apex); the margin within ``skip_base`` of the
    base and the tip (within 0.06 of the apex) stay entire, and in the blade's upper half the
    teeth shrink with its half-width once it is under 4 depths (an acuminate apex).
    """
    from leafsim.base.geometry import polygon_area, resample_closed

    if count <= 0 or depth <= 0:
        return pts
    n = max(count * 12, 200)
    p = resample_closed(pts, n)
    if polygon_area(p) < 0:
        p = p[::-1]
    # outward normal of a CCW polygon
    t = np.roll(p, -1, axis=0) - np.roll(p, 1, axis=0)
    nrm = np.column_stack([t[:, 1], -t[:, 0]])
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
    s = np.arange(n) / n
    phase = (s * count) % 1.0
    saw = np.where(phase < 0.7, phase / 0.7, (1 - phase) / 0.3)  # slow rise, sharp drop
    keep = np.linalg.norm(p, axis=1) > skip_base
    fade = np.clip((np.linalg.norm(p, axis=1) - skip_base) / 0.1, 0, 1) * keep
    # the tip stays entire too: inward offsets at a sharp apex would make the margin cross itself
    fade *= np.clip(np.linalg.norm(p - (0.0, 1.0), axis=1) / 0.06, 0, 1)
    # and the teeth shrink where the blade narrows towards its apex (an acuminate tip keeps small
    # teeth; full-depth notches below an entire tip left a knob there): full depth from a
    # half-width of 4 depths, a smooth ramp below it
    w = np.clip(np.abs(p[:, 0]) / (4.0 * depth), 0.0, 1.0)
    s = w * w * (3.0 - 2.0 * w)
    upper = np.clip((p[:, 1] - 0.4) / 0.2, 0.0, 1.0)  # (eased in over 0.4–0.6 of the length, no step)
    fade *= np.where(upper >= 1.0, s, np.where(upper <= 0.0, 1.0, 1.0 - upper * (1.0 - s)))
    return p - nrm * (depth * (1 - saw) * fade)[:, None]


def drawn_contour(sp: Species) -> np.ndarray:
    """Leaf-normalised contour of a drawn species (smoothed and serrated as configured)."""
    pts = sp.outline_points.copy()
    if sp.outline_smooth:
        pts = chaikin(pts, sp.outline_smooth, pin=np.zeros(2))
    if sp.teeth:
        pts = add_teeth(pts, int(sp.teeth.get("count", 0)), float(sp.teeth.get("depth", 0.0)), float(sp.teeth.get("skip_base", 0.15)))
    return pts
