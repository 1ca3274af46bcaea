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

from dataclasses import replace

import numpy as np

from leafsim.base.errors import LeafsimError
from leafsim.base.geometry import LeafShape, distance_to_outline
from leafsim.blade.budget import check_mesh_budget
from leafsim.blade.elements import Hinges, Springs, make_hinges, make_springs, t_edges
from leafsim.blade.kernels import greedy_colour
from leafsim.blade.masses import Masses, lump_masses
from leafsim.blade.petiole import Petiole, add_petiole, petiole_hinge_rods, rod_sides
from leafsim.blade.mesh import signed_areas, triangulate, vein_chains
from leafsim.blade.sample import patch_field, sample_particles
from leafsim.config.params import ParamSet
from leafsim.sim.model import (
    KIND_VORONOI,
    LAYER_T,
    LAYER_V,
    Model,
)
from leafsim.veins.graph import VeinGraph


def colour_sort(idx: np.ndarray, n: int):
    """Permutation sorting constraints by greedy colour, and the colour offsets."""
    if len(idx) == 0:
        return np.zeros(0, np.int64), np.zeros(1, np.int64)
    col = greedy_colour(np.ascontiguousarray(idx, np.int64), n)
    _, col = np.unique(col, return_inverse=True)
    perm = np.argsort(col, kind="stable")
    counts = np.bincount(col)
    return perm, np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)


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
    P = sample_particles(contour, veins, params, r, np.random.default_rng(seed), extra_points, holes)
    tri, P, remap = triangulate(P, contour, r, holes)
    vp, vw, vo = vein_chains(P, remap)
    base = int(np.argmin(np.linalg.norm(P.pts - np.asarray(shape.base, float), axis=1)))
    P, tri, vp, vw, vo, pet = add_petiole(P, tri, remap, base, shape, params, r, vp, vw, vo)
    nT, m = len(P.pts), len(tri)
    E = t_edges(P.pts, tri, vp, vo)
    rest = np.zeros((nT + m, 3))
    rest[:nT, :2] = P.pts
    rest[nT:, :2] = P.pts[tri].mean(1)
    rest[nT:, 2] = h
    tri_area = np.abs(signed_areas(P.pts, tri))
    S = make_springs(E, tri, rest, tri_area, nT, vp, vw)
    H = make_hinges(E, tri, rest, tri_area, S, vp, vw, vo)
    on_stalk, stalk_rod = petiole_hinge_rods(H.idx, pet)
    H = replace(H, rod=np.where(on_stalk, stalk_rod, H.rod), vein=H.vein | on_stalk)
    vol_idx = np.column_stack([np.arange(nT, nT + m), tri]).astype(np.int64)
    vol_rest0 = 2.0 * tri_area * h  # 6 × tetra volume = det = h × 2A
    M = lump_masses(P, tri, tri_area, S, E.n_T_springs, base, vp, vw, params, rod_sides(pet, len(P.pts)))
    model = _finalize(shape, P, tri, rest, S, H, vol_idx, vol_rest0, E.tri_edge, M, base, vp, vw, vo, remap, L, h, r, E.share)
    if pet is not None:
        model = _with_petiole(model, pet, veins)
    return replace(model, particle_patch=patch_field(model.particle_rest[:, :2], model.particle_area,
                                                     model.particle_layer == LAYER_T, L, seed))


