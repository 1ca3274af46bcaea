"""The simulator: runs only the enabled effects, in the pipeline's order (osmosis, shrink,
dynamics, colour; docs/method.md), and times each stage.

One :class:`Simulator` serves every driver: the GUI's session, ``leafsim run``, the accuracy
study and scenes.  A disabled effect is never constructed (costs nothing) and leaves its part
of the state untouched.

Example
-------
>>> sp = get_species("oak")                                # doctest: +SKIP
>>> model = build_leaf(sp, sp.params, seed=0).model
>>> sim = Simulator(model, sp.params, seed=0)             # the seed the model was built with
>>> state = sim.state()                                    # fresh leaf, pigments included
>>> ms = sim.step(state)  # {'osmosis': 0.3, 'shrink': 0.05, 'dynamics': 0.9, 'watchdog': 0.02, 'colour': 0.01}
"""

from __future__ import annotations

import time

import numpy as np

from leafsim.base.errors import Diverged, LeafsimError
from leafsim.config.params import ParamSet, as_params, check_seed
from leafsim.sim.effects import EFFECTS, Colour, Dynamics, Osmosis, Shrink
from leafsim.sim.effects.dynamics import held
from leafsim.sim.layout import check_layout, state_layout
from leafsim.sim.model import Model, State
from leafsim.sim.path import PATH_EFFECTS, PATH_LEVELS, DryingPath, path_allowed, path_params, work_done

#: the stage clock: CPU seconds of the calling thread (about 1 µs a call, 6 calls a frame)
_clock = time.thread_time

#: the prefix of the drying-path mesh's simulator's records in :meth:`Simulator.carry`
CARRY_PATH = "pathmesh_"

#: the watchdog measures energy and momentum every this many frames
WATCH_EVERY = 5


