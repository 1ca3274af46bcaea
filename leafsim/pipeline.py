"""The pipeline's stage order, in one place: species entry → outline in metres (stage 1,
:mod:`leafsim.outline`) → vein graph (stage 2, :mod:`leafsim.veins`) → blade model (stage 3,
:mod:`leafsim.blade`).  Every driver (the CLI, scenes, compare, export, the accuracy study,
the GUI's session) builds a leaf with :func:`build_leaf` and simulates it with
:class:`leafsim.sim.run.Run`.

>>> leaf = build_leaf(get_species("oak"), params, seed=0)   # doctest: +SKIP
>>> leaf.model.particle_count                                # doctest: +SKIP
"""

from __future__ import annotations

import math
import warnings
from dataclasses import replace
from typing import NamedTuple

import numpy as np

from leafsim.base.errors import LeafsimError, LeafsimWarning
from leafsim.base.geometry import (
    OUTLINE_END_TOLERANCE,
    LeafShape,
    distance_to_polygon,
    holes_problem,
    outline_problem,
    points_in_polygon,
    polygon_area,
    resample_closed,
    targets_problem,
)
from leafsim.blade.budget import check_mesh_budget
from leafsim.blade.build import build_blade
from leafsim.config.params import ParamSet, as_params, check_seed, show
from leafsim.config.species import Species
from leafsim.outline.drawn import drawn_contour
from leafsim.outline.trace import refuse_non_leaf, to_leaf_shape, trace_outline
from leafsim.sim.model import Model
from leafsim.sim.path import path_params
from leafsim.veins.graph import VeinGraph
from leafsim.veins.grow import grow_veins


def leaf_shape(sp: Species, params: ParamSet | None = None) -> LeafShape:
    """The species' outline in world metres (photo traced, or drawn outline scaled).

    Raises LeafsimError naming the config, species and key when the outline cannot be a leaf
    blade (see :func:`leafsim.base.geometry.outline_problem`).
    """
    params = params if params is not None else sp.params
    n = params["outline.points"]
    length = sp.length_m
    if isinstance(length, bool) or not isinstance(length, (int, float, np.floating)) or not (math.isfinite(length) and length > 0):
        # (a Species edited in code: the config's own check never saw it; NaN was reported as a bad outline)
        raise sp.error("length_m", f"{length!r}: expected a positive number of metres")
    if sp.image is None:
        c = drawn_contour(sp) * sp.length_m
        c = resample_closed(c, n)
        if polygon_area(c) < 0:
            c = c[::-1]
        apex = np.array([0.0, sp.length_m])
        shape = LeafShape(contour=c, base=np.zeros(2), apex=apex, lobes=np.empty((0, 2)), length=sp.length_m,
                          px_to_world=np.array([[1.0, 0, 0], [0, 1.0, 0]]), image=None, image_size=None)
        key = "outline.teeth" if sp.teeth else "outline"
    else:
        traced = species_trace(sp, params)
        try:
            found = refuse_non_leaf(traced)
        except LeafsimError as e:
            raise sp.error("image", str(e)) from None
        for text in found:  # (once per message and process: Python's warning registry)
            warnings.warn(LeafsimWarning(str(sp.error("image", text))), stacklevel=1)
        _check_given_ends(sp, traced)
        shape = to_leaf_shape(traced, sp.length_m)
        key = "image"
    problem = outline_problem(shape.contour, shape.base, shape.apex) or holes_problem(shape.holes, shape.contour)
    if problem:
        raise sp.error(key, f"the outline {problem}")
    return shape


#: traced photos kept for reuse (outline, texture and compare trace the same photo)
_TRACES: dict = {}
_TRACE_KEYS = ("outline.simplify", "outline.points", "outline.lobe_depth", "limits.image_pixels")


def trace_photo(path, params: ParamSet, base_px=None, apex_px=None):
    """:func:`leafsim.outline.trace.trace_outline`, remembered per file (path, size, modification
    time), given ends and outline parameters; the last few traces are kept."""
    import os

    try:
        st = os.stat(path)
        stamp = (st.st_size, st.st_mtime_ns)
    except OSError:
        stamp = None  # trace_outline reports the missing file
    key = (str(path), stamp, base_px, apex_px, tuple(params[k] for k in _TRACE_KEYS))
    if stamp is None or key not in _TRACES:
        traced = trace_outline(path, params, base_px=base_px, apex_px=apex_px)
        if stamp is None:
            return traced
        while len(_TRACES) >= 8:
            _TRACES.pop(next(iter(_TRACES)))
        _TRACES[key] = traced
    return _TRACES[key]


