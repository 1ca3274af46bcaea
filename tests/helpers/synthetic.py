"""Synthetic leaf outlines and vein graphs for the simulation tests (no image, no grower)."""

from __future__ import annotations

import numpy as np

from leafsim.base.geometry import LeafShape, resample_polyline
from leafsim.veins.graph import LATERAL, MAIN, SUB, Vein, VeinGraph


def ellipse_shape(length: float = 0.12, width: float = 0.07, n: int = 200) -> LeafShape:
    """An elliptic leaf, base (0,0), apex (0, length), counter-clockwise."""
    t = np.linspace(-np.pi / 2, 1.5 * np.pi, n, endpoint=False)
    c = np.column_stack([0.5 * width * np.cos(t), 0.5 * length * (1 + np.sin(t))])
    return LeafShape(contour=c, base=np.zeros(2), apex=np.array([0.0, length]), lobes=np.empty((0, 2)), length=length)


def lobed_shape(length: float = 0.12, lobes: int = 5, depth: float = 0.35, n: int = 400) -> LeafShape:
    """A palmate, maple-like lobed outline (concave), base at (0,0), apex on +y."""
    t = np.linspace(-np.pi / 2, 1.5 * np.pi, n, endpoint=False)
    ang = t - np.pi / 2  # 0 at the top
    rad = 1.0 - depth * (0.5 - 0.5 * np.cos(lobes * ang + 0.0)) ** 0.7
    rad *= 0.6 + 0.4 * np.cos(ang / 2) ** 2
    c = np.column_stack([rad * np.cos(t), rad * np.sin(t)])
    c -= c[0]  # base at the bottom point
    c *= length / c[:, 1].max()
    c[:, 0] -= 0.0
    apex = np.array([0.0, c[:, 1].max()])
    return LeafShape(contour=c, base=np.zeros(2), apex=apex, lobes=np.empty((0, 2)), length=length)


def _line(a, b, w0, w1, step):
    p = resample_polyline(np.array([a, b], float), step)
    return Vein(order=0, points=p, widths=np.linspace(w0, w1, len(p)))


def synthetic_veins(shape: LeafShape, laterals: int = 5, sub: bool = True) -> VeinGraph:
    """Midrib base→apex, straight laterals on alternating sides, one sublateral per lateral."""
    L = shape.length
    step = 0.02 * L
    veins = []
    mid = _line((0, 0.0), (0, 0.97 * L), 0.012 * L, 0.003 * L, step)
    mid.order = MAIN
    veins.append(mid)
    from leafsim.base.geometry import ray_polygon_hit

    for k in range(laterals):
        y = L * (0.15 + 0.7 * k / max(laterals - 1, 1))
        side = 1 if k % 2 == 0 else -1
        d = np.array([side * np.cos(np.radians(40)), np.sin(np.radians(40))])
        hit = ray_polygon_hit(np.array([0.0, y]), d, shape.contour)
        if hit is None:
            continue
        end = np.array([0.0, y]) + 0.85 * hit * d
        lat = _line((0.0, y), end, 0.005 * L, 0.002 * L, step)
        lat.order, lat.parent = LATERAL, 0
        veins.append(lat)
        li = len(veins) - 1
        if sub:
            s0 = lat.points[len(lat.points) // 2]
            d2 = np.array([side * np.cos(np.radians(-10)), np.sin(np.radians(-10))])
            h2 = ray_polygon_hit(s0, d2, shape.contour)
            if h2 is not None and h2 > 0.1 * L:
                sv = _line(s0, s0 + 0.8 * h2 * d2, 0.002 * L, 0.001 * L, step)
                sv.order, sv.parent = SUB, li
                veins.append(sv)
    return VeinGraph(veins=veins)
