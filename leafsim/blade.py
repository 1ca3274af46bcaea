"""Blade builder [Jeong 2013; thesis §3.6]: outline + veins + params -> immutable Model.

Layer T (bottom): vein particles along the veins, contour particles along the outline and
Poisson-disk surface particles, Delaunay-triangulated (outside triangles and boundary slivers
dropped).  Layer V (top): one particle per T triangle at its centroid lifted by the physical
thickness h; V springs across shared T edges (the Voronoi dual), link springs V → the three
triangle vertices.  Bending hinges on interior T edges and one thickness (tetrahedron)
constraint per triangle keep the layers the right way round.  Mass from Dijkstra distances.

Example
-------
>>> model = build_blade(shape, veins, ParamSet(), seed=1)      # doctest: +SKIP
>>> model.to_report()["vein_edge_share"] >= 0.99                # doctest: +SKIP
True
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import Delaunay, cKDTree

from .errors import LeafsimError
from .geometry import LeafShape, distance_to_outline, points_in_region, polygon_area, resample_closed, resample_polyline
from .params import ParamSet
from .sim.kernels.build import greedy_colour, poisson_accept
from .sim.model import (
    KIND_CONTOUR, KIND_SURFACE, KIND_VEIN, KIND_VORONOI, LAYER_T, LAYER_V,
    SPRING_LINK, SPRING_SURFACE, SPRING_V, SPRING_VEIN, Model,
)
from .venation import VeinGraph

_ORDER = {"main": 0, "lateral": 1, "sublateral": 2, "net": 3}


def _colour_sort(idx: np.ndarray, n: int):
    """Permutation sorting constraints by greedy colour, and the colour offsets."""
    if len(idx) == 0:
        return np.zeros(0, np.int64), np.zeros(1, np.int64)
    col = greedy_colour(np.ascontiguousarray(idx, np.int64), n)
    _, col = np.unique(col, return_inverse=True)
    perm = np.argsort(col, kind="stable")
    counts = np.bincount(col)
    return perm, np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)


@dataclass
class _Points:
    """Layer-T particles before triangulation: positions (n, 2), kinds (n,), vein orders (n,),
    vein polylines as particle-index chains with widths [m] and orders, contour count."""

    pts: np.ndarray
    kinds: np.ndarray
    vorders: np.ndarray
    vein_lists: list
    vein_ord: list
    vein_wid: list
    n_contour: int


#: peak memory of a built and running model: a fixed part plus this much per particle
#: (measured with ``leafsim run``: 0.31 GB at 33 k particles, 0.58 GB at 122 k; rounded up)
MEMORY_BASE_BYTES = 300e6
MEMORY_PER_PARTICLE = 4e3
#: refuse a model whose estimated memory exceeds this share of the machine's RAM
MEMORY_SHARE = 0.75


def estimate_particles(shape: LeafShape, params: ParamSet) -> int:
    """Particles (both layers) the builder would make, from outline area / r² and perimeter / r.

    Layer T holds ≈ 0.58 A/r² + 2.2 P/r particles (Poisson-disk interior plus contour), layer V
    one per triangle (≈ 2× T).  Fitted on 5 species × 3 spacings: within −10 % … +5 %.
    """
    a, b = _estimate_terms(shape)
    s = params["mesh.spacing"]
    return int(round(a / s**2 + b / s))


def _estimate_terms(shape: LeafShape) -> tuple[float, float]:
    """(a, b) of the estimate ``a / spacing² + b / spacing`` (spacing relative to the length)."""
    c = np.asarray(shape.contour, float)
    L = float(shape.length)
    area = abs(polygon_area(c))
    per = float(np.linalg.norm(np.diff(np.vstack([c, c[:1]]), axis=0), axis=1).sum())
    return 3.0 * 0.58 * area / L**2, 3.0 * 2.2 * per / L


def _physical_memory() -> float | None:
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, OSError, ValueError):
        return None


def check_mesh_budget(shape: LeafShape, params: ParamSet) -> int:
    """Refuse (one-line LeafsimError) a blade larger than ``limits.max_particles`` or than the
    machine's memory allows, before anything is built.  Returns the estimated particle count."""
    n = estimate_particles(shape, params)
    limit = int(params["limits.max_particles"])
    spacing = params["mesh.spacing"]
    gb = (MEMORY_BASE_BYTES + MEMORY_PER_PARTICLE * n) / 1e9
    # spacing at which the estimate meets the limit: limit·s² − b·s − a = 0
    ea, eb = _estimate_terms(shape)
    ok_spacing = 1.01 * (eb + math.sqrt(eb * eb + 4.0 * limit * ea)) / (2.0 * limit) if n else spacing
    if n > limit:
        raise LeafsimError(
            f"mesh.spacing = {spacing:g} would build about {n:,} particles (≈ {gb:.1f} GB) for this outline, more than "
            f"limits.max_particles = {limit:,}; use mesh.spacing ≥ {ok_spacing:.3g}, or raise limits.max_particles")
    phys = _physical_memory()
    if phys and gb * 1e9 > MEMORY_SHARE * phys:
        raise LeafsimError(
            f"mesh.spacing = {spacing:g} would build about {n:,} particles needing ≈ {gb:.1f} GB, more than "
            f"{100 * MEMORY_SHARE:.0f} % of this machine's {phys / 1e9:.1f} GB; use a larger mesh.spacing")
    return n


