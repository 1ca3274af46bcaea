"""The colour effect (SPEC §9): pigment kinetics per particle, driven by the season clock and
the local relative water (:mod:`leafsim.sim.pigments`)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from leafsim.sim.model import Model, State
from leafsim.sim.pigments import age_at, init_pigments, step_pigments
from leafsim.sim.senescence import FIELD_KEYS, senescence_field


class Colour:
    """Pigment aging (SPEC §9): chlorophyll, carotenoids, anthocyanins and browning per
    particle, driven by the season clock and the local relative water.  The pigments live in
    ``State.pigments`` (made by :meth:`init`), so a state snapshot carries its colour."""

    def __init__(self, model: Model):
        self.model = model
        self._field = None  # ((field parameter values, seed), (rate, spot, max rate, max spot))
        self.w_rel = np.zeros(model.particle_count, np.float32)
        self.inv_w0 = 1.0 / np.maximum(model.particle_water0, 1e-300)
        # the petiole's pigments age with the blade: a stalk, thick with water, stays wet long
        # after the blade has dried, but its tissue senesces with the lamina it serves
        self.stalk = np.flatnonzero(~model.blade_particles) if model.particle_petiole is not None else None

    def configure(self, params):
        self.params = params

    def field(self, seed: int) -> tuple:
        """(rate, spot, max rate, max spot, particles by falling rate, their rates) of
        :func:`leafsim.sim.senescence.senescence_field`
        for the current parameters and the leaf's seed (the pigments' own, so a resumed run has
        the same field), made again only when one of them changed."""
        key = (tuple(float(self.params[k]) for k in FIELD_KEYS), int(seed))
        if self._field is None or self._field[0] != key:
            rate, spot = senescence_field(self.model, self.params, int(seed))
            n = len(rate)
            order = np.argsort(-rate, kind="stable")
            self._field = (key, (rate, spot, float(rate.max()) if n else 1.0, float(spot.max()) if n else 0.0,
                                 order, np.ascontiguousarray(rate[order], np.float64)))
        return self._field[1]

    def init(self, state: State, seed: int) -> State:
        """``state`` with summer pigments (aged to the clock's start, ``colour.season``)."""
        m = self.model
        state = replace(state, pigments=init_pigments(m.particle_count, self.params, seed=seed,
                                                      rest_relative_mass=m.areal_mass0))
        self.apply(state, 0.0)
        return state

    def apply(self, state: State, dt: float) -> None:
        np.multiply(state.particle_water, self.inv_w0, out=self.w_rel, casting="unsafe")
        np.clip(self.w_rel, 0.0, 1.0, out=self.w_rel)
        if self.stalk is not None and len(self.stalk):
            blade = self.model.water_fraction(state.particle_water)
            self.w_rel[self.stalk] = np.minimum(self.w_rel[self.stalk], np.float32(blade))
        step_pigments(state.pigments, self.w_rel, age_at(state.time, self.params), dt, self.params, self.field(state.pigments.seed))
