"""Pipeline glue: species entry → outline in metres → vein graph (core, no OpenGL)."""

from __future__ import annotations

import numpy as np

from .errors import LeafsimError
from .geometry import LeafShape, polygon_area, resample_closed
from .params import ParamSet
from .species import Species, drawn_contour
from .venation import VeinGraph, grow_veins


def leaf_shape(sp: Species, params: ParamSet | None = None) -> LeafShape:
    """The species' outline in world metres (photo traced, or drawn outline scaled)."""
    params = params if params is not None else sp.params
    n = params["outline.points"]
    if sp.image is None:
        c = drawn_contour(sp) * sp.length_m
        c = resample_closed(c, n)
        if polygon_area(c) < 0:
            c = c[::-1]
        r = np.linalg.norm(c, axis=1)
        apex = np.array([0.0, sp.length_m])
        return LeafShape(contour=c, base=np.zeros(2), apex=apex, lobes=np.empty((0, 2)), length=sp.length_m,
                         px_to_world=np.array([[1.0, 0, 0], [0, 1.0, 0]]), image=None, image_size=None)
    from .outline import to_leaf_shape, trace_outline

    traced = trace_outline(sp.image, params, base_px=sp.base_px, apex_px=sp.apex_px)
    return to_leaf_shape(traced, sp.length_m)


def species_veins(sp: Species, shape: LeafShape, params: ParamSet, seed: int) -> VeinGraph:
    """Grow the venation of a species (config targets win over automatic ones)."""
    targets = None if sp.targets is None else sp.targets * sp.length_m
    return grow_veins(shape, params, seed, targets=targets, main_origin=sp.main_origin, lateral_profile=sp.lateral_profile)


def resolve_params(sp: Species, overrides: dict | None = None) -> ParamSet:
    """Species parameters with user overrides applied (validated)."""
    return sp.params.with_overrides(overrides or {}, where="--set")


def load_photo_rgba(path) -> np.ndarray:
    """The species photo as (H, W, 4) uint8 RGB with alpha = leaf mask (textures, the GUI's
    photo panel).  Raises LeafsimError naming the file when it cannot be read."""
    import cv2

    from .outline import load_image, segment_leaf

    img = load_image(path)
    mask = segment_leaf(img, str(path))
    rgb = cv2.cvtColor(np.ascontiguousarray(img[:, :, :3]), cv2.COLOR_BGR2RGB)
    return np.ascontiguousarray(np.dstack([rgb, mask]))


def build_leaf(sp: Species, params: ParamSet, seed: int, report=None):
    """Species entry → (shape, veins, model): outline in metres, vein graph, blade Model.

    ``report(fraction, text)`` is called before each stage (progress bars; it may raise to
    cancel a build between stages)."""
    from .blade import build_blade

    report = report or (lambda p, t: None)
    report(0.02, "outline: tracing the leaf contour")
    shape = leaf_shape(sp, params)
    report(0.2, "veins: growing the venation")
    veins = species_veins(sp, shape, params, seed)
    report(0.5, "blade: particles, Delaunay/Voronoi layers, springs")
    model = build_blade(shape, veins, params, seed)
    return shape, veins, model