def build_blade(shape: LeafShape, veins: VeinGraph, params: ParamSet, seed: int,
                extra_points: np.ndarray | None = None) -> Model:
    """Build the two-layer blade.

    Stages (each a function below): sample particles → triangulate → T edges and vein springs →
    dual layer V and links → hinges → thickness volumes → masses per area → colour sort.

    Parameters
    ----------
    shape : LeafShape — outline in metres (base at origin, apex on +y).
    veins : VeinGraph — veins of all orders; those up to ``mesh.veins_included`` get particles.
    params : ParamSet — uses the ``mesh.*`` and ``mass.*`` groups.
    seed : int — seeds the Poisson-disk sampling (same seed → same model).
    extra_points : (k, 2) optional extra surface points (tests: slivers, degenerate input).

    Returns
    -------
    Model
    """
    L = float(shape.length)
    if not np.isfinite(L) or L <= 0:
        raise LeafsimError(f"build: leaf length {L!r} must be a positive number of metres")
    contour = np.asarray(shape.contour, float)
    if len(contour) < 3:
        raise LeafsimError("build: the outline needs at least 3 points")
    check_mesh_budget(shape, params)
    r = params["mesh.spacing"] * L
    h = params["mesh.thickness"]
    holes = tuple(np.asarray(hh, float) for hh in shape.holes)
    P = _sample_particles(contour, veins, params, r, np.random.default_rng(seed), extra_points, holes)
    tri, P, remap = _triangulate(P, contour, r, holes)
    nT, m = len(P.pts), len(tri)
    vp, vw, vo = _vein_chains(P, remap)
    E = _t_edges(P.pts, tri, vp, vo)
    rest = np.zeros((nT + m, 3))
    rest[:nT, :2] = P.pts
    rest[nT:, :2] = P.pts[tri].mean(1)
    rest[nT:, 2] = h
    tri_area = np.abs(_areas(P.pts, tri))
    S = _springs(E, tri, rest, tri_area, nT, vp, vw)
    H = _hinges(E, tri, rest, tri_area, S, vp, vw, vo)
    vol_idx = np.column_stack([np.arange(nT, nT + m), tri]).astype(np.int64)
    vol_rest0 = 2.0 * tri_area * h  # 6 × tetra volume = det = h × 2A
    base = int(np.argmin(np.linalg.norm(P.pts - np.asarray(shape.base, float), axis=1)))
    M = _masses(P, tri, tri_area, S, E.n_T_springs, base, vp, vw, params)
    model = _finalize(shape, P, tri, rest, S, H, vol_idx, vol_rest0, E.tri_edge, M, base, vp, vw, vo, remap, L, h, r, E.share)
    return replace(model, particle_patch=patch_field(model.particle_rest[:, :2], model.particle_area,
                                                     model.particle_layer == LAYER_T, L, seed))


