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
    it fall or hang), then :func:`~leafsim.sim.curl.dried_shape` (margin roll, midrib fold,
    wrinkles) and :func:`~leafsim.sim.crinkle.crinkle_stats` (the lamina's excess length and the
    crinkle it draws), None for a state holding NaN.  Refuses a state of another model and params
    that set a parameter the model is built from otherwise (one line)."""
    from leafsim.base.errors import LeafsimError
    from leafsim.config.params import as_params
    from leafsim.sim.simulator import check_built_with

    if not isinstance(model, Model):
        hint = " (pass leaf.model, the model of build_leaf's result)" if hasattr(model, "model") else ""
        raise LeafsimError(f"leaf_measures: model is a {type(model).__name__}, expected a Model{hint}")
    if not isinstance(state, State):
        raise LeafsimError(f"leaf_measures: state is a {type(state).__name__}, expected a State (run.state)")
    if (state.model_key and state.model_key != model.fingerprint) or getattr(state.particle_q, "shape", None) != (model.particle_count, 3):
        raise LeafsimError("leaf_measures: the state is a state of another model (another build: its seed, mesh or "
                           "species differ), expected one of this model (run.state)")
    params = as_params(params, "leaf_measures")
    check_built_with(model, params, "leaf_measures")
    finite = bool(np.isfinite(state.particle_q).all())
    stalk = ~model.blade_particles
    out = {
        "time_s": round(float(state.time), 9),
        "water_fraction": round(model.water_fraction(state.particle_water), 6),
        **{f"shape_{k}": v for k, v in shape_metrics(
            model, state, own_frame=params["dynamics.scene"] != "ground" and finite).items()},
        # (a state with NaN has every key, as None: a script reading one of them met a KeyError)
        **{f"shape_{k}": v if finite else None for k, v in dried_shape(model, state if finite else model.state()).items()},
        **{f"shape_{k}": v if finite else None for k, v in crinkle_stats(model, state if finite else model.state()).items()},
        "water_kg": float(state.particle_water.sum()),
        "blade_water_kg": float(state.particle_water[model.blade_particles].sum()),
        "petiole_water_fraction": (round(float(state.particle_water[stalk].sum()
                                               / max(float(model.particle_water0[stalk].sum()), 1e-300)), 6)
                                   if model.particle_petiole is not None else None),
    }
    return out
