"""Stage 3a: layer-T particles — contour, veins (up to ``mesh.veins_included``) and Poisson-disk
surface particles — and the seeded hydraulic patch field."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from leafsim.base.errors import LeafsimError
from leafsim.base.geometry import points_in_region, polygon_area, resample_closed, resample_polyline
from leafsim.blade.kernels import poisson_accept
from leafsim.config.params import ParamSet
from leafsim.sim.model import (
    KIND_CONTOUR,
    KIND_SURFACE,
    KIND_VEIN,
)
from leafsim.sim.senescence import random_field
from leafsim.veins.graph import VeinGraph

#: index of each ``mesh.veins_included`` choice in the vein orders
ORDER_INDEX = {"main": 0, "lateral": 1, "sublateral": 2, "net": 3}


@dataclass
class Points:
    """Layer-T particles before triangulation: positions (n, 2), kinds (n,), vein orders (n,),
    vein polylines as particle-index chains with widths [m] and orders, contour count."""

    pts: np.ndarray
    kinds: np.ndarray
    vorders: np.ndarray
    vein_lists: list
    vein_ord: list
    vein_wid: list
    n_contour: int


#: correlation length of the hydraulic patch field, × leaf length (patches a few mm to cm)
PATCH_LENGTH = 0.12


def patch_field(xy: np.ndarray, area: np.ndarray, ref: np.ndarray, length: float, seed: int) -> np.ndarray:
    """(n,) smooth seeded random field over the blade, zero mean and unit spread (area-weighted
    over the particles ``ref``): patchy hydraulic failure — some patches of the blade lose
    water faster than others (a drying leaf's xylem fails in patches; Brodribb & Holbrook
    2003, Plant Physiol. 132:2166).  A Gaussian-correlated field with correlation length
    ``PATCH_LENGTH`` × length from 64 random Fourier features; a function of position only, so
    the same seed gives the same patches at any mesh spacing."""
    return random_field(xy, np.asarray(area, float) * ref, PATCH_LENGTH * float(length), [int(seed), 0x9A7C4])


def margin_points(ring: np.ndarray, r: float, spacing: float, detail: float) -> np.ndarray:
    """Particles along one closed margin ring (contour or hole), starting at its first point:
    its corners — the vertices a Douglas–Peucker simplification at ``detail`` × r keeps (tooth
    tips and notches), no two closer than 0.1 r along the margin — and evenly spaced points
    along the margin between them, at most ``spacing`` apart (``detail`` = 0: evenly spaced
    only, which cuts teeth smaller than the spacing)."""
    seg = np.linalg.norm(np.diff(np.vstack([ring, ring[:1]]), axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    per = float(s[-1])
    if detail <= 0:
        return resample_closed(ring, max(12, int(round(per / spacing))))
    import cv2

    keep = cv2.approxPolyDP(np.ascontiguousarray(ring, np.float32).reshape(-1, 1, 2), float(detail * r), True).reshape(-1, 2)
    idx = np.unique(np.concatenate([[0], cKDTree(ring).query(keep.astype(np.float64))[1]]))
    corners = [0]
    for i in idx[1:]:
        if s[i] - s[corners[-1]] >= 0.1 * r and per - s[i] >= 0.1 * r:
            corners.append(int(i))
    ends = np.r_[s[corners], per]
    t = np.concatenate([np.linspace(a, b, max(1, int(np.ceil((b - a) / spacing))), endpoint=False) for a, b in zip(ends[:-1], ends[1:])])
    closed = np.vstack([ring, ring[:1]])
    return np.column_stack([np.interp(t, s, closed[:, 0]), np.interp(t, s, closed[:, 1])])


def sample_particles(contour, veins: VeinGraph, params: ParamSet, r: float, rng, extra_points, holes=()) -> Points:
    """Margin particles along the contour (first, in contour order) and the holes' edges
    (:func:`margin_points`), vein particles along the veins (merged at junctions, snapped to
    the margin), Poisson-disk surface particles at spacing ``r`` in the blade."""
    max_order = ORDER_INDEX[params["mesh.veins_included"]]
    spacing, detail = params["mesh.contour_spacing"] * r, params["mesh.contour_detail"]
    cpts = margin_points(contour, r, spacing, detail)
    nc = len(cpts)
    rings = [cpts] + [margin_points(hh, r, spacing, detail) for hh in holes]
    cpts = np.vstack(rings)
    pts = [cpts]
    kind = [np.full(len(cpts), KIND_CONTOUR, np.int8)]
    vorder = [np.full(len(cpts), -1, np.int8)]
    n = len(cpts)
    ctree = cKDTree(cpts)
    vein_lists, vein_ord, vein_wid = [], [], []
    vtree_pts = np.empty((0, 2))
    vtree = None
    vs = params["mesh.vein_spacing"] * r
    for v in sorted(veins.veins, key=lambda v: v.order):
        if v.order > max_order or len(v.points) < 2:
            continue
        Pv = resample_polyline(np.asarray(v.points, float), vs)
        s_old = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(v.points, axis=0), axis=1))])
        s_new = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(Pv, axis=0), axis=1))])
        W = np.interp(s_new / max(s_new[-1], 1e-30), s_old / max(s_old[-1], 1e-30), np.asarray(v.widths, float)) if len(v.widths) == len(v.points) else np.full(len(Pv), 0.001)
        inside = points_in_region(Pv, contour, holes)
        idx, wid = [], []
        for p, w, ins in zip(Pv, W, inside):
            dc, jc = ctree.query(p)
            if dc < 0.5 * r:
                j = int(jc)  # snap to the contour particle
            elif not ins:
                continue
            else:
                j = -1
                if vtree is not None:
                    dv, jv = vtree.query(p)
                    if dv < (0.8 if not idx else 0.4) * vs:
                        j = int(jv) + len(cpts)  # merge with an existing vein particle (junctions)
                    elif dv < 0.6 * vs:
                        continue  # would crowd another vein's edge
                if j < 0:
                    j = n
                    pts.append(p[None])
                    kind.append(np.array([KIND_VEIN], np.int8))
                    vorder.append(np.array([v.order], np.int8))
                    vtree_pts = np.vstack([vtree_pts, p[None]])
                    n += 1
            if not idx or idx[-1] != j:
                idx.append(j)
                wid.append(w)
        if len(idx) >= 2:
            vein_lists.append(np.array(idx, np.int64))
            vein_ord.append(v.order)
            vein_wid.append(np.array(wid))
        if len(vtree_pts):
            vtree = cKDTree(vtree_pts)
    fixed = np.vstack(pts)
    surf = poisson_surface(contour, fixed, vein_lists, r, rng, holes)
    if extra_points is not None and len(extra_points):
        surf = np.vstack([surf, np.asarray(extra_points, float)])
    allp = np.vstack([fixed, surf])
    kinds = np.concatenate(kind + [np.full(len(surf), KIND_SURFACE, np.int8)])
    vords = np.concatenate(vorder + [np.full(len(surf), -1, np.int8)])
    if len(allp) < 3:
        raise LeafsimError("build: too few particles; decrease mesh.spacing")
    return Points(allp, kinds, vords, vein_lists, vein_ord, vein_wid, nc)


def poisson_surface(contour, fixed, vein_lists, r: float, rng, holes=()) -> np.ndarray:
    """(k, 2) Poisson-disk surface points in the blade (inside the outline, outside its
    holes), ≥ r from every fixed point and kept off the vein segments (so consecutive vein
    particles stay Delaunay-connected)."""
    lo, hi = contour.min(0) - r, contour.max(0) + r
    area = abs(polygon_area(contour))
    ncand = int(12 * area / (r * r)) + 100
    cand = lo + rng.random((ncand, 2)) * (hi - lo)
    cand = cand[points_in_region(cand, contour, holes)]
    if vein_lists and len(cand):
        dense = np.vstack([resample_polyline(fixed[ch], 0.1 * r) for ch in vein_lists])
        dd, _ = cKDTree(dense).query(cand, distance_upper_bound=0.75 * r)
        cand = cand[~np.isfinite(dd)]
    ok = poisson_accept(np.ascontiguousarray(cand), np.ascontiguousarray(fixed), r, lo - r, hi + r)
    return cand[ok]
