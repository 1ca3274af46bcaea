"""The simulator: runs only the enabled effects, in SPEC order, and times each stage.

Example
-------
>>> sim = Simulator(model, ParamSet())          # doctest: +SKIP
>>> state = model.state()                        # doctest: +SKIP
>>> ms = sim.step(state)                         # {'osmosis': 0.3, 'shrink': 0.05, 'dynamics': 0.9}
"""

from __future__ import annotations

import time

from ..params import ParamSet
from .effects import Dynamics, Osmosis, Shrink
from .model import Model, State

EFFECTS = ("osmosis", "shrink", "gravity", "pbd", "bending", "ground", "self_collision", "colour")


class Simulator:
    """Composes the enabled stages for one model.

    Parameters
    ----------
    model : Model
    params : ParamSet — ``osmosis.*``, ``shrink.*``, ``dynamics.*`` and ``effects.*``.
    effects : optional iterable of effect names to enable (overrides ``effects.*``).
    """

    def __init__(self, model: Model, params: ParamSet, effects=None):
        self.model = model
        self._osmosis = None
        self._shrink = None
        self._dynamics = None
        self._override = None if effects is None else set(effects)
        if self._override is not None:
            bad = self._override - set(EFFECTS)
            if bad:
                from ..errors import LeafsimError
                raise LeafsimError(f"unknown effect(s) {', '.join(sorted(bad))}: expected some of {', '.join(EFFECTS)}")
        self.set_params(params)

    def set_params(self, params: ParamSet) -> None:
        """Apply (live) parameters; matrices are refactored only when Δt or λ change."""
        self.params = params
        if self._override is None:
            self.effects = {e: bool(params[f"effects.{e}"]) for e in EFFECTS}
        else:
            self.effects = {e: e in self._override for e in EFFECTS}
        e = self.effects
        if e["osmosis"]:
            self._osmosis = self._osmosis or Osmosis(self.model)
            self._osmosis.configure(params)
        if e["shrink"]:
            self._shrink = self._shrink or Shrink(self.model)
            self._shrink.configure(params)
        self.dynamic = e["pbd"] or e["gravity"]
        if self.dynamic:
            self._dynamics = self._dynamics or Dynamics(self.model)
            self._dynamics.configure(params, e)
        self.dt = params["dynamics.dt"]

    @property
    def iterations(self) -> int:
        """PBD iterations used in the last step."""
        return self._dynamics.last_iterations if (self._dynamics and self.dynamic) else 0

    def step(self, state: State) -> dict:
        """Advance one frame in place; returns milliseconds per executed stage."""
        ms = {}
        t0 = time.perf_counter()
        if self.effects["osmosis"]:
            self._osmosis.apply(state)
            t1 = time.perf_counter()
            ms["osmosis"] = (t1 - t0) * 1e3
            t0 = t1
        if self.effects["shrink"]:
            self._shrink.apply(state)
            t1 = time.perf_counter()
            ms["shrink"] = (t1 - t0) * 1e3
            t0 = t1
        if self.dynamic:
            self._dynamics.apply(state)
            t1 = time.perf_counter()
            ms["dynamics"] = (t1 - t0) * 1e3
        state.scalars[0] += self.dt
        state.scalars[1] += 1
        return ms