def species_trace(sp: Species, params: ParamSet | None = None):
    """The species photo traced with its config's base and apex (a given point off the photo:
    one line naming the species and its key)."""
    from leafsim.outline.trace import HintError

    try:
        return trace_photo(sp.image, params if params is not None else sp.params, sp.base_px, sp.apex_px)
    except HintError as e:
        raise sp.error(e.key, f"{e.detail.replace('lies outside the photo', f'lies outside the leaf traced in {sp.image}: off the photo')}") from None
    except LeafsimError as e:  # the photo itself (blank, no leaf, unreadable): say which entry names it
        text = str(e)
        if sp.config is not None and str(sp.config) in text:
            raise
        raise sp.error("image", text) from None


def _check_given_ends(sp: Species, traced) -> None:
    """``base_px`` / ``apex_px`` of a photo species must lie on (or inside) the traced leaf."""
    check_given_ends(traced, sp.image, {"base_px": sp.base_px, "apex_px": sp.apex_px}, sp.error)


def check_given_ends(traced, image, ends: dict, error) -> None:
    """Given leaf ends (``ends``: config key → photo pixel or None) must lie on or inside the leaf
    traced in ``image`` (within ``OUTLINE_END_TOLERANCE`` × its size outside it): a point on the
    background or on another leaf would set a wrong leaf axis.  ``error(key, message)`` makes
    the one-line error that names where the key came from."""
    c = traced.contour_px
    size = float(np.ptp(c, axis=0).max())
    for name, given in ends.items():
        if given is None:
            continue
        q = np.asarray(given, float).reshape(1, 2)
        if points_in_polygon(q, c)[0]:
            continue
        d = float(distance_to_polygon(q, c)[0])
        if d > OUTLINE_END_TOLERANCE * size:
            raise error(name, f"({q[0, 0]:.6g}, {q[0, 1]:.6g}) lies {d:.4g} px outside the leaf traced in {image} "
                              f"({traced.image_size[0]}×{traced.image_size[1]} px; expected a pixel on its margin)")


def species_veins(sp: Species, shape: LeafShape, params: ParamSet, seed: int) -> VeinGraph:
    """Grow the venation of a species (config targets win over automatic ones); a photo
    species takes its main veins (and laterals) from the photo (``veins.photo``)."""
    targets = None if sp.targets is None else sp.targets * sp.length_m
    if targets is not None:
        problem = targets_problem(targets, shape.contour, shape.length)
        if problem:
            raise sp.error("targets", problem)
    given = None
    if sp.image is not None and params["veins.photo"] != "off" and sp.targets is None:
        given = photo_veins_world(sp, shape, params)
    return grow_veins(shape, params, seed, targets=targets, main_origin=sp.main_origin, lateral_profile=sp.lateral_profile,
                      given=given)


#: traced photo venations kept for reuse, keyed like the traces
_VEINS: dict = {}


def photo_veins(sp: Species, params: ParamSet):
    """The species photo's own veins (:func:`leafsim.outline.venation.trace_venation`), in photo
    pixels, remembered per trace.  The main veins head for the lobe tips the grower would
    (:func:`leafsim.veins.stages.main_targets`)."""
    from leafsim.outline.image import load_image
    from leafsim.outline.venation import trace_venation
    from leafsim.veins.stages import main_targets

    traced = species_trace(sp, params)
    shape = leaf_shape(sp, params)
    _, others, _ = main_targets(shape, params, None, sp.main_origin)
    A = np.vstack([np.asarray(shape.px_to_world, float), [0.0, 0.0, 1.0]])
    lobes = [(np.linalg.inv(A) @ np.r_[t, 1.0])[:2] for t in others]
    key = (id(traced), sp.main_origin, tuple(np.round(np.ravel(lobes), 3)))
    if key not in _VEINS:
        import cv2

        img = load_image(sp.image)
        size = (img.shape[1], img.shape[0])
        up = lambda a: None if a is None else cv2.resize(a, size, interpolation=cv2.INTER_NEAREST)  # noqa: E731
        pv = trace_venation(img, up(traced.mask), traced.base_px, traced.apex_px, lobes, sp.main_origin,
                            exclude=up(traced.petiole_mask), holes=up(traced.hole_mask))
        while len(_VEINS) >= 8:
            _VEINS.pop(next(iter(_VEINS)))
        _VEINS[key] = (traced, pv)  # the trace is kept alive with its veins (the key is its id)
    return _VEINS[key][1]