#: correlation length of the hydraulic patch field, × leaf length (patches a few mm to cm)
PATCH_LENGTH = 0.12


def patch_field(xy: np.ndarray, area: np.ndarray, ref: np.ndarray, length: float, seed: int) -> np.ndarray:
    """(n,) smooth seeded random field over the blade, zero mean and unit spread (area-weighted
    over the particles ``ref``): patchy hydraulic failure — some patches of the blade lose
    water faster than others (a drying leaf's xylem fails in patches; Brodribb & Holbrook
    2003, Plant Physiol. 132:2166).  A Gaussian-correlated field with correlation length
    ``PATCH_LENGTH`` × length from 64 random Fourier features; a function of position only, so
    the same seed gives the same patches at any mesh spacing."""
    rng = np.random.default_rng([int(seed), 0x9A7C4])
    k = 64
    omega = rng.standard_normal((k, 2)) / (PATCH_LENGTH * float(length))
    phase = rng.uniform(0.0, 2.0 * np.pi, k)
    f = np.cos(np.asarray(xy, float) @ omega.T + phase).sum(1) * math.sqrt(2.0 / k)
    w = np.asarray(area, float) * ref
    mean = float(np.dot(w, f) / max(w.sum(), 1e-300))
    sd = math.sqrt(float(np.dot(w, (f - mean) ** 2) / max(w.sum(), 1e-300)))
    return (f - mean) / max(sd, 1e-12)


def _margin_points(ring: np.ndarray, r: float, spacing: float, detail: float) -> np.ndarray:
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


def _sample_particles(contour, veins: VeinGraph, params: ParamSet, r: float, rng, extra_points, holes=()) -> _Points:
    """Margin particles along the contour (first, in contour order) and the holes' edges
    (:func:`_margin_points`), vein particles along the veins (merged at junctions, snapped to
    the margin), Poisson-disk surface particles at spacing ``r`` in the blade."""
    max_order = _ORDER[params["mesh.veins_included"]]
    spacing, detail = params["mesh.contour_spacing"] * r, params["mesh.contour_detail"]
    cpts = _margin_points(contour, r, spacing, detail)
    nc = len(cpts)
    rings = [cpts] + [_margin_points(hh, r, spacing, detail) for hh in holes]
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
    surf = _poisson_surface(contour, fixed, vein_lists, r, rng, holes)
    if extra_points is not None and len(extra_points):
        surf = np.vstack([surf, np.asarray(extra_points, float)])
    allp = np.vstack([fixed, surf])
    kinds = np.concatenate(kind + [np.full(len(surf), KIND_SURFACE, np.int8)])
    vords = np.concatenate(vorder + [np.full(len(surf), -1, np.int8)])
    if len(allp) < 3:
        raise LeafsimError("build: too few particles; decrease mesh.spacing")
    return _Points(allp, kinds, vords, vein_lists, vein_ord, vein_wid, nc)


def _poisson_surface(contour, fixed, vein_lists, r: float, rng, holes=()) -> np.ndarray:
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


