"""The vein graph: one :class:`Vein` polyline per vein with its widths, order and parent."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

MAIN, LATERAL, SUB, NET = 0, 1, 2, 3


ORDER_NAMES = ("main", "lateral", "sublateral", "net")


@dataclass
class Vein:
    """One vein polyline.

    Attributes
    ----------
    order : 0 main, 1 lateral, 2 sublateral, 3 net.
    points : (k, 2) float64 — polyline in world metres, from its start (on the parent) outwards.
    widths : (k,) float64 — vein width at each point in metres.
    parent : index of the parent vein in ``VeinGraph.veins`` (−1 for main veins).
    target : (2,) float64 — the point the vein grew toward.
    """

    order: int
    points: np.ndarray
    widths: np.ndarray
    parent: int = -1
    target: np.ndarray | None = None

    @property
    def length(self) -> float:
        return float(np.linalg.norm(np.diff(self.points, axis=0), axis=1).sum()) if len(self.points) > 1 else 0.0


@dataclass
class VeinGraph:
    """All veins of one leaf plus the statistics the CLI reports."""

    veins: list[Vein] = field(default_factory=list)
    stats: dict = field(default_factory=dict)

    def of_order(self, order: int) -> list[Vein]:
        return [v for v in self.veins if v.order == order]

    def segments(self, max_order: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """All segments as (P (s,2), Q (s,2), order (s,)) up to ``max_order``."""
        P, Q, O = [], [], []
        for v in self.veins:
            if v.order <= max_order and len(v.points) > 1:
                P.append(v.points[:-1])
                Q.append(v.points[1:])
                O.append(np.full(len(v.points) - 1, v.order))
        if not P:
            return np.empty((0, 2)), np.empty((0, 2)), np.empty(0, int)
        return np.vstack(P), np.vstack(Q), np.concatenate(O)
