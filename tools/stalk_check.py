"""Where a stalk's strip meets the blade, per species and mesh: hinges folded at rest and strip
edges that cross blade edges (the measurements behind docs/performance.md, "meshes finer than
the default run at all").  Every count should be 0; before the strip learned to narrow in a
narrow basal notch, maple had 2 folded hinges and 17 / 26 crossings at 0.0141 / 0.01 L.

    python tools/stalk_check.py                     # every species with a stalk, 4 meshes
    python tools/stalk_check.py maple 0.0141,0.01   # one species, chosen meshes (× L)
"""

from __future__ import annotations

import sys

import numpy as np

from leafsim.config.species import load_library
from leafsim.pipeline import build_leaf
from leafsim.sim.kernels.pbd import dihedral_angles

MESHES = (0.028, 0.0199, 0.0141, 0.01)


def _proper_crossings(X: np.ndarray, edges: np.ndarray, others: np.ndarray) -> int:
    """How many pairs (edge of ``edges``, edge of ``others``) cross properly (not at a shared
    particle, not touching at an end)."""

    def side(a, b, c):
        return np.sign((b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0]))

    n = 0
    for a, b in edges:
        keep = ~((others == a).any(1) | (others == b).any(1))
        c, d = X[others[keep, 0]], X[others[keep, 1]]
        n += int(((side(X[a], X[b], c) * side(X[a], X[b], d) < 0) & (side(c, d, X[a]) * side(c, d, X[b]) < 0)).sum())
    return n


def check(model) -> tuple[int, int]:
    """(hinges folded at rest, strip edges crossing blade edges near the stalk)."""
    X = model.particle_rest[:, :2]
    folded = int((np.abs(dihedral_angles(model.particle_rest, model.hinge_idx)) > 1e-6).sum())
    if model.particle_petiole is None:
        return folded, 0
    T = model.tri_T.astype(np.int64)
    on = model.particle_petiole[T].any(1)

    def edges(tris):
        return np.unique(np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [0, 2]]]), 1), axis=0)

    strip, blade = edges(T[on]), edges(T[~on])
    mid = X[strip].mean(1)
    near = np.linalg.norm(X[blade].mean(1)[:, None] - mid[None], axis=2).min(1) < 4.0 * model.spacing
    return folded, _proper_crossings(X, strip, blade[near])


def main(argv: list[str]) -> None:
    lib = load_library()
    keys = [argv[0]] if argv else [k for k, sp in lib.items() if sp.params["petiole.length"] > 0]
    meshes = [float(x) for x in argv[1].split(",")] if len(argv) > 1 else MESHES
    for key in keys:
        sp = lib[key]
        cells = []
        for s in meshes:
            m = build_leaf(sp, sp.params.with_overrides({"mesh.spacing": s, "dynamics.path": "own"}), 0).model
            folded, crossing = check(m)
            cells.append(f"{s:g} L ({m.particle_count}): folded {folded}, crossings {crossing}")
        print(f"{key}: " + " | ".join(cells), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
