"""The weather-driven drying curve against a measured one.

A detached leaf's relative water content RWC(t) = (FW − DW)/(FW_sat − DW), measured by
weighing (the pvldcurve kohlrabi data in tests/data: 12 leaves, ≈ 11 h at 24 °C / 49 % RH),
beside the model's RWC(t) for a leaf of the same dry mass and water per area in the same
weather (``environment.drive = weather``): only osmosis runs, since RWC does not depend on
the blade's shape.  :func:`fit` finds the leaf conductances (g_min, g_stomata, the RWC at
which the stomata shut) that reproduce the measured median, to compare with the published
g_min of other species.

Example
-------
>>> data = load_curves("tests/data/pvldcurve_kohlrabi_leaf_drying_RWC.csv")   # doctest: +SKIP
>>> model_curve(leaf_overrides(data), data.hours)                               # doctest: +SKIP
"""

from __future__ import annotations

import csv
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from leafsim.base.errors import LeafsimError
from leafsim.config.species import get_species
from leafsim.pipeline import build_leaf
from leafsim.sim.run import Run

#: hours at which measured and modelled curves are compared (every leaf was weighed over 0–11 h)
GRID_HOURS = tuple(np.round(np.arange(0.0, 11.01, 0.5), 2))
#: mesh of the model leaf (RWC needs no fine mesh: the water field is smooth)
SPACING = 0.04


@dataclass
class Curves:
    """Measured curves on a common hour grid: per-leaf RWC (leaves × hours, NaN outside a
    leaf's weighings), their median, min and max, and the leaves' mean traits."""

    hours: np.ndarray
    rwc: np.ndarray
    median: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    lma: float            # dry mass per area [kg/m²]
    water_fraction: float  # water / saturated fresh mass
    water_per_area: float  # [kg/m²]


