"""Plication: the fresh blade's pleats along its main veins and laterals (``shrink.plication``).

Some leaves are folded like a fan in the bud, along every lateral (plicate vernation: hornbeam
and beech, Ward 1904; Kobayashi, Kresling & Vincent 1998 model both as a plane with straight
parallel folds), and the grown blade keeps a trace of it: the veins lie in shallow valleys and
the panels between them are raised ("veins somewhat sunken on the upper surface giving the
leaf a distinctly quilted look", Virginia Tech dendrology, *Carpinus betulus*).

The pleat is a height field over the rest blade, z = depth · L · u / u₉₅, where u solves
−Δu = 1 on the blade's T mesh (cotangent Laplacian, lumped area) with u = 0 on every particle of
a main vein or a lateral (and on the stalk) and a free margin: each panel between two veins
rises smoothly to its middle, as far as the panel is wide (u grows as the square of the
panel's width), and meets its veins in a valley.  u₉₅ is u's 95th percentile over the blade's
T particles, so ``depth`` × L is about the height of the deepest panels.  The pleat enters the mechanics only as
rest angles: each bending hinge's rest angle is the bilayer's plus the dihedral angle of z
across its edge (zero on the hinges that bend a main vein or lateral lengthwise, which
lie along z = 0).  Bending the flat rest blade into pleats keeps its lengths (a pleat is a
fold), so the T layer's springs keep their flat rest lengths, and the V layer follows the bent
state (its springs shorten by h θ) as it follows the bilayer curl.  Kobayashi et al.'s folds are
straight creases, ridges and valleys alike; these are rounded panels between creased valleys,
the grown blade's quilting rather than the bud's folds.  The field is the same function of position on every
mesh of a leaf (only its discretisation differs), so the pleats converge under refinement:
the panels' curvature is resolved, and the valley along a vein is a fold whose angle does not
depend on the mesh.

Example
-------
>>> th = pleat_angles(model)          # doctest: +SKIP
>>> pleat = 0.012 * th               # doctest: +SKIP
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spl
from scipy.sparse.csgraph import connected_components

from leafsim.sim.model import LAYER_T, Model

#: height of the linearisation probe, × L at the 95th percentile (the angles are linear in it)
PROBE = 1e-6


def pleat_field(model: Model) -> np.ndarray:
    """(n,) u / u₉₅ of the module docstring on the T particles (0 elsewhere, on the main veins,
    the laterals and the stalk).  u₉₅ is the 95th percentile over the blade's T particles.  A
    part of the mesh that touches no main vein or lateral (an island of the blade) gets no
    pleats: u = 0 there.  Raises ValueError if the solve is not finite."""
    n = model.particle_count
    tri = model.blade_tri_T
    P = model.particle_rest[:, :2]
    area = np.zeros(n)
    rows, cols, vals = [], [], []
    for k in range(3):
        i, j, o = tri[:, k], tri[:, (k + 1) % 3], tri[:, (k + 2) % 3]
        u, v = P[i] - P[o], P[j] - P[o]
        cross = np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
        ok = cross > 1e-12 * np.maximum((u * u).sum(1) * (v * v).sum(1), 1e-300) ** 0.5
        w = np.where(ok, 0.5 * (u * v).sum(1) / np.where(ok, cross, 1.0), 0.0)  # ½ cot at o; 0 on a sliver
        rows += [i, j, i, j]
        cols += [j, i, i, j]
        vals += [-w, -w, w, w]
        np.add.at(area, tri[:, k], cross / 6.0)
    K = sps.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
    used = np.zeros(n, bool)
    used[tri.ravel()] = True
    order = model.particle_vein_order
    fixed = ~used | ((order >= 0) & (order <= 1)) | (model.particle_layer != LAYER_T)
    if model.particle_petiole is not None:
        fixed |= model.particle_petiole
    # a part of the mesh with no fixed particle has no solution: it gets none (u = 0)
    edges = sps.csr_matrix((np.ones(3 * len(tri)), (tri.ravel(), np.roll(tri, 1, axis=1).ravel())), shape=(n, n))
    _, part = connected_components(edges, directed=False)
    anchored = np.zeros(part.max() + 1, bool)
    anchored[part[fixed & used]] = True
    fixed |= ~anchored[part]
    free = np.flatnonzero(~fixed)
    u = np.zeros(n)
    if len(free) == 0:
        return u  # no veins to pleat along
    u[free] = spl.spsolve(K[free][:, free].tocsc(), area[free])
    if not np.isfinite(u).all():
        raise ValueError("pleats: the height field's solve is not finite (a degenerate blade mesh)")
    blade = used & (model.particle_layer == LAYER_T)
    u95 = float(np.percentile(u[blade], 95))
    return u / u95 if u95 > 0 else np.zeros(n)


def pleat_angles(model: Model) -> np.ndarray:
    """(h,) rest-angle change of every hinge per unit ``shrink.plication`` (the dihedral angle of
    z = L · u/u₉₅ across the hinge's edge, linearised; 0 on hinges that bend a main vein or a
    lateral lengthwise)."""
    from leafsim.sim.kernels.pbd import dihedral_angles

    if model.hinge_count == 0:
        return np.zeros(0)
    q = model.particle_rest.copy()
    q[:, 2] = PROBE * model.length * pleat_field(model)
    th = dihedral_angles(np.ascontiguousarray(q), model.hinge_idx) / PROBE
    return np.where(model.hinge_vein, 0.0, th)
