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

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import Delaunay, cKDTree

from .errors import LeafsimError
from .geometry import LeafShape, points_in_polygon, polygon_area, resample_closed, resample_polyline
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
    c = np.asarray(shape.contour, float)
    r = params["mesh.spacing"] * float(shape.length)
    area = abs(polygon_area(c))
    per = float(np.linalg.norm(np.diff(np.vstack([c, c[:1]]), axis=0), axis=1).sum())
    n_t = 0.58 * area / r**2 + 2.2 * per / r
    return int(round(3.0 * n_t))


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
    # spacing at which the estimate meets the limit (the count scales with 1/spacing²)
    ok_spacing = 1.01 * spacing * math.sqrt(n / limit) if n else spacing
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
    rng = np.random.default_rng(seed)
    max_order = _ORDER[params["mesh.veins_included"]]

    # ---------------------------------------------------------------- contour particles
    per = float(np.linalg.norm(np.diff(np.vstack([contour, contour[:1]]), axis=0), axis=1).sum())
    nc = max(12, int(round(per / (params["mesh.contour_spacing"] * r))))
    cpts = resample_closed(contour, nc)
    pts = [cpts]
    kind = [np.full(nc, KIND_CONTOUR, np.int8)]
    vorder = [np.full(nc, -1, np.int8)]
    n = nc
    ctree = cKDTree(cpts)

    # ---------------------------------------------------------------- vein particles
    vein_lists, vein_ord, vein_wid = [], [], []
    vtree_pts = np.empty((0, 2))
    vtree = None
    vs = params["mesh.vein_spacing"] * r
    for v in sorted(veins.veins, key=lambda v: v.order):
        if v.order > max_order or len(v.points) < 2:
            continue
        P = resample_polyline(np.asarray(v.points, float), vs)
        s_old = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(v.points, axis=0), axis=1))])
        s_new = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])
        W = np.interp(s_new / max(s_new[-1], 1e-30), s_old / max(s_old[-1], 1e-30), np.asarray(v.widths, float)) if len(v.widths) == len(v.points) else np.full(len(P), 0.001)
        inside = points_in_polygon(P, contour)
        idx, wid = [], []
        for p, w, ins in zip(P, W, inside):
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
                        j = int(jv) + nc  # merge with an existing vein particle (junctions)
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
    # ---------------------------------------------------------------- surface particles
    lo, hi = contour.min(0) - r, contour.max(0) + r
    area = abs(float(0.5 * np.dot(contour[:, 0], np.roll(contour[:, 1], -1)) - 0.5 * np.dot(contour[:, 1], np.roll(contour[:, 0], -1))))
    ncand = int(12 * area / (r * r)) + 100
    cand = lo + rng.random((ncand, 2)) * (hi - lo)
    cand = cand[points_in_polygon(cand, contour)]
    # keep surface points off the vein segments (so consecutive vein particles stay Delaunay-connected)
    segs = [(fixed[a[:-1]], fixed[a[1:]]) for a in vein_lists]
    if segs and len(cand):
        dense = np.vstack([resample_polyline(fixed[ch], 0.1 * r) for ch in vein_lists])
        dd, _ = cKDTree(dense).query(cand, distance_upper_bound=0.75 * r)
        cand = cand[~np.isfinite(dd)]
    ok = poisson_accept(np.ascontiguousarray(cand), np.ascontiguousarray(fixed), r, lo - r, hi + r)
    surf = cand[ok]
    if extra_points is not None and len(extra_points):
        surf = np.vstack([surf, np.asarray(extra_points, float)])
    allp = np.vstack([fixed, surf])
    kinds = np.concatenate(kind + [np.full(len(surf), KIND_SURFACE, np.int8)])
    vords = np.concatenate(vorder + [np.full(len(surf), -1, np.int8)])
    if len(allp) < 3:
        raise LeafsimError("build: too few particles; decrease mesh.spacing")

    # ---------------------------------------------------------------- Delaunay, drop outside & slivers
    tri = Delaunay(allp).simplices.astype(np.int64)
    cen = allp[tri].mean(1)
    keep = points_in_polygon(cen, contour)
    a, b, c = allp[tri[:, 0]], allp[tri[:, 1]], allp[tri[:, 2]]
    ar = 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    e2 = ((b - a) ** 2).sum(1) + ((c - b) ** 2).sum(1) + ((a - c) ** 2).sum(1)
    quality = 4 * np.sqrt(3) * np.abs(ar) / np.maximum(e2, 1e-300)
    on_contour = (kinds[tri] == KIND_CONTOUR).all(1)
    keep &= ~(on_contour & (quality < 0.15))  # hull-fill slivers along the outline
    keep &= np.abs(ar) > 1e-6 * r * r  # degenerate (collinear) triangles
    tri = tri[keep]
    ar = ar[keep]
    flip = ar < 0
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
    mort = _morton(allp)
    order = np.argsort(mort, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    allp, kinds, vords = allp[order], kinds[order], vords[order]
    tri = rank[tri]
    tri = tri[np.argsort(_morton(allp[tri].mean(1)), kind="stable")]
    remap = np.where(remap >= 0, rank[np.maximum(remap, 0)], -1)
    nT = len(allp)
    tri = _flip_in_vein_edges(allp, tri, [remap[l][remap[l] >= 0] for l in vein_lists])
    m = len(tri)
    vp, vs_, vo, vw = [], [0], [], []
    for lst, o, w in zip(vein_lists, vein_ord, vein_wid):
        j = remap[lst]
        ok_ = j >= 0
        j, w = j[ok_], w[ok_]
        if len(j) >= 2:
            vp.append(j)
            vw.append(w)
            vo.append(o)
            vs_.append(vs_[-1] + len(j))
    vein_particles = np.concatenate(vp) if vp else np.zeros(0, np.int64)
    vein_width = np.concatenate(vw) if vw else np.zeros(0)

    # ---------------------------------------------------------------- T edges, vein edges
    E = np.vstack([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    Es = np.sort(E, 1)
    key = Es[:, 0] * nT + Es[:, 1]
    ukey, first, inv, cnt = np.unique(key, return_index=True, return_inverse=True, return_counts=True)
    edges = Es[first]
    tri_edge = inv.reshape(3, m).T  # (m,3) edge index of edges (01,12,20)
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
    sp_ij = np.vstack([edges, np.column_stack([missing // nT, missing % nT])]).astype(np.int64)
    allkeys = np.concatenate([ukey, missing])
    s_order = np.array([vein_edge_order.get(int(k_), -1) for k_ in allkeys], np.int8)
    s_type = np.where(s_order >= 0, SPRING_VEIN, SPRING_SURFACE).astype(np.int8)
    nTs = len(sp_ij)

    # ---------------------------------------------------------------- layer V
    rest = np.zeros((nT + m, 3))
    rest[:nT, :2] = allp
    rest[nT:, :2] = allp[tri].mean(1)
    rest[nT:, 2] = h
    tri_V = np.arange(nT, nT + m, dtype=np.int64)
    # interior edges -> pairs of triangles
    owner = np.arange(3 * m) % m
    order_ = np.argsort(inv, kind="stable")
    inv_s = inv[order_]
    pair_start = np.flatnonzero(np.r_[True, inv_s[1:] != inv_s[:-1]])
    two = cnt[inv_s[pair_start]] == 2
    e_int = inv_s[pair_start[two]]
    t1 = owner[order_[pair_start[two]]]
    t2 = owner[order_[pair_start[two] + 1]]
    V_ij = np.column_stack([tri_V[t1], tri_V[t2]])
    link_ij = np.column_stack([np.repeat(tri_V, 3), tri.ravel()])
    sp_ij = np.vstack([sp_ij, V_ij, link_ij])
    s_type = np.concatenate([s_type, np.full(len(V_ij), SPRING_V, np.int8), np.full(len(link_ij), SPRING_LINK, np.int8)])
    s_order = np.concatenate([s_order, -np.ones(len(V_ij) + len(link_ij), np.int8)])
    s_layer = np.concatenate([np.zeros(nTs, np.int8), np.ones(len(V_ij), np.int8), np.full(len(link_ij), 2, np.int8)])
    n_all = nT + m
    rest0 = np.linalg.norm(rest[sp_ij[:, 0]] - rest[sp_ij[:, 1]], axis=1)
    V_spring_of_edge = -np.ones(len(edges), np.int64)
    V_spring_of_edge[e_int] = nTs + np.arange(len(V_ij))

    # ---------------------------------------------------------------- hinges (c, d, a, b)
    hin = []
    tri_edge_vert = [(0, 1, 2), (1, 2, 0), (2, 0, 1)]  # edge (i,j), opposite k
    # for each interior edge find (a,b) oriented as in t1 and opposite vertices
    pos1 = order_[pair_start[two]] // m  # which edge slot of t1
    pos2 = order_[pair_start[two] + 1] // m
    sl = np.array(tri_edge_vert)
    a_ = tri[t1, sl[pos1, 0]]
    b_ = tri[t1, sl[pos1, 1]]
    c_ = tri[t1, sl[pos1, 2]]
    d_ = tri[t2, sl[pos2, 2]]
    hinge_idx = np.column_stack([c_, d_, a_, b_]).astype(np.int64)
    hinge_T = e_int.astype(np.int64)
    hinge_V = V_spring_of_edge[e_int]
    hinge_len = np.linalg.norm(rest[a_] - rest[b_], axis=1)
    tri_area = np.abs(_areas(allp, tri))
    hinge_area = tri_area[t1] + tri_area[t2]

    # ---------------------------------------------------------------- thickness constraints
    vol_idx = np.column_stack([tri_V, tri]).astype(np.int64)
    vol_rest0 = 2.0 * tri_area * h  # 6 × tetra volume = det = h × 2A
    vol_springs = tri_edge.astype(np.int64)

    # ---------------------------------------------------------------- mass (Dijkstra over T springs)
    wt = {0: params["mass.weight_main"], 1: params["mass.weight_lateral"], 2: params["mass.weight_sub"], 3: params["mass.weight_sub"]}
    w_edge = np.full(nTs, params["mass.weight_surface"])
    for o, wv in wt.items():
        w_edge[s_order[:nTs] == o] = wv
    lw = rest0[:nTs] * w_edge
    G = coo_matrix((np.r_[lw, lw], (np.r_[sp_ij[:nTs, 0], sp_ij[:nTs, 1]], np.r_[sp_ij[:nTs, 1], sp_ij[:nTs, 0]])), shape=(nT, nT)).tocsr()
    base = int(np.argmin(np.linalg.norm(allp - np.asarray(shape.base, float), axis=1)))
    dist = dijkstra(G, indices=base)
    finite = np.isfinite(dist)
    dmax = dist[finite].max() if finite.any() else 1.0
    dist[~finite] = dmax
    tau_T = (1.0 - dist / max(dmax, 1e-300)) ** params["mass.D"]
    mmin, mmax = params["mass.m_min"], params["mass.m_max"]
    m0_T = mmin * (1 - tau_T) + mmax * tau_T
    m0 = np.concatenate([m0_T, m0_T[tri].mean(1)])
    tau = np.concatenate([tau_T, tau_T[tri].mean(1)])
    fw = params["mass.water_fraction"]

    # petiole particles (pinned in the hanging scene)
    pinned = np.zeros(n_all, bool)
    pinned[:nT] = np.linalg.norm(allp - allp[base], axis=1) < 1.6 * r

    # ---------------------------------------------------------------- colour-sort constraints
    perm_s, s_cs = _colour_sort(sp_ij, n_all)
    inv_perm = np.empty_like(perm_s)
    inv_perm[perm_s] = np.arange(len(perm_s))
    sp_ij, rest0, s_type, s_order, s_layer = sp_ij[perm_s], rest0[perm_s], s_type[perm_s], s_order[perm_s], s_layer[perm_s]
    hinge_T, hinge_V, vol_springs = inv_perm[hinge_T], inv_perm[hinge_V], inv_perm[vol_springs]
    perm_h, h_cs = _colour_sort(hinge_idx, n_all)
    hinge_idx, hinge_T, hinge_V, hinge_len, hinge_area = (x[perm_h] for x in (hinge_idx, hinge_T, hinge_V, hinge_len, hinge_area))
    perm_v, v_cs = _colour_sort(vol_idx, n_all)
    vol_idx, vol_rest0, vol_springs = vol_idx[perm_v], vol_rest0[perm_v], vol_springs[perm_v]

    kinds_all = np.concatenate([kinds, np.full(m, KIND_VORONOI, np.int8)])
    cont = np.flatnonzero(remap[:nc] >= 0)
    return Model(
        particle_rest=rest,
        particle_layer=np.concatenate([np.full(nT, LAYER_T, np.int8), np.full(m, LAYER_V, np.int8)]),
        particle_kind=kinds_all,
        particle_vein_order=np.concatenate([vords, -np.ones(m, np.int8)]),
        particle_cytosol=(1 - fw) * m0,
        particle_mass0=m0,
        particle_water0=fw * m0,
        particle_tau=tau,
        particle_texcoord=shape.texcoords(rest[:, :2]),
        particle_pinned=pinned,
        tri_T=tri, tri_V=tri_V,
        spring_ij=sp_ij, spring_rest0=rest0, spring_type=s_type, spring_layer=s_layer,
        spring_order=s_order, spring_colour_start=s_cs,
        hinge_idx=hinge_idx, hinge_spring_T=hinge_T, hinge_spring_V=hinge_V,
        hinge_edge_len=hinge_len, hinge_area=hinge_area, hinge_colour_start=h_cs,
        vol_idx=vol_idx, vol_rest0=vol_rest0, vol_springs=vol_springs, vol_colour_start=v_cs,
        vein_particles=vein_particles.astype(np.int64), vein_start=np.array(vs_, np.int64),
        vein_order=np.array(vo, np.int8), vein_width=vein_width,
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
