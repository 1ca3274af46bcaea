"""Pipeline glue: species entry → outline in metres → vein graph (core, no OpenGL)."""

from __future__ import annotations

import numpy as np

from .geometry import (
    OUTLINE_END_TOLERANCE, LeafShape, distance_to_polygon, outline_problem, points_in_polygon, polygon_area,
    resample_closed, targets_problem,
)
from .params import ParamSet
from .species import Species, drawn_contour
from .venation import VeinGraph, grow_veins


def leaf_shape(sp: Species, params: ParamSet | None = None) -> LeafShape:
    """The species' outline in world metres (photo traced, or drawn outline scaled).

    Raises LeafsimError naming the config, species and key when the outline cannot be a leaf
    blade (see :func:`leafsim.geometry.outline_problem`).
    """
    params = params if params is not None else sp.params
    n = params["outline.points"]
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
        from .outline import to_leaf_shape, trace_outline

        traced = trace_outline(sp.image, params, base_px=sp.base_px, apex_px=sp.apex_px)
        _check_given_ends(sp, traced)
        shape = to_leaf_shape(traced, sp.length_m)
        key = "image"
    problem = outline_problem(shape.contour, shape.base, shape.apex)
    if problem:
        raise sp.error(key, f"the outline {problem}")
    return shape


def _check_given_ends(sp: Species, traced) -> None:
    """``base_px`` / ``apex_px`` of a photo species must lie on (or inside) the traced leaf."""
    c = traced.contour_px
    size = float(np.ptp(c, axis=0).max())
    for name, given in (("base_px", sp.base_px), ("apex_px", sp.apex_px)):
        if given is None:
            continue
        q = np.asarray(given, float).reshape(1, 2)
        if points_in_polygon(q, c)[0]:
            continue
        d = float(distance_to_polygon(q, c)[0])
        if d > OUTLINE_END_TOLERANCE * size:
            raise sp.error(name, f"({q[0, 0]:.6g}, {q[0, 1]:.6g}) lies {d:.4g} px outside the leaf traced in {sp.image} "
                                 f"({traced.image_size[0]}×{traced.image_size[1]} px; expected a pixel on its margin)")


def species_veins(sp: Species, shape: LeafShape, params: ParamSet, seed: int) -> VeinGraph:
    """Grow the venation of a species (config targets win over automatic ones)."""
    targets = None if sp.targets is None else sp.targets * sp.length_m
    if targets is not None:
        problem = targets_problem(targets, shape.contour, shape.length)
        if problem:
            raise sp.error("targets", problem)
    return grow_veins(shape, params, seed, targets=targets, main_origin=sp.main_origin, lateral_profile=sp.lateral_profile)


def resolve_params(sp: Species, overrides: dict | None = None) -> ParamSet:
    """Species parameters with user overrides applied (validated)."""
    return sp.params.with_overrides(overrides or {}, where="--set")


def load_photo_rgba(path, max_pixels: int | None = None) -> np.ndarray:
    """The species photo as (H, W, 4) uint8 RGB with alpha = leaf mask (textures, the GUI's
    photo panel), downscaled to at most ``max_pixels`` (default ``limits.image_pixels``;
    texture coordinates are relative, so any size fits).  Raises LeafsimError naming the file
    when it cannot be read."""
    import cv2

    from .outline import load_image, segment_leaf, working_image
    from .params import PARAMS

    if max_pixels is None:
        max_pixels = PARAMS["limits.image_pixels"].default
    img, _ = working_image(load_image(path), int(max_pixels))
    mask = segment_leaf(img, str(path))
    rgb = cv2.cvtColor(np.ascontiguousarray(img[:, :, :3]), cv2.COLOR_BGR2RGB)
    return np.ascontiguousarray(np.dstack([rgb, mask]))


def build_leaf(sp: Species, params: ParamSet, seed: int, report=None):
    """Species entry → (shape, veins, model): outline in metres, vein graph, blade Model.

    ``report(fraction, text)`` is called before each stage (progress bars; it may raise to
    cancel a build between stages)."""
    from .blade import build_blade, check_mesh_budget

    report = report or (lambda p, t: None)
    report(0.02, "outline: tracing the leaf contour")
    shape = leaf_shape(sp, params)
    check_mesh_budget(shape, params)  # refuse a too-large model before growing the veins
    report(0.2, "veins: growing the venation")
    veins = species_veins(sp, shape, params, seed)
    report(0.5, "blade: particles, Delaunay/Voronoi layers, springs")
    model = build_blade(shape, veins, params, seed)
    return shape, veins, model
