"""Statistics of a vein graph: counts and lengths per order, crossings, length outside the blade."""

from __future__ import annotations

import numpy as np

from leafsim.base.geometry import (  # noqa: E402
    LeafShape,
    crossing_pairs,
    points_in_region,
    segment_hits,
)
from leafsim.veins.graph import MAIN, ORDER_NAMES, VeinGraph


def _proper(p1, p2, q1, q2) -> bool:
    return len(segment_hits(np.asarray(p1), np.asarray(p2), np.asarray(q1)[None], np.asarray(q2)[None])) > 0


def count_crossings(graph: VeinGraph) -> int:
    """Number of proper intersections between vein segments (shared end points do not count)."""
    P, Q, _ = graph.segments()
    return len(crossing_pairs(P, Q))


def outside_length(graph: VeinGraph, contour: np.ndarray, holes=(), samples: int = 8) -> float:
    """Total vein length lying outside the blade: outside the contour or in a hole (sampled
    at segment interior points)."""
    P, Q, _ = graph.segments()
    if len(P) == 0:
        return 0.0
    t = (np.arange(samples) + 0.5) / samples
    pts = P[:, None, :] + (Q - P)[:, None, :] * t[None, :, None]
    inside = points_in_region(pts.reshape(-1, 2), contour, holes).reshape(len(P), samples)
    seg_len = np.linalg.norm(Q - P, axis=1)
    return float((seg_len * (1 - inside.mean(1))).sum())


def vein_stats(graph: VeinGraph, shape: LeafShape, main_targets=None, auto=True) -> dict:
    stats: dict = {"counts": {}, "lengths_m": {}, "segments": {}}
    for o, name in enumerate(ORDER_NAMES):
        vs = graph.of_order(o)
        stats["counts"][name] = len(vs)
        stats["lengths_m"][name] = round(sum(v.length for v in vs), 6)
        stats["segments"][name] = int(sum(max(len(v.points) - 1, 0) for v in vs))
    stats["crossings"] = count_crossings(graph)
    stats["outside_length"] = round(outside_length(graph, shape.contour, shape.holes), 9)
    mains = graph.of_order(MAIN)
    stats["main_target_error_m"] = round(max((float(np.linalg.norm(v.points[-1] - v.target)) for v in mains), default=0.0), 9)
    stats["main_last_step_m"] = round(max((float(np.linalg.norm(v.points[-1] - v.points[-2])) for v in mains if len(v.points) > 1), default=0.0), 9)
    stats["targets"] = auto if isinstance(auto, str) else ("auto" if auto else "config")  # or "photo": traced
    stats["main_targets"] = [[round(float(x), 6) for x in t] for t in (main_targets or [])]
    return stats
