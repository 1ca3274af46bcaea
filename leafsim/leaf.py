"""Pipeline glue: species entry → outline in metres → vein graph (core, no OpenGL)."""

from __future__ import annotations

import numpy as np

from .geometry import (
    OUTLINE_END_TOLERANCE, LeafShape, distance_to_polygon, holes_problem, outline_problem, points_in_polygon,
    polygon_area, resample_closed, targets_problem,
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
        from .outline import to_leaf_shape

        traced = species_trace(sp, params)
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
    """:func:`leafsim.outline.trace_outline`, remembered per file (path, size, modification
    time), given ends and outline parameters; the last few traces are kept."""
    import os

    from .outline import trace_outline

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
    """The species photo traced with its config's base and apex."""
    return trace_photo(sp.image, params if params is not None else sp.params, sp.base_px, sp.apex_px)


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


def load_photo_rgba(path, max_pixels: int | None = None, traced=None) -> np.ndarray:
    """The species photo as (H, W, 4) uint8 RGB with alpha = leaf mask (textures, the GUI's
    photo panel), downscaled to at most ``max_pixels`` (default ``limits.image_pixels``;
    texture coordinates are relative, so any size fits).  With ``traced`` (its
    :class:`~leafsim.outline.TracedOutline`) the alpha is the traced blade — holes (closed
    sinuses) transparent, a petiole cut off — and a petiole lying on the blade is inpainted
    from the blade around it (it is no blade colour).  Raises LeafsimError naming the file
    when it cannot be read."""
    import cv2

    from .outline import load_image, segment_leaf, working_image
    from .params import PARAMS

    if max_pixels is None:
        max_pixels = PARAMS["limits.image_pixels"].default
    img, _ = working_image(load_image(path), int(max_pixels))
    rgb = cv2.cvtColor(np.ascontiguousarray(img[:, :, :3]), cv2.COLOR_BGR2RGB)
    if traced is None:
        return np.ascontiguousarray(np.dstack([rgb, segment_leaf(img, str(path))]))
    size = (img.shape[1], img.shape[0])
    fit = lambda m: cv2.resize(m, size, interpolation=cv2.INTER_NEAREST)  # noqa: E731  (working → texture size)
    mask = fit(traced.mask)
    if traced.hole_mask is not None:
        mask = cv2.bitwise_and(mask, cv2.bitwise_not(fit(traced.hole_mask)))
    if traced.petiole_mask is not None:
        band = cv2.dilate(fit(traced.petiole_mask), np.ones((5, 5), np.uint8))
        rgb = cv2.inpaint(rgb, band, max(3.0, 0.01 * max(size)), cv2.INPAINT_TELEA)
    return np.ascontiguousarray(np.dstack([rgb, mask]))


def species_photo_rgba(sp: Species, params: ParamSet | None = None) -> np.ndarray:
    """The species photo as a texture: :func:`load_photo_rgba` with its traced blade."""
    params = params if params is not None else sp.params
    return load_photo_rgba(sp.image, params["limits.image_pixels"], species_trace(sp, params))


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
