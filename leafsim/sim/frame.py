"""The blade's mid-surface frame of a state: layer-T positions, triangles, vertex normals and the
local thickness from the V layer (exports and the level of detail use it)."""

from __future__ import annotations

import numpy as np

from leafsim.sim.model import Model, State

#: the shell's top surface never comes closer to the bottom than this fraction of the thickness
MIN_THICKNESS = 0.05


def _unit(v: np.ndarray, fallback=(0.0, 0.0, 1.0)) -> np.ndarray:
    n = np.linalg.norm(v, axis=1, keepdims=True)
    out = np.where(n > 1e-30, v / np.maximum(n, 1e-300), np.asarray(fallback, np.float64))
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def blade_frame(model: Model, state: State, T: np.ndarray, remap: np.ndarray):
    """Layer T of ``state``: positions (nT, 3), triangles (m, 3) into them, unit vertex normals
    (area-weighted) and the local layer separation (nT,) [m] — the height of each triangle's V
    particle above the triangle, averaged over the triangles around a vertex by area."""
    q = state.particle_q
    tri = remap[model.tri_T]
    p = q[T]
    a, b, c = p[tri[:, 0]], p[tri[:, 1]], p[tri[:, 2]]
    fn = np.cross(b - a, c - a)  # 2 × area × unit normal
    area = 0.5 * np.linalg.norm(fn, axis=1)
    vn = np.zeros_like(p)
    hw = np.zeros(len(p))
    w = np.zeros(len(p))
    h_tri = ((q[model.tri_V] - (a + b + c) / 3.0) * _unit(fn)).sum(1)
    for k in range(3):
        np.add.at(vn, tri[:, k], fn)
        np.add.at(hw, tri[:, k], area * h_tri)
        np.add.at(w, tri[:, k], area)
    h = np.maximum(hw / np.maximum(w, 1e-300), MIN_THICKNESS * model.thickness)
    return p, tri, _unit(vn), h
