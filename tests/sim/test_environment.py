"""The weather drive: vapour-pressure deficit, conductances in series, stomata that shut as
the tissue dries, the weather clock, and the osmosis step's invariants under it."""

import math

import numpy as np
import pytest

from helpers.synthetic import ellipse_shape, synthetic_veins
from leafsim.blade.build import build_blade
from leafsim.config.params import ParamSet
from leafsim.sim.effects.osmosis import edge_factor
from leafsim.sim.environment import (
    M_WATER,
    P_AIR,
    Weather,
    boundary_conductance,
    clock_text,
    leaf_dimension,
    saturation_vapour_pressure,
    stomatal_aperture,
    vapour_pressure_deficit,
)
from leafsim.sim.model import LAYER_T, LAYER_V
from leafsim.sim.simulator import Simulator

COARSE = {"mesh.spacing": 0.05, "environment.drive": "weather"}


@pytest.fixture(scope="module")
def model():
    s = ellipse_shape()
    return build_blade(s, synthetic_veins(s), ParamSet(COARSE), seed=2)


def test_vapour_pressure_and_cuticular_flux_match_tabulated_values():
    # e_s: 2.338 kPa at 20 °C and 3.169 kPa at 25 °C (Campbell & Norman, table A.3)
    assert saturation_vapour_pressure(20.0) == pytest.approx(2.338, abs=0.004)
    assert saturation_vapour_pressure(25.0) == pytest.approx(3.169, abs=0.006)
    assert vapour_pressure_deficit(20.0, 0.5) == pytest.approx(1.169, abs=0.003)
    assert vapour_pressure_deficit(20.0, 1.0) == 0.0
    # g_min 4.5 mmol m⁻² s⁻¹ at 20 °C / 50 % RH: ≈ 3.4 g m⁻² h⁻¹
    flux = 4.5e-3 * vapour_pressure_deficit(20.0, 0.5) / P_AIR * M_WATER * 3600 * 1e3
    assert flux == pytest.approx(3.37, abs=0.03)


def test_conductances_in_series_and_stomata(model):
    p = ParamSet(COARSE)
    w = Weather(model, p)
    full = model.particle_water0
    g_open = w.conductance(np.ones(model.particle_count))
    g_shut = w.conductance(np.full(model.particle_count, 0.5))
    bottom, top = model.particle_layer == LAYER_T, model.particle_layer == LAYER_V
    gb = boundary_conductance(p["environment.wind"], leaf_dimension(model))
    # shut: the cuticle's half of g_min per side, in series with the boundary layer
    gc = 0.5e-3 * p["osmosis.g_min"]
    assert np.allclose(g_shut, 1 / (1 / gc + 1 / gb))
    # open: the stomata are on the bottom (hypostomatous default), the top keeps its cuticle
    assert np.allclose(g_open[top], g_shut[top])
    assert np.allclose(g_open[bottom], 1 / (1 / (gc + 1e-3 * p["osmosis.g_stomata"]) + 1 / gb))
    assert stomatal_aperture(np.array([1.0, 0.91, 0.85, 0.5]), 0.85, 0.97) == pytest.approx([1.0, 0.5, 0.0, 0.0])
    # more wind, a thinner boundary layer: more evaporation, never above the leaf's own limit
    calm = Weather(model, p.with_overrides({"environment.wind": 0.0})).physical_rates(full)
    windy = Weather(model, p.with_overrides({"environment.wind": 10.0})).physical_rates(full)
    assert (windy > calm).all()
    assert (windy <= (gc + 1e-3 * p["osmosis.g_stomata"]) * vapour_pressure_deficit(20.0, 0.5) / P_AIR * M_WATER + 1e-15).all()
    # saturated air: no evaporation
    assert np.all(Weather(model, p.with_overrides({"environment.humidity": 0.99})).physical_rates(full) <
                  0.03 * w.physical_rates(full))


def _dry(model, params, hours):
    sim = Simulator(model, params, effects=("osmosis",))
    st = model.state()
    w0 = model.particle_water0.sum()
    per_frame = params["dynamics.dt"] * params["environment.time_warp"]
    out, losses = [], []
    for h in hours:
        while st.weather_time < h * 3600 - 1e-6:
            before = st.particle_water.sum()
            sim.step(st)
            assert st.particle_water.min() >= 0.0
            losses.append(before - st.particle_water.sum())
        out.append(st.particle_water.sum() / w0)
    assert st.weather_time == pytest.approx(st.frame * per_frame)
    return np.array(out), np.array(losses)


def test_weather_drying_two_phases_and_clock(model):
    p = ParamSet(COARSE)
    rwc, losses = _dry(model, p, [0.5, 2, 6, 12, 24])
    assert (np.diff(rwc) < 0).all() and rwc[-1] > 0
    # open stomata first: the first frames lose water many times faster than the cuticle later
    assert losses[:3].mean() > 5 * losses[-3:].mean()
    # by 2 h the stomata have shut (RWC below the closing point) and the loss is cuticular:
    # its rate is g_cut VPD / P M_w per side × both sides' area (the boundary layer barely limits)
    w = Weather(model, p, edge_factor(model, p["osmosis.edge_evaporation"], p["osmosis.edge_length"]))
    gc = w.conductance(np.full(model.particle_count, 0.5)) * w.flux_per_g
    expect = float((gc * model.particle_area).sum()) * p["dynamics.dt"] * p["environment.time_warp"]
    assert losses[-1] == pytest.approx(expect, rel=1e-6)
    assert clock_text(model.state(), p) == "t = 0.00 h"


def test_time_warp_changes_the_clock_not_the_drying(model):
    hours = [1, 4, 10]
    a, _ = _dry(model, ParamSet(COARSE), hours)
    b, _ = _dry(model, ParamSet({**COARSE, "environment.time_warp": 1.5e4}), hours)
    assert np.abs(a - b).max() < 0.005
    assert math.isclose(ParamSet(COARSE)["environment.time_warp"], 3.0e4)
