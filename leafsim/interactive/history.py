"""The live plots' data: one record per published frame (water per layer, in the margin band and
the interior, residual, kinetic energy, iterations, ms per stage), kept for the last
:data:`HISTORY` frames."""

from __future__ import annotations

from collections import deque

import numpy as np

from leafsim.sim.kernels.pbd import residual
from leafsim.sim.model import LAYER_T, LAYER_V

#: stats history length (frames kept for the live plots)
HISTORY = 2000
#: the margin band and the interior whose water the plot follows: blade tissue within
#: MARGIN_BAND leaf lengths of the outline, and beyond INTERIOR_DEPTH (the drying report's bands)
MARGIN_BAND = 0.02
INTERIOR_DEPTH = 0.1
#: the record's fields
KEYS = ("frame", "time", "water_T", "water_V", "water", "water_margin", "water_interior", "residual", "kinetic",
        "iterations", "ms_osmosis", "ms_shrink", "ms_dynamics", "ms_colour", "ms_total")


def new_history() -> dict[str, deque]:
    """An empty history: one bounded deque per field."""
    return {k: deque(maxlen=HISTORY) for k in KEYS}


def history_record(model, simulator, state, ms: dict) -> dict:
    """One history record of a state (runs on the worker thread)."""
    w = state.particle_water
    lay = model.particle_layer
    finite = bool(np.isfinite(state.particle_q).all() and np.isfinite(w).all())
    mass = model.particle_cytosol + w
    qd = state.particle_qd
    b = model.blade_particles  # the blade's water: the petiole's dries last (Model.water_fraction)
    rec = {"frame": state.frame, "time": state.time, "water_T": float(w[(lay == LAYER_T) & b].sum()),
           "water_V": float(w[(lay == LAYER_V) & b].sum()), "water": model.water_fraction(w),
           "water_margin": _band_water(model, w, 0.0, MARGIN_BAND), "water_interior": _band_water(model, w, INTERIOR_DEPTH, None),
           "residual": float(residual(state.particle_q, model.spring_ij, state.spring_rest)) if finite else float("nan"),
           "kinetic": float(0.5 * (mass * (qd * qd).sum(1)).sum()) if finite else float("nan"),
           "iterations": simulator.iterations}
    tot = 0.0
    for k in ("osmosis", "shrink", "dynamics", "colour"):
        v = float(ms.get(k, 0.0))
        rec["ms_" + k] = v
        tot += v
    rec["ms_total"] = tot
    return rec


def _band_water(model, w: np.ndarray, lo: float, hi: float | None) -> float:
    """Water now / fresh of the blade's particles lo ≤ d / L < hi from the outline (NaN when
    the band holds none: a leaf narrower than the interior's depth)."""
    d = model.particle_margin_distance / max(float(model.length), 1e-300)
    sel = model.blade_particles & (d >= lo) & ((d < hi) if hi is not None else True)
    w0 = float(model.particle_water0[sel].sum())
    return float(w[sel].sum()) / w0 if w0 > 0.0 else float("nan")
