"""Colour on the real pipeline: the spatial pattern must emerge from the simulated water field."""

import numpy as np
import pytest

from leafsim.appearance.reflectance import pigments_to_rgb
from leafsim.interactive.session import Session
from leafsim.sim.model import KIND_CONTOUR, KIND_VEIN, LAYER_T

COLOUR_ONLY = {"effects.shrink": False, "effects.gravity": False, "effects.pbd": False, "effects.bending": False,
               "effects.ground": False, "effects.self_collision": False, "mesh.spacing": 0.04}


def _rgb(s):
    return pigments_to_rgb(s.pigments, s.simulator.params if s.simulator else s.params)


@pytest.mark.parametrize("species", ["chestnut", "maple"])
def test_margins_turn_before_veins(species):
    s = Session(species, overrides={**COLOUR_ONLY, "colour.age_rate": 0.1}, build=True)
    m = s.model
    rgb0 = _rgb(s).copy()
    s.step(600)  # ~ a quarter of the water gone, mid-senescence
    rgb = _rgb(s)
    T = m.particle_layer == LAYER_T
    margin = T & (m.particle_kind == KIND_CONTOUR)
    vein = T & (m.particle_kind == KIND_VEIN) & (m.particle_vein_order <= 1)
    d = np.linalg.norm(rgb - rgb0, axis=1)
    assert margin.sum() > 10 and vein.sum() > 10
    # the cause: light margin tissue loses relatively more water (per-area evaporation; the
    # veins' rods hold more water per area and feed their neighbours by osmosis) ...
    wrel = s.state.particle_water / m.particle_water0
    assert 1 - wrel[margin].mean() > 1.04 * (1 - wrel[vein].mean())
    # ... so the margin's colour has moved farther from the young green than the veins'
    assert d[margin].mean() > 1.04 * d[vein].mean()
    # and the positions did not move: dynamics is off in a colour-only scene
    assert np.array_equal(s.state.particle_q, m.particle_rest)


def test_no_water_loss_no_senescence_colour_constant():
    s = Session("oak", overrides={**COLOUR_ONLY, "osmosis.evaporation_top": 0, "osmosis.evaporation_bottom": 0,
                                  "colour.age_rate": 0.0, "colour.season": 0.0}, build=True)
    rgb0 = _rgb(s).copy()
    s.step(200)
    assert np.abs(_rgb(s) - rgb0).max() < 1e-6


def test_water_in_the_pipeline_is_monotone_and_non_negative():
    s = Session("maple", overrides={**COLOUR_ONLY, "osmosis.evaporation_top": 0.35, "osmosis.evaporation_bottom": 0.28}, build=True)
    prev = s.total_water()
    for _ in range(20):
        s.step(10)
        w = s.state.particle_water
        assert (w >= 0).all() and np.isfinite(w).all()
        assert s.total_water() <= prev + 1e-12
        prev = s.total_water()


def test_pigment_heat_maps_available_and_evolve():
    s = Session("maple", overrides={**COLOUR_ONLY, "colour.age_rate": 0.5}, build=True)
    s.render_mesh()  # sets the render index
    f0 = s.scalar_fields()
    assert {"chlorophyll", "carotenoid", "anthocyanin", "browning", "mass", "water"} <= set(f0)
    chl0 = f0["chlorophyll"].copy()
    s.step(300)
    f1 = s.scalar_fields()
    assert (f1["chlorophyll"] <= chl0 + 1e-6).all() and f1["chlorophyll"].mean() < chl0.mean()
    assert f1["anthocyanin"].mean() > f0["anthocyanin"].mean()  # maple reddens