class Simulator:
    """Composes the enabled stages for one model.

    Parameters
    ----------
    model : Model
    params : ParamSet — ``osmosis.*``, ``shrink.*``, ``dynamics.*``, ``colour.*`` and ``effects.*``.
    effects : optional iterable of effect names to enable (overrides ``effects.*``).
    seed : seeds the per-leaf colour variation of the states this simulator makes and the blade's
        shrinkage field (``shrink.patchiness``); default: the seed the model was built with
        (``model.seed``, set by :func:`leafsim.pipeline.build_leaf`), else 0, so
        ``Simulator(build_leaf(sp, p, 3).model, p)`` is ``leafsim run --seed 3``.
    watchdog : check energy and momentum every few frames and raise LeafsimError on a
        blow-up that produces no NaN (see :mod:`leafsim.sim.watchdog`).
    """

    def __init__(self, model: Model, params: ParamSet, effects=None, seed: int | None = None, watchdog: bool = True):
        if not isinstance(model, Model):
            hint = " (pass leaf.model, the model of build_leaf's result)" if hasattr(model, "model") else ""
            raise LeafsimError(f"Simulator: model ({type(model).__name__}): expected a Model{hint}")
        params = as_params(params, "Simulator")
        check_built_with(model, params, "Simulator")
        self.model = model
        self._layout = state_layout(model)  # what step() checks every state against
        self._path_layout = None
        if seed is None:  # the seed the model was built with, as `leafsim run --seed S` uses it for both
            seed = model.seed if model.seed is not None else 0
        self.seed = check_seed(seed, "Simulator")  # int() truncated 0.5 and took '7'; numpy refused -1 in a bare ValueError
        self.watchdog = None
        self._watch = watchdog
        self._osmosis = None
        self._shrink = None
        self._dynamics = None
        self._colour = None
        self._path = None
        self._path_was_active = True
        if isinstance(effects, str):  # set('osmosis') is {'o', 's', 'm', 'i'}
            raise LeafsimError(f"effects {effects!r}: expected a list of effect names, e.g. ['{effects}']")
        self._override = None if effects is None else set(effects)
        if self._override is not None:
            bad = self._override - set(EFFECTS)
            if bad:
                raise LeafsimError(f"unknown effect(s) {', '.join(sorted(bad))}: expected some of {', '.join(EFFECTS)}")
        self.set_params(params)

    def set_params(self, params: ParamSet) -> None:
        """Apply (live) parameters; matrices are refactored only when Δt or λ change.  A
        parameter the model is built from, set otherwise than the build did, is refused
        (:func:`check_built_with`): it would change nothing."""
        params = as_params(params, "Simulator.set_params")
        check_built_with(self.model, params, "Simulator.set_params")
        self.params = params
        if self._override is None:
            self.effects = {e: bool(params[f"effects.{e}"]) for e in EFFECTS}
        else:
            self.effects = {e: e in self._override for e in EFFECTS}
        e = self.effects
        self.osmosis_every = int(params["osmosis.every"])
        if e["osmosis"]:
            self._osmosis = self._osmosis or Osmosis(self.model)
            self._osmosis.configure(params, dt=params["dynamics.dt"] * self.osmosis_every)
        if e["shrink"]:
            self._shrink = self._shrink or Shrink(self.model)
            self._shrink.configure(params, self.seed)
        self.dynamic = e["pbd"] or e["gravity"]
        on_path = self.dynamic and self.model.path is not None and path_allowed(params)
        # after the drying path's hand-over the own mesh finishes with XPBD or, where the leaf is
        # held, with static equilibria (dynamics.finish)
        finish = on_path and params["dynamics.finish"] == "static" and held(self.model, params, e)
        if self.dynamic:
            self._dynamics = self._dynamics or Dynamics(self.model)
            self._dynamics.configure(params.with_overrides({"dynamics.integrator": "static"}) if finish else params, e)
        if on_path:
            # the drying's mechanics on the model's coarser path mesh (leafsim.sim.path)
            coarse = path_params(params, params["dynamics.path"])
            on = tuple(k for k in PATH_EFFECTS if e.get(k))
            if self._path is None or self._path.effects != on:
                self._path = DryingPath(self.model, params, Simulator(self.model.path, coarse, on, seed=self.seed), on,
                                        finish)
            else:
                self._path.set_params(params, coarse, finish)
        else:
            self._path = None
        if self._colour is not None or e["colour"]:
            # pigments exist whenever a state exists (the young colour is drawn even when the
            # aging effect is off), so the stage is configured once made
            self._colour = self._colour or Colour(self.model)
            self._colour.configure(params)
        self.dt = params["dynamics.dt"]
        # the weather clock: real seconds per frame when the weather drives the drying
        self.weather_dt = self.dt * params["environment.time_warp"] if params["environment.drive"] == "weather" else 0.0
        if self._watch and self.dynamic:
            from leafsim.sim.watchdog import Watchdog

            if self.watchdog is None:
                self.watchdog = Watchdog(self.model, params, every=WATCH_EVERY)
            self.watchdog.params = params  # blame the values in force
        else:
            self.watchdog = None

    def state(self) -> State:
        """A fresh leaf: rest positions, full water, summer pigments (:func:`young_state`)."""
        self._colour = self._colour or Colour(self.model)
        self._colour.configure(self.params)
        return self._colour.init(self.model.state(), self.seed)

    def sync_path(self, state: State) -> None:
        """After a caller moved ``state``'s particles (a perturbed start, a shifted leaf): put the
        drying-path mesh where the leaf now is, or the next step's mechanics would undo it."""
        if self._path is not None and state.path is not None:
            self._path.sync(state)

    def drying_progress(self, water_left: float, target: float) -> float:
        """The share of the work of a drying to ``target`` of the water that is done at
        ``water_left``: the water lost, weighted by what a frame costs on the mesh that carries
        the mechanics then (the drying path's frames are cheap, the own mesh's are not: on maple
        the last 15 % of the water took two thirds of the time)."""
        paths, sim = [], self
        while sim._path is not None:  # nested paths (dynamics.path = fine): the own mesh's first
            paths.append(sim._path)
            sim = sim._path.sim
        if not paths:
            return work_done(1.0 - water_left, 1.0 - target, None, 0.0)
        ratios = [p.cost_ratio for p in paths]
        for k in range(len(paths) - 1):  # a static finish's cost is per draft frame: per frame of the mesh under it
            if paths[k].per_draft:
                ratios[k] /= max(float(np.prod(ratios[k + 1:])), 1e-12)
        return work_done(1.0 - water_left, 1.0 - target, [p.handover for p in paths], ratios)

    def carry(self) -> dict:
        """What the stages hand from one frame to the next beyond the :class:`State`: whether
        the drying-path mesh carried the last frame's mechanics (its hand-over starts a static
        finish) and the static solver's friction and predictor (:meth:`Equilibrium.carry`).
        ``leafsim run``'s checkpoints keep it beside the state (a resumed run is then
        bit-identical also after a static finish has taken over)."""
        out = {"path_was_active": np.array([self._path_was_active], bool)}
        d = self._dynamics
        if d is not None and d.static and getattr(d, "equilibrium", None) is not None:
            out.update({f"equilibrium_{k}": v for k, v in d.equilibrium.carry().items()})
        if self._path is not None:  # the drying-path mesh's simulator's, which may have a path of its own
            out.update({f"{CARRY_PATH}{k}": v for k, v in self._path.sim.carry().items()})
        return out

    def restore(self, carry: dict) -> None:
        """Take back what :meth:`carry` gave (checked arrays: :func:`leafsim.sim.checkpoint.load_carry`);
        a key this simulator has no stage for is ignored, a missing one leaves the stage fresh."""
        if "path_was_active" in carry:
            self._path_was_active = bool(carry["path_was_active"][0])
        inner = {k.removeprefix(CARRY_PATH): v for k, v in carry.items() if k.startswith(CARRY_PATH)}
        if inner and self._path is not None:
            self._path.sim.restore(inner)
        d = self._dynamics
        eq = {k.removeprefix("equilibrium_"): v for k, v in carry.items() if k.startswith("equilibrium_")}
        if eq and d is not None and d.static and getattr(d, "equilibrium", None) is not None:
            d.equilibrium.restore(eq)

    @property
    def on_path(self) -> bool:
        """The last step's mechanics ran on the model's drying-path mesh (``dynamics.path``)."""
        return self._path is not None and self._path_was_active

    @property
    def mechanics_mesh(self) -> int:
        """Which mesh carried the last step's mechanics: 0 the model's own, 1 its drying-path
        mesh, 2 that mesh's own path mesh (``dynamics.path = fine``)."""
        return 1 + self._path.sim.mechanics_mesh if self.on_path else 0

    @property
    def on_coarsest(self) -> bool:
        """The last step's mechanics ran on the coarsest mesh there is (the cheap frames before
        every hand-over; the model has a drying path)."""
        depth, m = 0, self.model
        while m.path is not None:
            depth, m = depth + 1, m.path
        return depth > 0 and self.mechanics_mesh == depth

    @property
    def iterations(self) -> int:
        """PBD iterations used in the last step (on the path mesh while it carries the mechanics)."""
        if self.on_path:
            return self._path.sim.iterations
        return self._dynamics.last_iterations if (self._dynamics and self.dynamic) else 0

    def step(self, state: State) -> dict:
        """Advance one frame in place; returns milliseconds per executed stage, the CPU time of
        the calling thread (``time.thread_time``: in the window, a stage that waits for the GIL
        while the UI thread draws does not count the wait).  ``state`` must be a state of this
        simulator's model (its arrays' shapes and dtypes are checked: the kernels trust them)."""
        check_layout(state, self._layout, "Simulator.step: state")
        if state.path is not None and self.model.path is not None:
            if self._path_layout is None:
                self._path_layout = state_layout(self.model.path)
            check_layout(state.path, self._path_layout, "Simulator.step: state (drying-path mesh)")
        try:
            return self._step(state)
        except ArithmeticError as e:  # a kernel met NaN/Inf (division by zero, overflow)
            raise Diverged(f"the simulation blew up at frame {state.frame + 1} ({type(e).__name__}: {e})") from None

    def _step(self, state: State) -> dict:
        ms = {}
        t0 = _clock()
        if self.effects["osmosis"] and state.frame % self.osmosis_every == 0:
            self._osmosis.apply(state)  # one step of k Δt every k-th frame (osmosis.every)
            t1 = _clock()
            ms["osmosis"] = (t1 - t0) * 1e3
            t0 = t1
        if self.effects["shrink"]:
            self._shrink.apply(state)
            t1 = _clock()
            ms["shrink"] = (t1 - t0) * 1e3
            t0 = t1
        if self.dynamic:
            path = self._path is not None and self._path.active(state)
            if path:
                if not self._path_was_active:
                    self._path.sync(state)  # the hand-over level was raised live: start from here
                self._path.step(state)
            else:
                if self._path is not None and self._path_was_active and self._dynamics.static:
                    # a static finish takes over: its equilibrium at once, friction and predictor
                    # from here (not from before a live return to the path mesh)
                    self._dynamics.equilibrium.reset()
                    self._dynamics.solve_now = True
                self._dynamics.apply(state)
            self._path_was_active = path
            t1 = _clock()
            ms["dynamics"] = (t1 - t0) * 1e3
            t0 = t1
        state.scalars[0] += self.dt
        state.scalars[1] += 1
        state.scalars[2] += self.weather_dt
        if self.watchdog is not None:
            self.watchdog.check(state)
            t1 = _clock()
            ms["watchdog"] = (t1 - t0) * 1e3
            t0 = t1
        if self.effects["colour"] and state.pigments is not None:
            self._colour.apply(state, self.dt)
            ms["colour"] = (_clock() - t0) * 1e3
        return ms


