"""Vein growth from the leaf outline [Kim 2017; thesis §3.2–3.5]: :func:`grow_veins` runs
the stages of :mod:`leafsim.veins.stages` in order.

Orders: 0 main, 1 lateral, 2 sublateral, 3 net (tertiary).
"""

from __future__ import annotations

import numpy as np

from leafsim.base.geometry import LeafShape
from leafsim.config.params import ParamSet
from leafsim.veins.graph import VeinGraph
from leafsim.veins.grower import Grower
from leafsim.veins.stages import (
    given_laterals,
    given_main_veins,
    grow_laterals,
    grow_main_veins,
    fill_gaps,
    grow_net,
    grow_sublaterals,
    main_targets,
)
from leafsim.veins.stats import vein_stats


def grow_veins(
    shape: LeafShape,
    params: ParamSet,
    seed: int = 0,
    targets: np.ndarray | None = None,
    main_origin: str = "base",
    lateral_profile: np.ndarray | None = None,
    given: dict | None = None,
) -> VeinGraph:
    """Grow the whole venation of one leaf (deterministic for a given seed).

    Parameters
    ----------
    shape : the leaf outline in metres (base at origin, apex on +y).
    params : all parameters; the ``veins.*`` group is read.
    seed : random seed.
    targets : (k, 2) main-vein targets in metres, or None for automatic detection from lobes.
    main_origin : ``"base"`` (palmate: every main vein starts at the petiole) or
        ``"midrib"`` (pinnate lobes: secondary main veins branch off the midrib).
    lateral_profile : (k, 2) table, position along the main vein in % → lateral length factor.
    given : veins traced from a photo, in metres: {"mains": [midrib, ...], "laterals": [...],
        "parents": [...]} (:func:`leafsim.pipeline.photo_veins_world`); they replace the grown
        main veins and, when any are given, the grown laterals.
    """
    p = params
    rng = np.random.default_rng(seed)
    g = Grower(shape, p, rng)
    profile = np.asarray(lateral_profile if lateral_profile is not None else [[0, 1], [100, 1]], float)
    taper = p["veins.taper"]
    graph = VeinGraph()
    apex_t, others, auto = main_targets(shape, p, targets, main_origin)
    traced = None
    if given is not None and given.get("mains"):
        reached, traced = given_main_veins(g, graph, shape, p, given["mains"], main_origin, taper)
        auto = "photo"  # (the stats read "config" for main veins traced from the photo)
    else:
        reached = grow_main_veins(g, graph, shape, p, apex_t, others, main_origin, taper)
    if p["veins.lateral.enabled"] and given is not None and given.get("laterals"):
        given_laterals(g, graph, shape, p, given["laterals"], given["parents"], taper, traced)
    elif p["veins.lateral.enabled"]:
        grow_laterals(g, graph, shape, p, rng, profile, taper)
    fills = 0
    if p["veins.sub.enabled"]:
        grow_sublaterals(g, graph, shape, p, rng, taper)
        fills = fill_gaps(g, graph, shape, p, rng, taper)
    if p["veins.net.enabled"]:
        grow_net(g, graph, shape, p, rng, taper)
    graph.stats = vein_stats(graph, shape, reached, auto)
    graph.stats["collision_tests"] = g.tests
    graph.stats["gap_fills"] = fills
    if p["veins.lateral.enabled"] and given is not None and given.get("lateral_test"):
        # the photo's laterals: traced, or grown when none stands above its shuffled blade's
        graph.stats["photo_laterals"] = {**given["lateral_test"], "traced": len(given.get("laterals") or ())}
    return graph
