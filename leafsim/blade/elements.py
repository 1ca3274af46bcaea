"""Stage 3c–d: the T edges and springs (membrane and vein rods), the dual layer V and its links,
and the bending hinges on interior edges."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from leafsim.sim.model import (
    SPRING_LINK,
    SPRING_SURFACE,
    SPRING_V,
    SPRING_VEIN,
)


@dataclass
class Edges:
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


def t_edges(pts, tri, vp, vo) -> Edges:
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
    return Edges(ij, order, len(edges), inv.reshape(3, m).T, inv_s[pair_start[two]],
                  owner[order_[pair_start[two]]], owner[order_[pair_start[two] + 1]],
                  order_[pair_start[two]] // m, order_[pair_start[two] + 1] // m, share)


@dataclass
class Springs:
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


def make_springs(E: Edges, tri, rest, tri_area, nT: int, vp, vw) -> Springs:
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
    face = np.concatenate([dual_faces(E, tri, rest), np.zeros(nTs - E.n_edges),
                           np.linalg.norm(rest[E.ij[E.e_int, 0], :2] - rest[E.ij[E.e_int, 1], :2], axis=1),
                           np.zeros(len(link_ij))])
    V_of_edge = -np.ones(E.n_edges, np.int64)
    V_of_edge[E.e_int] = nTs + np.arange(nV)
    return Springs(ij, s_type, s_order, s_layer, rest0, weight, rod, face, V_of_edge)


def dual_faces(E: Edges, tri, rest) -> np.ndarray:
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
class Hinges:
    idx: np.ndarray         # (h, 4) = (c, d, a, b)
    spring_T: np.ndarray
    spring_V: np.ndarray
    edge_len: np.ndarray
    area: np.ndarray
    rod: np.ndarray         # (h,) vein bending weight I/ℓ [m³]
    vein: np.ndarray        # (h,) bool: the hinge bends a main/lateral vein along its length


def make_hinges(E: Edges, tri, rest, tri_area, S: Springs, vp, vw, vo) -> Hinges:
    """Bending hinges on interior T edges: (c, d, a, b) = wings and shared edge a–b, edge
    length, the two triangles' area (from which leafsim.sim.bending makes the hinge's weight, by
    default the discrete-shell 3|e|²/(A₁+A₂)).  A hinge whose wings
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
    return Hinges(idx, E.e_int.astype(np.int64), S.V_of_edge[E.e_int], edge_len, area, rod, vein)