def photo_veins_world(sp: Species, shape: LeafShape, params: ParamSet) -> dict:
    """:func:`photo_veins` in world metres for :func:`leafsim.veins.grow.grow_veins`'s ``given``:
    {"mains": [midrib, ...], "laterals": [...] (empty for ``veins.photo`` = main), "parents": [...]}."""
    pv = photo_veins(sp, params)
    A = np.asarray(shape.px_to_world, float)

    def world(p):
        return np.asarray(p, float) @ A[:, :2].T + A[:, 2]

    lat = params["veins.photo"] == "main+lateral"
    mains = [world(p) for p in pv.all_mains()]
    mains[0][0] = shape.base  # the midrib starts at the base exactly, ends near the apex
    return {"mains": mains, "laterals": [world(p) for p in pv.laterals] if lat else [],
            "parents": list(pv.parents) if lat else [], "lateral_test": dict(pv.lateral_test) if lat else {}}


class BuiltLeaf(NamedTuple):
    """What :func:`build_leaf` makes: the outline in metres, the vein graph, the blade model."""

    shape: LeafShape
    veins: VeinGraph
    model: Model


def build_leaf(sp: Species, params: ParamSet, seed: int, report=None) -> BuiltLeaf:
    """Species entry → :class:`BuiltLeaf` (shape, veins, model): outline in metres, vein graph,
    blade Model.

    ``report(fraction, text)`` is called before each stage (progress bars; it may raise to
    cancel a build between stages).  A species that is not a :class:`Species`, params that are
    not a :class:`ParamSet` or a seed outside [0, 2**63-1] is one LeafsimError line."""
    if not isinstance(sp, Species):
        raise LeafsimError(f"build_leaf: species {show(sp)} ({type(sp).__name__}): expected a Species, e.g. get_species('oak')")
    params = as_params(params, "build_leaf")
    seed = check_seed(seed, "build_leaf")
    report = report or (lambda p, t: None)
    report(0.02, "outline: tracing the leaf contour")
    shape = leaf_shape(sp, params)
    check_mesh_budget(shape, params)  # refuse a too-large model before growing the veins
    report(0.2, "veins: growing the venation")
    veins = species_veins(sp, shape, params, seed)
    report(0.5, "blade: particles, Delaunay/Voronoi layers, springs")
    model = replace(build_blade(shape, veins, params, seed), seed=seed, built_with=params.build_values())
    coarse = path_params_for(params)
    if coarse is not None:
        report(0.85, "blade: the coarser mesh that carries the drying (dynamics.path)")
        model = replace(model, path=replace(_with_path(shape, veins, coarse, seed), seed=seed))
    return BuiltLeaf(shape, veins, model)


def _with_path(shape: LeafShape, veins: VeinGraph, params: ParamSet, seed: int) -> Model:
    """The blade of ``params`` with the drying-path mesh its own parameters ask for (the
    ``fine`` path's mesh has the draft one below it)."""
    model = build_blade(shape, veins, params, seed)
    coarse = path_params_for(params)
    return model if coarse is None else replace(model, path=_with_path(shape, veins, coarse, seed))


def path_params_for(params: ParamSet) -> ParamSet | None:
    """The parameters of the drying-path mesh (``dynamics.path``), or None when the leaf's own
    mesh carries the whole drying (``own``, or a mesh not finer than the path's)."""
    level = params["dynamics.path"]
    if level == "own":
        return None
    p = path_params(params, level)
    return p if p["mesh.spacing"] > params["mesh.spacing"] * 1.001 else None