def _triangulate(P: _Points, contour, r: float, holes=()):
    """Delaunay triangulation of layer T: triangles outside the blade (outside the contour or
    in a hole) and boundary slivers dropped,
    CCW, unused particles removed, particles and triangles in Morton order, missing vein
    edges flipped in.  Returns (tri (m, 3), reordered points, remap old → new index (−1 gone))."""
    allp, kinds, vords = P.pts, P.kinds, P.vorders
    tri = Delaunay(allp).simplices.astype(np.int64)
    keep = points_in_region(allp[tri].mean(1), contour, holes)
    a, b, c = allp[tri[:, 0]], allp[tri[:, 1]], allp[tri[:, 2]]
    ar = 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    e2 = ((b - a) ** 2).sum(1) + ((c - b) ** 2).sum(1) + ((a - c) ** 2).sum(1)
    quality = 4 * np.sqrt(3) * np.abs(ar) / np.maximum(e2, 1e-300)
    on_contour = (kinds[tri] == KIND_CONTOUR).all(1)
    keep &= ~(on_contour & (quality < 0.15))  # hull-fill slivers along the outline
    keep &= np.abs(ar) > 1e-6 * r * r  # degenerate (collinear) triangles
    tri = tri[keep]
    flip = ar[keep] < 0
    tri[flip] = tri[flip][:, [0, 2, 1]]
    # drop particles no triangle uses (e.g. veins poking past a concave margin)
    used = np.zeros(len(allp), bool)
    used[tri.ravel()] = True
    remap = -np.ones(len(allp), np.int64)
    remap[used] = np.arange(used.sum())
    allp, kinds, vords = allp[used], kinds[used], vords[used]
    tri = remap[tri]
    # spatial (Morton) order of particles and triangles: constraint loops then walk memory
    # almost sequentially (measured: the random Poisson order made every access a cache miss)
    order = np.argsort(_morton(allp), kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    allp, kinds, vords = allp[order], kinds[order], vords[order]
    tri = rank[tri]
    tri = tri[np.argsort(_morton(allp[tri].mean(1)), kind="stable")]
    remap = np.where(remap >= 0, rank[np.maximum(remap, 0)], -1)
    tri = _flip_in_vein_edges(allp, tri, [remap[l][remap[l] >= 0] for l in P.vein_lists])
    return tri, _Points(allp, kinds, vords, P.vein_lists, P.vein_ord, P.vein_wid, P.n_contour), remap


def _vein_chains(P: _Points, remap):
    """Vein polylines in the final particle numbering: (chains, widths [m], orders)."""
    vp, vw, vo = [], [], []
    for lst, o, w in zip(P.vein_lists, P.vein_ord, P.vein_wid):
        j = remap[lst]
        ok_ = j >= 0
        if ok_.sum() >= 2:
            vp.append(j[ok_])
            vw.append(w[ok_])
            vo.append(o)
    return vp, vw, vo


@dataclass
class _Edges:
    """Layer-T springs: edges of the triangulation first (``n_edges``), then vein links the
    triangulation lacks; per edge the triangle pairs of interior edges."""

    ij: np.ndarray          # (s_T, 2)
    order: np.ndarray       # (s_T,) vein order or −1
    n_edges: int
    tri_edge: np.ndarray    # (m, 3) edge index of triangle edges (01, 12, 20)
    e_int: np.ndarray       # interior edge indices
    t1: np.ndarray          # first / second triangle of each interior edge
    t2: np.ndarray
    pos1: np.ndarray        # edge slot (0, 1, 2) of the interior edge in t1 / t2
    pos2: np.ndarray
    share: float            # vein_edge_share

    @property
    def n_T_springs(self) -> int:
        return len(self.ij)


def _t_edges(pts, tri, vp, vo) -> _Edges:
    """Unique edges of the triangulation, which of them are vein edges (and the vein links
    no triangle edge carries), and the two triangles of each interior edge."""
    nT, m = len(pts), len(tri)
    Es = np.sort(np.vstack([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), 1)
    key = Es[:, 0] * nT + Es[:, 1]
    ukey, first, inv, cnt = np.unique(key, return_index=True, return_inverse=True, return_counts=True)
    edges = Es[first]
    vein_edge_order = {}
    for j, o in zip(vp, vo):
        for p, q in zip(j[:-1], j[1:]):
            if p != q:
                k_ = min(p, q) * nT + max(p, q)
                vein_edge_order[k_] = min(o, vein_edge_order.get(k_, 9))
    vkeys = np.array(sorted(vein_edge_order), np.int64)
    present = np.isin(vkeys, ukey)
    share = float(present.mean()) if len(vkeys) else 1.0
    missing = vkeys[~present]  # still join them by a spring (not a triangle edge)
    ij = np.vstack([edges, np.column_stack([missing // nT, missing % nT])]).astype(np.int64)
    order = np.array([vein_edge_order.get(int(k_), -1) for k_ in np.concatenate([ukey, missing])], np.int8)
    owner = np.arange(3 * m) % m
    order_ = np.argsort(inv, kind="stable")
    inv_s = inv[order_]
    pair_start = np.flatnonzero(np.r_[True, inv_s[1:] != inv_s[:-1]])
    two = cnt[inv_s[pair_start]] == 2
    return _Edges(ij, order, len(edges), inv.reshape(3, m).T, inv_s[pair_start[two]],
                  owner[order_[pair_start[two]]], owner[order_[pair_start[two] + 1]],
                  order_[pair_start[two]] // m, order_[pair_start[two] + 1] // m, share)


@dataclass
class _Springs:
    """All springs (T, then V, then links) with their physical weights (see Model)."""

    ij: np.ndarray
    type: np.ndarray
    order: np.ndarray
    layer: np.ndarray
    rest0: np.ndarray
    weight: np.ndarray
    rod: np.ndarray
    face: np.ndarray
    V_of_edge: np.ndarray   # V spring index across each T edge (−1 on the boundary)


def _springs(E: _Edges, tri, rest, tri_area, nT: int, vp, vw) -> _Springs:
    """T springs (surface or vein), V springs across interior T edges (the Voronoi dual),
    links V → triangle vertices; rest lengths, membrane weights ΣA/|e|², vein rod weights
    (cross-section / length) and osmosis faces."""
    m = len(tri)
    tri_V = np.arange(nT, nT + m, dtype=np.int64)
    V_ij = np.column_stack([tri_V[E.t1], tri_V[E.t2]])
    link_ij = np.column_stack([np.repeat(tri_V, 3), tri.ravel()])
    nTs, nV = E.n_T_springs, len(V_ij)
    ij = np.vstack([E.ij, V_ij, link_ij])
    s_type = np.concatenate([np.where(E.order >= 0, SPRING_VEIN, SPRING_SURFACE).astype(np.int8),
                             np.full(nV, SPRING_V, np.int8), np.full(len(link_ij), SPRING_LINK, np.int8)])
    s_order = np.concatenate([E.order, -np.ones(nV + len(link_ij), np.int8)])
    s_layer = np.concatenate([np.zeros(nTs, np.int8), np.ones(nV, np.int8), np.full(len(link_ij), 2, np.int8)])
    rest0 = np.linalg.norm(rest[ij[:, 0]] - rest[ij[:, 1]], axis=1)
    # area each spring stands for: T edge = its triangles' areas; V spring = a third of the two
    # cells it joins (each cell has three); link = a third of its triangle
    tri_edge = E.tri_edge
    edge_area = np.bincount(tri_edge.ravel(), np.repeat(tri_area, 3), E.n_edges)
    area = np.concatenate([edge_area, np.zeros(nTs - E.n_edges), (tri_area[E.t1] + tri_area[E.t2]) / 3.0,
                           np.repeat(tri_area, 3) / 3.0])
    weight = area / np.maximum(rest0, 1e-30) ** 2
    # vein rods: cross-section π w²/4 of the thinner end, per length
    rod = np.zeros(len(ij))
    wmap = {}
    for chain, w in zip(vp, vw):
        for p, q, wa, wb in zip(chain[:-1], chain[1:], w[:-1], w[1:]):
            if p != q:
                k_ = (min(p, q), max(p, q))
                wmap[k_] = max(wmap.get(k_, 0.0), min(wa, wb))
    if wmap:
        sk = {(int(a), int(b)): s for s, (a, b) in enumerate(np.sort(E.ij, 1))}
        for k_, w in wmap.items():
            s = sk.get(k_)
            if s is not None:
                rod[s] = 0.25 * np.pi * w * w / max(rest0[s], 1e-30)
    face = np.concatenate([_dual_faces(E, tri, rest), np.zeros(nTs - E.n_edges),
                           np.linalg.norm(rest[E.ij[E.e_int, 0], :2] - rest[E.ij[E.e_int, 1], :2], axis=1),
                           np.zeros(len(link_ij))])
    V_of_edge = -np.ones(E.n_edges, np.int64)
    V_of_edge[E.e_int] = nTs + np.arange(nV)
    return _Springs(ij, s_type, s_order, s_layer, rest0, weight, rod, face, V_of_edge)


def _dual_faces(E: _Edges, tri, rest) -> np.ndarray:
    """Finite-volume face of each T edge such that face / |e| is the P1 (cotangent) weight
    ½ (cot α + cot β) of the angles facing the edge: the length of the edge's circumcentric
    (Voronoi) dual.  The two-point flux D (c_j − c_i) face / |e| is then the consistent
    piecewise-linear Laplacian (a linear field carries almost no net flux into a cell: 4–10 %
    of one edge's flux on these meshes, from the few non-Delaunay triangles along the veins);
    the barycentric face used before was not (a linear field's residual 60 %, the cell-wise
    diffusivity of x² scattered from −280 % to +460 %).  Clamped at 0 (a boundary edge facing
    an obtuse angle) so the operator stays an M-matrix and the water non-negative."""
    p = rest[:, :2]
    e_len = np.linalg.norm(p[E.ij[:E.n_edges, 1]] - p[E.ij[:E.n_edges, 0]], axis=1)
    w = np.zeros(E.n_edges)
    for k in range(3):  # tri_edge columns are the edges 01, 12, 20: opposite vertices 2, 0, 1
        o, a, b = tri[:, (k + 2) % 3], tri[:, k], tri[:, (k + 1) % 3]
        u, v = p[a] - p[o], p[b] - p[o]
        cross = np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
        np.add.at(w, E.tri_edge[:, k], 0.5 * (u * v).sum(1) / np.maximum(cross, 1e-300))
    return np.maximum(w, 0.0) * e_len


@dataclass
class _Hinges:
    idx: np.ndarray         # (h, 4) = (c, d, a, b)
    spring_T: np.ndarray
    spring_V: np.ndarray
    edge_len: np.ndarray
    area: np.ndarray
    rod: np.ndarray         # (h,) vein bending weight I/ℓ [m³]
    vein: np.ndarray        # (h,) bool: the hinge bends a main/lateral vein along its length


def _hinges(E: _Edges, tri, rest, tri_area, S: _Springs, vp, vw, vo) -> _Hinges:
    """Bending hinges on interior T edges: (c, d, a, b) = wings and shared edge a–b, edge
    length, the two triangles' area (discrete-shell weight 3|e|²/(A₁+A₂)).  A hinge whose wings
    lie on the vein through a (the vein runs c–a–d) bends that vein lengthwise: it carries the
    vein's rod stiffness share, I = π w⁴/64 over the vein length ℓ̄ at a, split among a's hinges."""
    sl = np.array([(0, 1, 2), (1, 2, 0), (2, 0, 1)])  # edge (i, j), opposite k
    a_ = tri[E.t1, sl[E.pos1, 0]]
    b_ = tri[E.t1, sl[E.pos1, 1]]
    c_ = tri[E.t1, sl[E.pos1, 2]]
    d_ = tri[E.t2, sl[E.pos2, 2]]
    idx = np.column_stack([c_, d_, a_, b_]).astype(np.int64)
    edge_len = np.linalg.norm(rest[a_] - rest[b_], axis=1)
    area = tri_area[E.t1] + tri_area[E.t2]
    # vein neighbours along each chain: (prev, next, I/ℓ̄) per vein particle
    rod_at: dict[int, tuple] = {}
    for chain, w, o in zip(vp, vw, vo):
        for k in range(1, len(chain) - 1):
            i = int(chain[k])
            lbar = 0.5 * (np.linalg.norm(rest[chain[k - 1]] - rest[i]) + np.linalg.norm(rest[chain[k + 1]] - rest[i]))
            I = np.pi * float(w[k]) ** 4 / 64.0
            rod_at[i] = (int(chain[k - 1]), int(chain[k + 1]), I / max(lbar, 1e-30), o)
    rod = np.zeros(len(idx))
    vein = np.zeros(len(idx), bool)
    hits: dict[int, list] = {}
    for e in range(len(idx)):
        c, d, a, b = idx[e]
        for v in (a, b):
            nb = rod_at.get(int(v))
            if nb is not None and {int(c), int(d)} == {nb[0], nb[1]}:
                hits.setdefault(int(v), []).append(e)
                vein[e] |= nb[3] <= 1
    for v, es in hits.items():
        for e in es:
            rod[e] += rod_at[v][2] / len(es)
    return _Hinges(idx, E.e_int.astype(np.int64), S.V_of_edge[E.e_int], edge_len, area, rod, vein)


@dataclass
class _Masses:
    area: np.ndarray        # (n,) area each particle stands for [m²]
    mass0: np.ndarray       # (n,) fresh mass [kg]
    water0: np.ndarray
    cytosol: np.ndarray
    tau: np.ndarray
    vein_width: np.ndarray  # (n,) [m], 0 off the veins


def _masses(P: _Points, tri, tri_area, S: _Springs, nTs: int, base: int, vp, vw, params: ParamSet) -> _Masses:
    """Fresh mass lumped by area: each layer carries half the blade's areal mass; a T particle
    stands for a third of its triangles' area, a V particle for its triangle.  The areal mass
    follows Jeong's graph-distance profile (τ from Dijkstra over the T springs, weighted per
    vein order) between ``mass.profile_min`` × and 1 × its peak, normalised so that the
    blade's mean dry mass per area is ``mass.lma``; vein particles add their rod (π w²/4 ×
    length share × ``mass.vein_density``, minus the lamina it replaces).  Water = water
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
        np.add.at(extra, chain, np.maximum(rod, 0.0) * share)
        np.maximum.at(vein_width, chain, w)
    m0 += extra
    tau = np.concatenate([tau_T, tau_T[tri].mean(1)])
    area = np.concatenate([area_T, tri_area])
    return _Masses(area, m0, fw * m0, (1.0 - fw) * m0, tau, vein_width)


def _finalize(shape, P, tri, rest, S: _Springs, H: _Hinges, vol_idx, vol_rest0, tri_edge, M: _Masses, base,
              vp, vw, vo, remap, L, h, r, share) -> Model:
    """Colour-sort every constraint type and assemble the immutable Model."""
    nT, m = len(P.pts), len(tri)
    n_all = nT + m
    perm_s, s_cs = _colour_sort(S.ij, n_all)
    inv_perm = np.empty_like(perm_s)
    inv_perm[perm_s] = np.arange(len(perm_s))
    sp = {k: getattr(S, k)[perm_s] for k in ("ij", "type", "order", "layer", "rest0", "weight", "rod", "face")}
    hinge_T, hinge_V, vol_springs = inv_perm[H.spring_T], inv_perm[H.spring_V], inv_perm[tri_edge.astype(np.int64)]
    perm_h, h_cs = _colour_sort(H.idx, n_all)
    hs = {k: getattr(H, k)[perm_h] for k in ("idx", "edge_len", "area", "rod", "vein")}
    hinge_T, hinge_V = hinge_T[perm_h], hinge_V[perm_h]
    perm_v, v_cs = _colour_sort(vol_idx, n_all)
    pinned = np.zeros(n_all, bool)
    pinned[:nT] = np.linalg.norm(P.pts - P.pts[base], axis=1) < 1.6 * r  # petiole (hanging scene)
    cont = np.flatnonzero(remap[:P.n_contour] >= 0)
    vs_ = np.concatenate([[0], np.cumsum([len(j) for j in vp])]).astype(np.int64)
    return Model(
        particle_rest=rest,
        particle_layer=np.concatenate([np.full(nT, LAYER_T, np.int8), np.full(m, LAYER_V, np.int8)]),
        particle_kind=np.concatenate([P.kinds, np.full(m, KIND_VORONOI, np.int8)]),
        particle_vein_order=np.concatenate([P.vorders, -np.ones(m, np.int8)]),
        particle_area=M.area, particle_cytosol=M.cytosol, particle_mass0=M.mass0, particle_water0=M.water0,
        particle_tau=M.tau, particle_vein_width=M.vein_width,
        particle_margin_distance=distance_to_outline(rest[:, :2], np.asarray(shape.contour, float), shape.holes),
        particle_texcoord=shape.texcoords(rest[:, :2]),
        particle_pinned=pinned,
        tri_T=tri, tri_V=np.arange(nT, nT + m, dtype=np.int64),
        spring_ij=sp["ij"], spring_rest0=sp["rest0"], spring_type=sp["type"], spring_layer=sp["layer"],
        spring_order=sp["order"], spring_weight=sp["weight"], spring_rod=sp["rod"], spring_face=sp["face"],
        spring_colour_start=s_cs,
        hinge_idx=hs["idx"], hinge_spring_T=hinge_T, hinge_spring_V=hinge_V,
        hinge_edge_len=hs["edge_len"], hinge_area=hs["area"], hinge_rod=hs["rod"], hinge_vein=hs["vein"],
        hinge_colour_start=h_cs,
        vol_idx=vol_idx[perm_v], vol_rest0=vol_rest0[perm_v], vol_springs=vol_springs[perm_v], vol_colour_start=v_cs,
        vein_particles=(np.concatenate(vp) if vp else np.zeros(0, np.int64)).astype(np.int64), vein_start=vs_,
        vein_order=np.array(vo, np.int8), vein_width=np.concatenate(vw) if vw else np.zeros(0),
        contour_particles=remap[cont].astype(np.int64),
        base_particle=base, length=L, thickness=h, spacing=r, vein_edge_share=share,
    )


def _areas(p2: np.ndarray, tri: np.ndarray) -> np.ndarray:
    a, b, c = p2[tri[:, 0]], p2[tri[:, 1]], p2[tri[:, 2]]
    return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))


def _cross2(o, a, b):
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def _flip_in_vein_edges(p2: np.ndarray, tri: np.ndarray, chains) -> np.ndarray:
    """Constrained-Delaunay repair: a vein edge a–b missing from the triangulation that crosses
    exactly one triangle edge c–d is recovered by flipping c–d (the quad a,c,b,d is convex)."""
    tri = tri.copy()
    edge_tris: dict = {}
    for t, (i, j, k) in enumerate(tri):
        for e in ((i, j), (j, k), (k, i)):
            edge_tris.setdefault((min(e), max(e)), []).append(t)
    for ch in chains:
        for a, b in zip(ch[:-1], ch[1:]):
            a, b = int(a), int(b)
            if a == b or (min(a, b), max(a, b)) in edge_tris:
                continue
            done = False
            for t in list(np.flatnonzero((tri == a).any(1))):
                i, j, k = tri[t]
                # rotate so that a is first
                while i != a:
                    i, j, k = j, k, i
                c, d = j, k  # edge c–d opposite a
                if _cross2(p2[c], p2[d], p2[a]) * _cross2(p2[c], p2[d], p2[b]) >= 0:
                    continue
                if _cross2(p2[a], p2[b], p2[c]) * _cross2(p2[a], p2[b], p2[d]) >= 0:
                    continue
                other = [u for u in edge_tris.get((min(c, d), max(c, d)), []) if u != t]
                if len(other) != 1:
                    continue
                u = other[0]
                if b not in tri[u]:
                    continue
                # flip: (a, c, d) + (d, c, b) -> (a, c, b) + (a, b, d)
                for e in ((a, c), (c, d), (d, a)):
                    edge_tris[(min(e), max(e))].remove(t)
                x, y, z = tri[u]
                for e in ((x, y), (y, z), (z, x)):
                    edge_tris[(min(e), max(e))].remove(u)
                del edge_tris[(min(c, d), max(c, d))]
                tri[t] = (a, c, b)
                tri[u] = (a, b, d)
                for tt in (t, u):
                    x, y, z = tri[tt]
                    for e in ((x, y), (y, z), (z, x)):
                        edge_tris.setdefault((min(e), max(e)), []).append(tt)
                done = True
                break
            if not done:
                continue
    return tri


def _morton(p2: np.ndarray) -> np.ndarray:
    """Morton (Z-order) code of 2D points on a 2^16 grid."""
    lo = p2.min(0)
    span = max(float(np.ptp(p2, 0).max()), 1e-30)
    g = np.clip(((p2 - lo) / span * 65535).astype(np.uint64), 0, 65535)

    def spread(v):
        v = (v | (v << np.uint64(8))) & np.uint64(0x00FF00FF)
        v = (v | (v << np.uint64(4))) & np.uint64(0x0F0F0F0F)
        v = (v | (v << np.uint64(2))) & np.uint64(0x33333333)
        v = (v | (v << np.uint64(1))) & np.uint64(0x55555555)
        return v

    return spread(g[:, 0]) | (spread(g[:, 1]) << np.uint64(1))
