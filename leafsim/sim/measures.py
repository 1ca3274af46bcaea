"""What ``leafsim run --json`` reports of a leaf's state, as one library call.

>>> from leafsim.sim.measures import leaf_measures               # doctest: +SKIP
>>> m = leaf_measures(model, run.state, params)                   # the same numbers as run --json
>>> m["water_fraction"], m["shape_margin_lift"], m["shape_midrib_fold_deg"]
"""

from __future__ import annotations

import numpy as np

from leafsim.config.params import ParamSet
from leafsim.sim.crinkle import crinkle_stats
from leafsim.sim.curl import dried_shape
from leafsim.sim.model import Model, State
from leafsim.sim.shape import shape_metrics


def leaf_measures(model: Model, state: State, params: ParamSet) -> dict:
    """The state's water and shape, by the rules ``leafsim run`` reports them with:

    ``time_s`` simulated seconds; ``water_fraction`` the blade's water now / fresh (the petiole
    left out, :meth:`Model.water_fraction`); ``water_kg`` all water, ``blade_water_kg`` the
    blade's [kg]; ``petiole_water_fraction`` the stalk's own (None without one);
    ``shape_*``: :func:`~leafsim.sim.shape.shape_metrics` (lengths over the blade's length L; in
    the world frame on the ground, in the leaf's own best-fit frame when ``dynamics.scene`` lets
    it fall or hang), then, for a finite state, :func:`~leafsim.sim.curl.dried_shape` (margin
    roll, midrib fold, wrinkles) and :func:`~leafsim.sim.crinkle.crinkle_stats` (the lamina's
    excess length and the crinkle it draws)."""
    finite = bool(np.isfinite(state.particle_q).all())
    stalk = ~model.blade_particles
    out = {
        "time_s": round(float(state.time), 9),
        "water_fraction": round(model.water_fraction(state.particle_water), 6),
        **{f"shape_{k}": v for k, v in shape_metrics(
            model, state, own_frame=params["dynamics.scene"] != "ground" and finite).items()},
        **({f"shape_{k}": v for k, v in dried_shape(model, state).items()} if finite else {}),
        **({f"shape_{k}": v for k, v in crinkle_stats(model, state).items()} if finite else {}),
        "water_kg": float(state.particle_water.sum()),
        "blade_water_kg": float(state.particle_water[model.blade_particles].sum()),
        "petiole_water_fraction": (round(float(state.particle_water[stalk].sum()
                                               / max(float(model.particle_water0[stalk].sum()), 1e-300)), 6)
                                   if model.particle_petiole is not None else None),
    }
    return out
