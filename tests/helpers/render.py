"""Tiny cv2 rasteriser for test/debug pictures of a leaf (no OpenGL): top and side views."""

from __future__ import annotations

import numpy as np


def views_png(path, model, q, size=360):
    import cv2

    tri = model.tri_T
    lo = q[: tri.max() + 1].min(0)
    span = max(np.ptp(q[: tri.max() + 1], 0).max(), 1e-9)
    imgs = []
    a, b, c = q[tri[:, 0]], q[tri[:, 1]], q[tri[:, 2]]
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-300
    light = np.array([0.3, -0.4, 0.86])
    shade = np.abs(n @ light)
    for axes, depth_axis, name in (((0, 1), 2, "top"), ((0, 2), 1, "side x"), ((1, 2), 0, "side y")):
        img = np.full((size, size, 3), 255, np.uint8)
        P = (q[:, axes] - lo[list(axes)]) / span * (size - 40) + 20
        P[:, 1] = size - P[:, 1]
        depth = q[tri, depth_axis].mean(1)
        order = np.argsort(depth if depth_axis == 2 else -depth)
        for t in order:
            col = (40 + 60 * shade[t], 110 + 130 * shade[t], 40 + 60 * shade[t])
            cv2.fillConvexPoly(img, np.round(P[tri[t]] * 16).astype(np.int32), col, cv2.LINE_AA, 4)
        for k in range(len(model.vein_order)):
            idx = model.vein_particles[model.vein_start[k]:model.vein_start[k + 1]]
            cv2.polylines(img, [np.round(P[idx] * 16).astype(np.int32)], False, (30, 60, 120), 1, cv2.LINE_AA, 4)
        cv2.putText(img, name, (5, 15), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1)
        imgs.append(img)
    cv2.imwrite(str(path), np.hstack(imgs))