def load_curves(path, hours=GRID_HOURS) -> Curves:
    """Read the pvldcurve drying table (columns ``sample``, ``leaf.area`` [cm²],
    ``dry.weight``, ``fresh.weight.saturated`` [g], ``hours``, ``RWC``)."""
    path = Path(path)
    try:
        with path.open(newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
        by = defaultdict(list)
        for r in rows:
            by[r["sample"]].append((float(r["hours"]), float(r["RWC"]), float(r["leaf.area"]) * 1e-4,
                                    float(r["dry.weight"]) * 1e-3, float(r["fresh.weight.saturated"]) * 1e-3))
    except (OSError, KeyError, ValueError) as e:
        raise LeafsimError(f"{path}: not a pvldcurve drying table ({type(e).__name__}: {e})") from None
    if not by:
        raise LeafsimError(f"{path}: no rows")
    hours = np.asarray(hours, float)
    rwc, lma, wf, wpa = [], [], [], []
    for leaf in by.values():
        leaf.sort()
        t, r = np.array([x[0] for x in leaf]), np.array([x[1] for x in leaf])
        rwc.append(np.where((hours >= t[0]) & (hours <= t[-1]), np.interp(hours, t, r), np.nan))
        area, dw, fws = leaf[0][2:]
        lma.append(dw / area)
        wf.append((fws - dw) / fws)
        wpa.append((fws - dw) / area)
    rwc = np.array(rwc)
    return Curves(hours, rwc, np.nanmedian(rwc, 0), np.nanmin(rwc, 0), np.nanmax(rwc, 0),
                  float(np.mean(lma)), float(np.mean(wf)), float(np.mean(wpa)))


def measured_window(path) -> tuple[str, str]:
    """First and last weighing time (``t`` column, ISO text) of a pvldcurve drying table."""
    try:
        with Path(path).open(newline="", encoding="utf-8") as f:
            t = sorted(r["t"] for r in csv.DictReader(f))
    except (OSError, KeyError) as e:
        raise LeafsimError(f"{path}: not a pvldcurve drying table with a t column ({e})") from None
    if not t:
        raise LeafsimError(f"{path}: no rows")
    return t[0], t[-1]


def mean_weather(path, window: tuple[str, str] | None = None) -> tuple[float, float]:
    """Mean air temperature [°C] and relative humidity (0–1) of the pvldcurve weather log,
    over ``window`` (first, last ISO time; the whole log when None)."""
    try:
        with Path(path).open(newline="", encoding="utf-8") as f:
            rows = [r for r in csv.DictReader(f) if window is None or window[0] <= r["t"] <= window[1]]
        if not rows:
            raise ValueError("no logged time inside the weighings' window")
        return (float(np.mean([float(r["temperature"]) for r in rows])),
                float(np.mean([float(r["humidity"]) for r in rows])) / 100.0)
    except (OSError, KeyError, ValueError) as e:
        raise LeafsimError(f"{path}: not a weather log with t, temperature and humidity columns ({e})") from None


def leaf_overrides(curves: Curves, temperature: float, humidity: float, wind: float = 0.0) -> dict:
    """Parameters of a model leaf with the measured leaves' dry mass and water per area, in
    that weather (still air by default: leaves on a lab bench)."""
    return {"mass.lma": curves.lma, "mass.water_fraction": curves.water_fraction,
            "environment.drive": "weather", "environment.temperature": temperature,
            "environment.humidity": humidity, "environment.wind": wind, "mesh.spacing": SPACING,
            "osmosis.stomata_top": 0.5}  # kohlrabi (Brassica) is amphistomatous


class CurveModel:
    """RWC(t) of one model leaf under changing conductances (the leaf is built once)."""

    def __init__(self, overrides: dict, species: str = "maple", seed: int = 0):
        self.sp = get_species(species)
        # the blade alone: the measured leaves are kohlrabi's, not this species', so the model
        # leaf takes their dry mass and water per area and none of the species' stalk
        self.base = self.sp.params.with_overrides({**overrides, "effects.colour": False, "petiole.length": 0.0})
        self.model = build_leaf(self.sp, self.base, seed).model

    def __call__(self, hours, changes: dict | None = None) -> np.ndarray:
        p = self.base.with_overrides(changes or {})
        run = Run(self.model, p, effects=["osmosis"])
        per_frame = p["dynamics.dt"] * p["environment.time_warp"] / 3600.0  # hours per frame
        w0 = float(self.model.particle_water0.sum())
        out = []
        for h in hours:
            while run.state.frame * per_frame < h - 1e-9:
                run.step()
            out.append(float(run.state.particle_water.sum()) / w0)
        return np.array(out)


def model_curve(overrides: dict, hours, species: str = "maple", seed: int = 0) -> np.ndarray:
    """RWC of the model leaf at ``hours`` (one osmosis-only run)."""
    return CurveModel(overrides, species, seed)(hours)


FIT_KEYS = ("osmosis.g_min", "osmosis.g_stomata", "osmosis.stomata_closed_rwc")


def fit(curves: Curves, overrides: dict, species: str = "maple") -> dict:
    """Least-squares conductances (:data:`FIT_KEYS`) for the measured median RWC; returns the
    values, the RMS error and the share of grid hours inside the leaves' min–max band."""
    from scipy.optimize import least_squares

    cm = CurveModel(overrides, species)
    ok = np.isfinite(curves.median)
    hours = curves.hours[ok]

    def changes(x):
        return {"osmosis.g_min": float(np.exp(x[0])), "osmosis.g_stomata": float(np.exp(x[1])),
                "osmosis.stomata_closed_rwc": float(x[2])}

    def resid(x):
        return cm(hours, changes(x)) - curves.median[ok]

    x0 = np.array([np.log(5.0), np.log(50.0), 0.85])
    sol = least_squares(resid, x0, bounds=([np.log(0.1), np.log(1.0), 0.5], [np.log(50.0), np.log(1000.0), 0.96]),
                        diff_step=1e-3, xtol=1e-6)
    best = changes(sol.x)
    curve = cm(curves.hours, best)
    return {"values": best, "curve": curve, "rms": float(np.sqrt(np.mean(resid(sol.x) ** 2))),
            "in_band": float(np.mean((curve[ok] >= curves.lo[ok] - 1e-9) & (curve[ok] <= curves.hi[ok] + 1e-9)))}
