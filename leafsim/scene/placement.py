"""Where the finished leaves of a scene go (core: no OpenGL).

Each leaf was simulated alone; a layout then gives it a rigid transform ``p' = R p + t``
(rotation ``R``, translation ``t``; the leaf's shape is not changed):

* ``floor`` — dropped in scene order onto a square of ground: a random position and rotation
  about the vertical (from the scene seed and the leaf's index), then raised until its
  underside clears the **height field** of the leaves already placed under it.  The height
  field is a raster of ``cell`` metres holding the highest top surface (layer T plus the
  blade thickness) seen in each cell; a leaf's underside is rasterised the same way (its
  lowest point per cell) and lifted by the largest overlap plus ``clearance``.  So no two
  leaves interpenetrate at the raster's resolution.  The drop is rigid: a leaf does not tilt,
  slide or drape onto the leaves below (it rests on its highest contact, level as it dried).
* ``canopy`` — hung in a crown (a flattened sphere of ``radius`` at ``height``): random
  position, blade tilted by ``tilt`` degrees apex-down about its petiole, random heading.
  Leaves in the air may overlap; nothing resolves contacts there.
* ``row`` — side by side along x, ``gap`` apart, on the ground (close-ups).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from leafsim.appearance.mesh import RenderMesh
from leafsim.scene.layout import leaf_dir

#: barycentric sampling of a triangle for the height field: points per edge length in cells
SAMPLES_PER_CELL = 2.0


def load_views(out: Path, jobs) -> dict:
    """``view.npz`` arrays of every finished leaf, by name."""
    from leafsim.scene.job import load_view

    return {j.name: load_view(leaf_dir(out, j.name) / "view.npz") for j in jobs}


def rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def place(layout: dict, seed: int, jobs, views: dict) -> dict:
    """``{"kind", "leaves": [{"name", "rotation" (3×3), "translation" (3)}]}`` in scene order."""
    fn = {"floor": _floor, "canopy": _canopy, "row": _row}[layout["kind"]]
    transforms = fn(layout, seed, [views[j.name] for j in jobs])
    leaves = [{"name": j.name, "rotation": R.round(12).tolist(), "translation": t.round(12).tolist()}
              for j, (R, t) in zip(jobs, transforms)]
    return {"kind": layout["kind"], "leaves": leaves}


def transformed(view: dict, leaf: dict) -> np.ndarray:
    """(nT, 3) positions of a leaf view after its placement."""
    return view["positions"] @ np.asarray(leaf["rotation"]).T + np.asarray(leaf["translation"])


def _row(layout, seed, views):
    out, x = [], 0.0
    for v in views:
        p = v["positions"]
        lo, hi = p.min(0), p.max(0)
        out.append((np.eye(3), np.array([x - lo[0], -0.5 * (lo[1] + hi[1]), -lo[2]])))
        x += (hi[0] - lo[0]) + layout["gap"]
    shift = 0.5 * (x - layout["gap"])
    return [(R, t - [shift, 0.0, 0.0]) for R, t in out]


def _canopy(layout, seed, views):
    out = []
    r, h = layout["radius"], layout["height"]
    for k, _v in enumerate(views):
        rng = np.random.default_rng([seed, k, 2])
        d = rng.normal(size=3)
        d *= rng.random() ** (1 / 3) / np.linalg.norm(d)  # uniform in the unit ball
        tilt = math.radians(rng.uniform(*layout["tilt"]))
        R = rot_z(rng.uniform(0, 2 * math.pi)) @ rot_x(-tilt)
        out.append((R, np.array([r * d[0], r * d[1], h + 0.6 * r * d[2]])))
    return out


def _samples(p: np.ndarray, tri: np.ndarray, cell: float) -> np.ndarray:
    """Points on every triangle, no further apart than cell / SAMPLES_PER_CELL."""
    e = np.linalg.norm(p[tri] - p[np.roll(tri, 1, axis=1)], axis=2).max()
    s = max(1, math.ceil(e * SAMPLES_PER_CELL / cell))
    i, j = np.meshgrid(np.arange(s + 1), np.arange(s + 1), indexing="ij")
    keep = i + j <= s
    b = np.column_stack([i[keep], j[keep], s - i[keep] - j[keep]]) / s  # (k, 3)
    return np.einsum("kj,tjd->tkd", b, p[tri]).reshape(-1, 3)


class HeightField:
    """Highest top surface per ground cell of the leaves placed so far (ground = 0)."""

    def __init__(self, lo: np.ndarray, span: np.ndarray, cell: float):
        self.lo, self.cell = lo, cell
        self.shape = tuple(int(math.ceil(s / cell)) + 1 for s in span)
        self.top = np.zeros(self.shape)
        self.occupied = np.zeros(self.shape, bool)

    def cells(self, pts: np.ndarray) -> tuple:
        ij = np.floor((pts[:, :2] - self.lo) / self.cell).astype(np.int64)
        ij = np.clip(ij, 0, np.array(self.shape) - 1)
        return ij[:, 0], ij[:, 1]

    def lift(self, pts: np.ndarray, clearance: float) -> float:
        """How far to raise a leaf (sample points ``pts``, lowest at z = 0) so its underside
        clears every occupied cell by ``clearance``."""
        i, j = self.cells(pts)
        bottom = np.full(self.shape, np.inf)
        np.minimum.at(bottom, (i, j), pts[:, 2])
        hit = self.occupied & np.isfinite(bottom)
        return float(max(0.0, (self.top[hit] + clearance - bottom[hit]).max(initial=0.0)))

    def add(self, pts: np.ndarray, thickness: float) -> None:
        i, j = self.cells(pts)
        np.maximum.at(self.top, (i, j), pts[:, 2] + thickness)
        self.occupied[i, j] = True


def _floor(layout, seed, views):
    size = np.asarray(layout["size"])
    reach = max((float(np.ptp(v["positions"][:, :2], 0).max()) for v in views), default=0.0)
    hf = HeightField(-0.5 * size - reach, size + 2 * reach, layout["cell"])
    out = []
    for k, v in enumerate(views):
        rng = np.random.default_rng([seed, k, 1])
        p = v["positions"]
        centre = 0.5 * (p.min(0) + p.max(0))
        R = rot_z(rng.uniform(0, 2 * math.pi))
        xy = rng.uniform(-0.5, 0.5, 2) * size
        t = np.array([xy[0], xy[1], 0.0]) - R @ np.array([centre[0], centre[1], p[:, 2].min()])
        pts = _samples(p @ R.T + t, v["triangles"], layout["cell"])
        lift = hf.lift(pts, layout["clearance"])
        t[2] += lift
        pts[:, 2] += lift
        hf.add(pts, float(v["thickness"]))
        out.append((R, t))
    return out


def merge_views(views: dict, placed: dict) -> RenderMesh:
    """One RenderMesh of every placed leaf (``views``: name → ``view.npz`` arrays;
    ``placed``: :func:`leafsim.scene.placement.place` output)."""
    pos, tri, col, vcol, veins = [], [], [], [], []
    base = 0
    for leaf in placed["leaves"]:
        v = views[leaf["name"]]
        pos.append(transformed(v, leaf))
        tri.append(v["triangles"] + base)
        col.append(v["colours"])
        vcol.append(v.get("vein_colours", v["colours"]))  # a leaf finished before they were kept
        s = v["vein_start"]
        for k in range(len(v["vein_order"])):
            a, b = s[k], s[k + 1]
            veins.append((v["vein_index"][a:b] + base, v["vein_width"][a:b], int(v["vein_order"][k])))
        base += len(v["positions"])
    return RenderMesh(positions=np.concatenate(pos).astype(np.float32), triangles=np.concatenate(tri).astype(np.int32),
                      colours=np.concatenate(col).astype(np.float32),
                      vein_colours=np.concatenate(vcol).astype(np.float32), vein_lines=veins)
