"""2D pictures drawn with OpenCV (no OpenGL): veins over the photo or the drawn outline."""

from __future__ import annotations

import cv2
import numpy as np

from leafsim.base.fileio import write_png_atomic  # noqa: F401  (re-exported for callers)
from leafsim.base.geometry import LeafShape
from leafsim.veins.graph import VeinGraph

#: BGR colour per vein order (main, lateral, sublateral, net)
ORDER_BGR = [(20, 20, 200), (30, 140, 240), (40, 200, 250), (200, 200, 60)]


def draw_veins(shape: LeafShape, graph: VeinGraph, size: int = 900, photo: np.ndarray | None = None) -> np.ndarray:
    """Veins (anti-aliased, width by order) over the leaf: the photo if given, else the outline.

    With a photo the veins are drawn in the photo's pixel frame beside a copy of the photo,
    so a person can compare generated and real venation.
    """
    S = 4  # supersampling for smooth thin lines
    if photo is not None and shape.image_size is not None:
        img = photo.copy()
        if img.ndim == 3 and img.shape[2] == 4:
            a = img[:, :, 3:4].astype(np.float32) / 255.0
            img = (img[:, :, :3] * a + 255 * (1 - a)).astype(np.uint8)
        scale = size / max(img.shape[:2])
        base = cv2.resize(img, (int(img.shape[1] * scale), int(img.shape[0] * scale)), interpolation=cv2.INTER_AREA)
        to_px = lambda pts: shape.world_to_px(pts) * scale  # noqa: E731
        px_per_m = scale / np.sqrt(abs(np.linalg.det(shape.px_to_world[:, :2])))
        canvas = base.copy()
        left = base
    else:
        lo, hi = shape.contour.min(0), shape.contour.max(0)
        ext = (hi - lo).max() * 1.1
        px_per_m = size / ext
        c = (lo + hi) / 2
        to_px = lambda pts: np.column_stack([(pts[:, 0] - c[0]) * px_per_m + size / 2, (c[1] - pts[:, 1]) * px_per_m + size / 2])  # noqa: E731
        canvas = np.full((size, size, 3), 255, np.uint8)
        cv2.fillPoly(canvas, [np.round(to_px(shape.contour) * 16).astype(np.int32)], (150, 200, 150), cv2.LINE_AA, shift=4)
        for hole in shape.holes:
            cv2.fillPoly(canvas, [np.round(to_px(hole) * 16).astype(np.int32)], (255, 255, 255), cv2.LINE_AA, shift=4)
        left = None
    big = cv2.resize(canvas, (canvas.shape[1] * S, canvas.shape[0] * S), interpolation=cv2.INTER_NEAREST)
    for ring in (shape.contour, *shape.holes):
        cv2.polylines(big, [np.round(to_px(ring) * S).astype(np.int32)], True, (30, 90, 30), max(1, S), cv2.LINE_AA)
    for v in sorted(graph.veins, key=lambda v: -v.order):
        q = to_px(v.points) * S
        for k in range(len(q) - 1):
            w = max(1, int(round(v.widths[k] * px_per_m * S)))
            cv2.line(big, tuple(np.round(q[k]).astype(int)), tuple(np.round(q[k + 1]).astype(int)), ORDER_BGR[v.order], w, cv2.LINE_AA)
    b = to_px(shape.base[None])[0] * S
    cv2.circle(big, tuple(np.round(b).astype(int)), 4 * S, (0, 0, 0), -1, cv2.LINE_AA)
    out = cv2.resize(big, (canvas.shape[1], canvas.shape[0]), interpolation=cv2.INTER_AREA)
    if left is not None:
        out = np.hstack([left, np.full((left.shape[0], 8, 3), 255, np.uint8), out])
    return out
