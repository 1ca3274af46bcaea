"""What ``leafsim outline`` reports of a trace (JSON) and draws (the outline, base, apex and lobe
tips over the photo)."""

from __future__ import annotations

import math
import os
from pathlib import Path

import cv2
import numpy as np

from leafsim.base.fileio import write_png_atomic
from leafsim.base.geometry import polygon_area
from leafsim.outline.checks import problems
from leafsim.outline.trace import TracedOutline


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
        "vein_direction": None if traced.vein_direction is None else round(float(traced.vein_direction), 4),
        "petiole": None if traced.petiole_px is None else [r2(q) for q in traced.petiole_px],
        "iou": round(float(traced.iou), 5),
        "holes": [round(abs(polygon_area(hp)), 1) for hp in traced.holes_px],
        "petiole_on_blade": traced.petiole_mask is not None,
        "work_scale": round(float(traced.work_scale), 6),
        "border_fraction": round(float(traced.border_fraction), 5),
        "cut_by_border": list(traced.leafness.get("cut_by", [])),
        "leafness": {**{k: (round(v, 5) if isinstance(v, float) else v) for k, v in traced.leafness.items()},
                     "problems": [{"level": lv, "text": tx} for lv, tx in problems(traced.leafness)]},
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