def young_state(model: Model, params, seed: int = 0) -> State:
    """The fresh leaf a :class:`Simulator` of ``model``, ``params`` and ``seed`` starts from (its
    :meth:`Simulator.state`: rest positions, full water, summer pigments), without building the
    simulation's stages: what a view needs as the young pigments of an already simulated leaf."""
    params = as_params(params, "young_state")
    c = Colour(model)
    c.configure(params)
    return c.init(model.state(), check_seed(seed, "young_state"))


def check_built_with(model: Model, params: ParamSet, who: str) -> None:
    """A parameter the model is built from (outline, veins, mesh, petiole, mass: *rebuild* in
    docs/parameters.md) set otherwise for the simulation changes nothing it does: refused,
    naming it (a sweep of mass.lma over one model gave the same leaf three times, without a
    word).  A model of unknown build (``built_with`` None: built by hand, a drying-path mesh)
    is not checked."""
    if model.built_with is None:
        return
    now = dict(params.build_values())
    diff = [(k, now[k], v) for k, v in model.built_with if k in now and now[k] != v]
    if diff:
        shown = ", ".join(f"{k} = {a!r} (built with {b!r})" for k, a, b in diff[:3]) + (" ..." if len(diff) > 3 else "")
        raise LeafsimError(f"{who}: params set {shown}, which the model is built from: build it again with these "
                           "params (build_leaf) for them to take effect")
    _check_path_built(model, params, who)


def _check_path_built(model: Model, params: ParamSet, who: str) -> None:
    """``dynamics.path`` asks for a drying-path mesh the model was not built with (none, or the
    other level's): the simulator ran the leaf's own mesh throughout, or the other mesh with this
    level's solver, without a word.  ``own`` on a model with a path mesh leaves it unused: fine."""
    level = params["dynamics.path"]
    if not path_allowed(params):  # own, or solver settings the path does not stand in for: the own mesh runs
        return
    want = path_params(params, level)["mesh.spacing"] * model.length
    if want <= model.spacing * 1.001:
        want = None  # the mesh is not finer than this level's: no path mesh (the own mesh carries the drying)
    have = model.path.spacing if model.path is not None else None
    if (want is None) != (have is None) or (want is not None and abs(have - want) > 1e-6 * want):
        built = ("'own' (no drying-path mesh)" if have is None else
                 next((repr(k) for k in PATH_LEVELS if abs(path_params(params, k)["mesh.spacing"] * model.length - have)
                       <= 1e-6 * have), "another drying-path mesh"))
        raise LeafsimError(f"{who}: params set dynamics.path = {level!r}, but the model was built with {built}: build it "
                           "again with these params (build_leaf) for the drying path to take effect")