def _with_petiole(model: Model, pet: Petiole, veins: VeinGraph) -> Model:
    """Mark the stalk's particles (its T particles and the V particles over its triangles), pin
    its tip instead of the base (hanging scene), give it the margin distance of a thin rod
    (d/2: it is all margin to the air) and texture coordinates on the photo's midrib next to the
    base (the stalk is vein tissue; the photo's own stalk is cut off or lies on the blade)."""
    nT = int((model.particle_layer == LAYER_T).sum())
    stalk = np.zeros(model.particle_count, bool)
    stalk[pet.first:nT] = True
    on = stalk[model.tri_T].any(1)
    stalk[model.tri_V[on]] = True
    pinned = np.zeros(model.particle_count, bool)
    pinned[pet.tip] = True
    margin = model.particle_margin_distance.copy()
    margin[stalk] = 0.5 * pet.diameter
    tex = model.particle_texcoord.copy()
    xy = model.particle_rest[:, :2] - model.particle_rest[model.base_particle, :2]
    along = np.clip(xy[stalk] @ pet.direction, 0.0, None)
    across = xy[stalk] @ np.array([-pet.direction[1], pet.direction[0]])
    mid = _midrib_from_base(model, veins)
    if mid is not None:
        # the stalk's length maps onto the first MIDRIB_SHARE of the midrib, its width onto the vein's
        total = max(float(along.max()), 1e-300)
        s_mid = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(mid, axis=0), axis=1))]
        t = np.clip(along / total, 0.0, 1.0) * min(MIDRIB_SHARE * model.length, s_mid[-1])
        px = np.interp(t, s_mid, mid[:, 0])
        py = np.interp(t, s_mid, mid[:, 1])
        k = np.clip(np.searchsorted(s_mid, t), 1, len(mid) - 1)
        tang = mid[k] - mid[k - 1]
        tang /= np.maximum(np.linalg.norm(tang, axis=1, keepdims=True), 1e-300)
        sq = 0.25 * np.clip(across / max(0.5 * pet.diameter, 1e-300), -1.0, 1.0) * model.spacing
        pts = np.column_stack([px - sq * tang[:, 1], py + sq * tang[:, 0]])
        ref = model.particle_rest[:, :2]
        # texcoords are affine in the rest position: fit the blade's map and apply it to the points
        Tb = np.flatnonzero(~stalk & (model.particle_layer == LAYER_T))
        X = np.column_stack([ref[Tb], np.ones(len(Tb))])
        A, *_ = np.linalg.lstsq(X, model.particle_texcoord[Tb], rcond=None)
        tex[stalk] = np.column_stack([pts, np.ones(len(pts))]) @ A
    return replace(model, particle_petiole=stalk, particle_pinned=pinned, particle_margin_distance=margin,
                   particle_texcoord=tex)


#: share of the leaf length of the midrib, from the base, whose photo pixels texture the stalk
MIDRIB_SHARE = 0.05


def _midrib_from_base(model: Model, veins: VeinGraph):
    """(k, 2) rest points of the order-0 vein that starts at the base (the midrib), or None."""
    base = model.particle_rest[model.base_particle, :2]
    best = None
    for v in veins.veins:
        if v.order != 0 or len(v.points) < 2:
            continue
        p = np.asarray(v.points, float)
        if np.linalg.norm(p[-1] - base) < np.linalg.norm(p[0] - base):
            p = p[::-1]
        dist = float(np.linalg.norm(p[0] - base))
        if best is None or dist < best[0]:
            best = (dist, p)
    return None if best is None else best[1]


def _finalize(shape, P, tri, rest, S: Springs, H: Hinges, vol_idx, vol_rest0, tri_edge, M: Masses, base,
              vp, vw, vo, remap, L, h, r, share) -> Model:
    """Colour-sort every constraint type and assemble the immutable Model."""
    nT, m = len(P.pts), len(tri)
    n_all = nT + m
    perm_s, s_cs = colour_sort(S.ij, n_all)
    inv_perm = np.empty_like(perm_s)
    inv_perm[perm_s] = np.arange(len(perm_s))
    sp = {k: getattr(S, k)[perm_s] for k in ("ij", "type", "order", "layer", "rest0", "weight", "rod", "face")}
    hinge_T, hinge_V, vol_springs = inv_perm[H.spring_T], inv_perm[H.spring_V], inv_perm[tri_edge.astype(np.int64)]
    perm_h, h_cs = colour_sort(H.idx, n_all)
    hs = {k: getattr(H, k)[perm_h] for k in ("idx", "edge_len", "area", "rod", "vein")}
    hinge_T, hinge_V = hinge_T[perm_h], hinge_V[perm_h]
    perm_v, v_cs = colour_sort(vol_idx, n_all)
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


