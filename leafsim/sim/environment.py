"""Evaporation from the weather: temperature, relative humidity and wind, through the leaf's
cuticular, stomatal and boundary-layer conductances, in SI and real time.

With ``environment.drive = weather`` the osmosis step takes its evaporation from here instead
of the declared ``osmosis.evaporation_*`` rates.  Per surface (top = layer V, adaxial; bottom =
layer T, abaxial) the water vapour leaves through the leaf's own conductance and the air's
boundary layer in series (Campbell & Norman 1998, ch. 7 and 14; Nobel 2009):

    E = g · VPD / P · M_w,      1/g = 1/(g_cuticle + g_stomata · f(RWC)) + 1/g_boundary

* VPD = e_s(T) (1 − RH), e_s by Tetens' formula; the leaf at air temperature (a detached leaf
  in shade: transpiration cools it by < 1 K at these rates).
* g_cuticle = g_min / 2 per side: g_min (``osmosis.g_min``) is the minimum leaf conductance
  after stomatal closure, per projected leaf area for both sides together, as compiled per
  species by Duursma et al. 2019 (New Phytol. 221:693).
* g_stomata = ``osmosis.g_stomata`` × the abaxial share (the species here are hypostomatous:
  ``osmosis.stomata_top`` = 0), opened by f(RWC) = 1 at RWC ≥ ``osmosis.stomata_open_rwc``,
  0 at RWC ≤ ``osmosis.stomata_closed_rwc``, linear between: a detached leaf loses its first
  10–20 % of water in an hour or two through open stomata, then slowly through the cuticle
  (the two phases of the detached-leaf drying curve).
* g_boundary = 0.147 √(u / d) mol m⁻² s⁻¹ per side for forced convection over a flat plate of
  characteristic dimension d = 0.72 × the blade's mean width (Campbell & Norman eq. 7.33 and
  the width rule of their table 7.1); still air counts as u = 0.1 m/s (free convection).

Time is real for the evaporation: each frame loses Δt × ``environment.time_warp`` real seconds
of it, so a leaf that takes a day to dry in the weather dries in a few simulated seconds.
Everything else keeps the simulated clock it was calibrated on: the blade's motion (drying is
quasi-static), diffusion within the blade (``osmosis.diffusion`` per simulated second, like the
declared rates), the tissue's setting (``dynamics.plasticity``) and the colour's ageing.

Example
-------
>>> round(vapour_pressure_deficit(20.0, 0.5), 3)   # kPa
1.169
"""

from __future__ import annotations

import math

import numpy as np

from leafsim.sim.model import LAYER_V, Model

#: molar mass of water [kg/mol] and standard air pressure [kPa]
M_WATER = 0.018015
P_AIR = 101.325
#: Campbell & Norman's forced-convection vapour conductance coefficient [mol m⁻² s⁻¹ (s/m)^½ m^½]
BOUNDARY_COEFF = 0.147
#: slowest air counted (free convection keeps a leaf's boundary layer open in still air) [m/s]
STILL_AIR = 0.1
#: characteristic dimension of a leaf / its mean width (Campbell & Norman, table 7.1)
WIDTH_FACTOR = 0.72


def saturation_vapour_pressure(t_celsius: float) -> float:
    """e_s [kPa] over water at ``t_celsius`` (Tetens 1930, as in Campbell & Norman eq. 3.8)."""
    return 0.6108 * math.exp(17.27 * t_celsius / (t_celsius + 237.3))


def vapour_pressure_deficit(t_celsius: float, rh: float) -> float:
    """VPD [kPa] of air at ``t_celsius`` and relative humidity ``rh`` (0–1)."""
    return saturation_vapour_pressure(t_celsius) * (1.0 - rh)


def boundary_conductance(wind: float, dimension: float) -> float:
    """Boundary-layer conductance for water vapour of one leaf side [mol m⁻² s⁻¹]."""
    return BOUNDARY_COEFF * math.sqrt(max(wind, STILL_AIR) / max(dimension, 1e-6))


def leaf_dimension(model: Model) -> float:
    """Characteristic dimension d [m]: 0.72 × the blade's mean width (area / length)."""
    area = float(model.particle_area[model.blade_T].sum())
    return WIDTH_FACTOR * area / max(model.length, 1e-9)


def stomatal_aperture(rwc: np.ndarray, closed: float, opened: float) -> np.ndarray:
    """f(RWC): 1 at RWC ≥ ``opened``, 0 at ≤ ``closed``, linear between."""
    span = max(opened - closed, 1e-9)
    return np.clip((rwc - closed) / span, 0.0, 1.0)


def clock_text(state, params) -> str:
    """The clock as a user reads it: real hours of weather when the weather drives the drying
    (``t = 12.4 h``), else the simulated seconds (``t = 1.234 s``)."""
    weather = params["environment.drive"] == "weather"
    if state is None:
        return "t = 0 h" if weather else "t = 0 s"
    if weather:
        return f"t = {state.weather_time / 3600.0:.2f} h"
    return f"t = {state.time:.3f} s"


class Weather:
    """Per-particle evaporation rates [kg m⁻² per simulated second] from the weather.

    Parameters
    ----------
    model : Model ; params : ParamSet (``environment.*``, ``osmosis.g_*``, ``osmosis.stomata_*``).
    edge : optional (n,) relative boundary-layer conductance (mean 1): the air's boundary layer
        is thinner near the margin (:func:`leafsim.sim.effects.osmosis.edge_factor`).
    """

    def __init__(self, model: Model, params, edge: np.ndarray | None = None):
        self.model = model
        self.top = model.particle_layer == LAYER_V
        self.edge = np.ones(model.particle_count) if edge is None else np.asarray(edge, float)
        self.configure(params)

    def configure(self, params) -> None:
        self.warp = float(params["environment.time_warp"])
        vpd = vapour_pressure_deficit(params["environment.temperature"], params["environment.humidity"])
        #: kg m⁻² s⁻¹ per mol m⁻² s⁻¹ of conductance
        self.flux_per_g = vpd / P_AIR * M_WATER
        self.g_b = boundary_conductance(params["environment.wind"], leaf_dimension(self.model)) * self.edge
        self.g_cut = 0.5e-3 * params["osmosis.g_min"]
        gs = 1e-3 * params["osmosis.g_stomata"]
        share = params["osmosis.stomata_top"]
        self.g_st = np.where(self.top, gs * share, gs * (1.0 - share))
        self.closed = params["osmosis.stomata_closed_rwc"]
        self.opened = max(params["osmosis.stomata_open_rwc"], self.closed)

    def conductance(self, rwc: np.ndarray) -> np.ndarray:
        """(n,) total vapour conductance of each particle's surface [mol m⁻² s⁻¹]."""
        g_leaf = self.g_cut + self.g_st * stomatal_aperture(rwc, self.closed, self.opened)
        return 1.0 / (1.0 / np.maximum(g_leaf, 1e-12) + 1.0 / self.g_b)

    def physical_rates(self, water: np.ndarray) -> np.ndarray:
        """(n,) evaporation [kg m⁻² s⁻¹ of real time] at the particles' water now."""
        rwc = water / np.maximum(self.model.particle_water0, 1e-300)
        return self.conductance(rwc) * self.flux_per_g

    def rates(self, water: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """(n,) evaporation per simulated second (× the time warp)."""
        r = self.physical_rates(water) * self.warp
        if out is not None:
            out[:] = r
            return out
        return r
