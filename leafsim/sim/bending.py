"""The hinges' weights: how a dihedral angle becomes bending energy.

A hinge on the shared edge e of two triangles stores ½ k θ² with k = D w, θ the dihedral angle
and D the plate rigidity E h³ / 12(1 − ν²) (:mod:`leafsim.sim.effects.dynamics`).  Two weights:

* ``discrete_shells``: w = 3 |e|² / (A₁ + A₂), the weight of Grinspun et al.'s discrete shells
  as it is usually written.  Summed over a mesh bent into a cylinder of curvature κ it gives
  3.0 × ½ D κ² A on a regular triangulation and about 4 × on our blade meshes (measured by
  :func:`cylinder_ratio`; ``tools/bending_stiffness.py``), so the hinges alone are about four
  times as stiff as the plate they stand for.
* ``cylinder``: the blade's weights scaled, once per mesh, so that this mesh's hinges bent into a
  cylinder (about the leaf's length axis and about its width axis, averaged) store exactly
  ½ D κ² A over the blade: the hinges then carry the plate rigidity D in cylindrical bending.
  A stalk's strip hinges keep the discrete-shells weights (the stalk is not a plate).

No single scale makes the hinges a plate in every mode: the plate stores ½ D ((κ₁ + κ₂)² −
2 (1 − ν) κ₁ κ₂), while the hinges' energy on a regular mesh goes as 3 (κ₁ + κ₂)² − 8 κ₁ κ₂ (no
Poisson term), so a cup (κ₁ = κ₂) takes 1.5 × and a saddle 5.7 × the plate's energy with the
discrete-shells weights (ν = 0.3), 0.5 × and 1.9 × with the cylinder-scaled ones
(:func:`mode_ratios`).

Imports no OpenGL."""

from __future__ import annotations

import numpy as np

from leafsim.sim.model import Model

#: the choices of ``material.hinge_weights``
WEIGHTS = ("discrete_shells", "cylinder")


def shells_weights(model: Model) -> np.ndarray:
    """(h,) 3 |e|² / (A₁ + A₂) in model order."""
    return 3.0 * model.hinge_edge_len ** 2 / np.maximum(model.hinge_area, 1e-30)


def _dihedral(q: np.ndarray, hidx: np.ndarray) -> np.ndarray:
    """(h,) the angle between the two triangles' normals of each hinge (c, d, a, b: wings c, d,
    shared edge a–b)."""
    c, d, a, b = (hidx[:, k] for k in range(4))
    n1 = np.cross(q[a] - q[c], q[b] - q[c])
    n2 = np.cross(q[b] - q[d], q[a] - q[d])
    n1 /= np.maximum(np.linalg.norm(n1, axis=1), 1e-300)[:, None]
    n2 /= np.maximum(np.linalg.norm(n2, axis=1), 1e-300)[:, None]
    return np.arccos(np.clip(np.abs((n1 * n2).sum(1)), -1.0, 1.0))


def cylinder_ratio(model: Model, weights: np.ndarray, kappa: float | None = None) -> float:
    """Σ ½ w θ² over the blade's hinges with the rest layer T bent into a cylinder of curvature
    ``kappa`` (default 1 / (20 L), a gentle bend), over ½ κ² A (A the blade's area): 1 when the
    weights carry the plate rigidity exactly; the mean of the bends about the leaf's length and
    width axes."""
    hidx = np.asarray(model.hinge_idx, np.int64)
    blade = model.blade_particles
    on = blade[hidx].all(1) if len(hidx) else np.zeros(0, bool)
    area = float(model.particle_area[model.blade_T].sum())
    if not on.any() or area <= 0.0:
        return 1.0
    kappa = 1.0 / (20.0 * model.length) if kappa is None else float(kappa)
    rest = model.particle_rest
    R = 1.0 / kappa
    ratios = []
    for axis in (0, 1):
        q = rest.copy()
        u = rest[:, axis] - rest[blade, axis].mean()
        q[:, axis] = R * np.sin(u / R)
        q[:, 2] = R - R * np.cos(u / R)
        th = _dihedral(q, hidx[on])
        ratios.append(float((weights[on] * th * th).sum()) / (kappa * kappa * area))
    return float(np.mean(ratios))


def mode_ratios(model: Model, weights: np.ndarray, nu: float, kappa: float | None = None) -> dict:
    """The hinges' energy over the plate's (½ D ((κ₁ + κ₂)² − 2 (1 − ν) κ₁ κ₂) A, D = 1) with the
    rest layer T bent by the height field z = ½ κ (a x² + b y²) of a gentle curvature ``kappa``
    (default 1 / (20 L)): a cylinder (a, b) = (1, 0) and (0, 1), averaged; a cup (1, 1); a saddle
    (1, −1).  All 1 for a blade whose hinges are the plate in every mode."""
    hidx = np.asarray(model.hinge_idx, np.int64)
    blade = model.blade_particles
    on = blade[hidx].all(1) if len(hidx) else np.zeros(0, bool)
    area = float(model.particle_area[model.blade_T].sum())
    if not on.any() or area <= 0.0:
        return {"cylinder": 1.0, "cup": 1.0, "saddle": 1.0}
    kappa = 1.0 / (20.0 * model.length) if kappa is None else float(kappa)
    rest = model.particle_rest
    c = rest[blade].mean(0)

    def ratio(a, b):
        q = rest.copy()
        x, y = rest[:, 0] - c[0], rest[:, 1] - c[1]
        q[:, 2] = 0.5 * kappa * (a * x * x + b * y * y)
        th = _dihedral(q, hidx[on])
        k1, k2 = a * kappa, b * kappa
        plate = 0.5 * ((k1 + k2) ** 2 - 2.0 * (1.0 - nu) * k1 * k2) * area
        return 0.5 * float((weights[on] * th * th).sum()) / plate

    return {"cylinder": 0.5 * (ratio(1.0, 0.0) + ratio(0.0, 1.0)), "cup": ratio(1.0, 1.0), "saddle": ratio(1.0, -1.0)}


def hinge_weights(model: Model, mode: str = "discrete_shells") -> np.ndarray:
    """(h,) the hinges' weights w in model order (k = D w): ``discrete_shells`` or ``cylinder``
    (module doc)."""
    w = shells_weights(model)
    if mode == "discrete_shells":
        return w
    if mode != "cylinder":
        raise ValueError(f"hinge weights {mode!r}: expected one of {WEIGHTS}")
    r = cylinder_ratio(model, w)
    if r <= 0.0:
        return w
    # the blade's hinges only: a stalk's strip hinges (any of their four particles the petiole's)
    # keep their weights, so the stalk bends alike under either choice (its rods dominate it)
    hidx = np.asarray(model.hinge_idx, np.int64)
    on = model.blade_particles[hidx].all(1) if len(hidx) else np.zeros(0, bool)
    return np.where(on, w / r, w)
