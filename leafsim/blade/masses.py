"""Stage 3e: masses per area — dry mass and water lumped to the particles by the area each stands
for (veins by cross-section × length), with Jeong's graph-distance profile."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from leafsim.blade.elements import Springs
from leafsim.blade.sample import Points
from leafsim.config.params import ParamSet


@dataclass
class Masses:
    area: np.ndarray        # (n,) area each particle stands for [m²]
    mass0: np.ndarray       # (n,) fresh mass [kg]
    water0: np.ndarray
    cytosol: np.ndarray
    tau: np.ndarray
    vein_width: np.ndarray  # (n,) [m], 0 off the veins


def lump_masses(P: Points, tri, tri_area, S: Springs, nTs: int, base: int, vp, vw, params: ParamSet,
                rod_sides: np.ndarray | None = None) -> Masses:
    """Fresh mass lumped by area: each layer carries half the blade's areal mass; a T particle
    stands for a third of its triangles' area, a V particle for its triangle.  The areal mass
    follows Jeong's graph-distance profile (τ from Dijkstra over the T springs, weighted per
    vein order) between ``mass.profile_min`` × and 1 × its peak, normalised so that the
    blade's mean dry mass per area is ``mass.lma``; vein particles add their rod (π w²/4 ×
    length share × ``mass.vein_density``, minus the lamina it replaces); where ``rod_sides``
    names a particle's two side particles (the stalk's strip, :func:`~leafsim.blade.petiole.rod_sides`)
    half of it stays on the particle and a quarter goes to either side (the rod's polar moment
    of inertia M d²/8 over particles d/2 off its axis).  Water = water
    fraction × fresh mass, the rest is dry mass (cytosol)."""
    nT, m = len(P.pts), len(tri)
    wt = {0: params["mass.weight_main"], 1: params["mass.weight_lateral"], 2: params["mass.weight_sub"], 3: params["mass.weight_sub"]}
    w_edge = np.full(nTs, params["mass.weight_surface"])
    for o, wv in wt.items():
        w_edge[S.order[:nTs] == o] = wv
    lw = S.rest0[:nTs] * w_edge
    ij = S.ij[:nTs]
    G = coo_matrix((np.r_[lw, lw], (np.r_[ij[:, 0], ij[:, 1]], np.r_[ij[:, 1], ij[:, 0]])), shape=(nT, nT)).tocsr()
    dist = dijkstra(G, indices=base)
    finite = np.isfinite(dist)
    dmax = dist[finite].max() if finite.any() else 1.0
    dist[~finite] = dmax
    tau_T = (1.0 - dist / max(dmax, 1e-300)) ** params["mass.D"]
    prof_T = params["mass.profile_min"] + (1.0 - params["mass.profile_min"]) * tau_T
    area_T = np.bincount(tri.ravel(), np.repeat(tri_area, 3) / 3.0, nT)
    prof_V = prof_T[tri].mean(1)
    fw = params["mass.water_fraction"]
    fresh = params["mass.lma"] / (1.0 - fw)  # fresh blade mass per area [kg/m²]
    scale = fresh / (np.dot(area_T, prof_T) / area_T.sum())
    m0 = np.concatenate([0.5 * scale * prof_T * area_T, 0.5 * scale * prof_V * tri_area])
    vein_width = np.zeros(nT + m)
    extra = np.zeros(nT + m)
    pts = P.pts
    for chain, w in zip(vp, vw):
        seg = np.linalg.norm(np.diff(pts[chain], axis=0), axis=1)
        share = 0.5 * (np.r_[seg, 0.0] + np.r_[0.0, seg])
        rod = params["mass.vein_density"] * 0.25 * np.pi * w * w - scale * prof_T[chain] * w
        mass = np.maximum(rod, 0.0) * share
        if rod_sides is not None:
            sides = rod_sides[chain]
            strip = (sides >= 0).all(1)
            mass = np.where(strip, 0.5 * mass, mass)
            np.add.at(extra, sides[strip, 0], 0.5 * mass[strip])
            np.add.at(extra, sides[strip, 1], 0.5 * mass[strip])
        np.add.at(extra, chain, mass)
        np.maximum.at(vein_width, chain, w)
    m0 += extra
    tau = np.concatenate([tau_T, tau_T[tri].mean(1)])
    area = np.concatenate([area_T, tri_area])
    return Masses(area, m0, fw * m0, (1.0 - fw) * m0, tau, vein_width)
