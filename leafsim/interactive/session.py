"""One interactive leaf: species, seed and parameters (staged until a rebuild where they need
one), the built model, and what the GUI draws of it.

The GUI (``leafsim.gui``) drives a :class:`Session`; it is plain Python/numpy and imports no
OpenGL and no imgui, so it is tested without a display.  A session is three parts:

* **staging** (this class): the values the widgets show; live ones go to the simulation at
  once, rebuild ones wait for :meth:`apply_rebuild` (:attr:`pending_rebuild`);
* **building** (:class:`~leafsim.interactive.builder.Builder`): outline → veins → blade on a
  background thread, swapped in whole by :meth:`poll` (called once per GUI frame);
* **playback** (:attr:`playback`, :class:`~leafsim.interactive.playback.Playback`): the
  worker thread stepping the model on screen, its snapshots and history.

Example
-------
>>> s = Session("oak")                          # doctest: +SKIP  (synchronous first build)
>>> s.step(10)                                  # doctest: +SKIP
>>> s.set_params(s.params.with_overrides({"osmosis.evaporation_top": 2.0}))   # live: applies at once
>>> s.set_params(s.params.with_overrides({"mesh.spacing": 0.04}))      # staged: pending_rebuild
>>> s.apply_rebuild(); s.wait()                 # doctest: +SKIP
"""

from __future__ import annotations

from functools import partial
from pathlib import Path

import numpy as np

from leafsim.appearance.view import LeafView
from leafsim.base.errors import LeafsimError
from leafsim.config.params import PARAMS, ParamSet, check_seed
from leafsim.config.presets_io import read_param_set, write_param_set
from leafsim.config.species import DEFAULT_SPECIES, get_species, load_library
from leafsim.interactive.builder import Builder, BuildResult, build, live_params
from leafsim.interactive.history import history_record
from leafsim.interactive.playback import Playback
from leafsim.sim.run import Run

class Session:
    """One leaf being simulated, plus what the GUI needs to show it.

    Parameters
    ----------
    species : str — species key of the config (default ``maple``).
    config : path of the species config (default: the built-in library).
    seed : int — random seed of veins, mesh and colour variation.
    overrides : dict of dotted parameter values applied over the species' own values.
    build : True = build the model now (synchronously); False = start empty and call
        :meth:`rebuild_async` (the GUI does this so its first frame appears at once).

    Attributes
    ----------
    species_key, species, seed, params (ParamSet, what the widgets show), built_params (what the
    current model was built with), shape, veins, model, simulator, view (LeafView),
    photo_rgba, photo_error, generation (increments whenever a new model is swapped in),
    build_error, playback.
    """

    def __init__(self, species: str | None = None, config=None, seed: int = 0,
                 overrides: dict | None = None, build: bool = True):
        self.config = config
        self.species_key = DEFAULT_SPECIES if species is None else species
        self.species = get_species(self.species_key, config)
        self.overrides = dict(overrides or {})
        self.params: ParamSet = self.species.params.with_overrides(self.overrides, where="--set")
        self.seed = int(seed)
        self.built_params: ParamSet | None = None
        self.built_seed: int | None = None
        self.built_species: str | None = None
        self.shape = self.veins = self.model = self.simulator = self.view = None
        self.sim_params: ParamSet | None = None  # live values on top of the built ones
        self._params_version = 0
        self._shown_species = self.species
        self.photo_rgba: np.ndarray | None = None
        self.photo_error: str | None = None
        self.generation = 0
        self.build_error: str | None = None
        self.build_seconds = 0.0
        #: with a photo as albedo: tint it by the pigment change (True), or leave the tint at 1
        #: (for renderers that take the pigment colour with the photo's detail)
        self.photo_tint = True
        self.builder = Builder()
        self.playback = Playback()
        if build:
            self._install(self._build_now())

    # ------------------------------------------------------------------ what is on screen
    @property
    def state(self):
        """The latest snapshot's state (None before the first build)."""
        return self.playback.state

    @property
    def frame(self) -> int:
        """Frames simulated since the last build or reset."""
        return 0 if self.state is None else self.state.frame

    @property
    def time(self) -> float:
        return 0.0 if self.state is None else self.state.time

    @property
    def ready(self) -> bool:
        return self.model is not None

    @property
    def pigments(self):
        """Pigments of the current state (None before the first build)."""
        return None if self.state is None else self.state.pigments

    @property
    def shown_species(self):
        """The species of the model on screen (the old one while a switch is building)."""
        return self._shown_species if self.model is not None else self.species

    def counts(self) -> dict:
        """Particle / spring / triangle counts of the current model (empty before the first build)."""
        return {} if self.model is None else self.model.to_report()

    def total_water(self) -> float:
        """Total water [kg] now."""
        return 0.0 if self.state is None else float(self.state.particle_water.sum())

    def water_fraction(self) -> float:
        """Water now / water at the start (1 = fresh leaf)."""
        if self.model is None:
            return 1.0
        return self.model.water_fraction(self.state.particle_water)

    # ------------------------------------------------------------------ building
    @property
    def building(self) -> bool:
        """A background build is running (or finished but not yet swapped in)."""
        return self.builder.busy

    @property
    def progress(self) -> float:
        return self.builder.progress

    @property
    def progress_text(self) -> str:
        return self.builder.progress_text

    @property
    def pending_rebuild(self) -> bool:
        """Rebuild-needing values (parameters, seed or species) differ from the current model's."""
        if self.built_params is None:
            return self.model is None and not self.building
        return (self.params.rebuild_differs(self.built_params) or self.seed != self.built_seed
                or self.species_key != self.built_species)

    def _build_now(self) -> BuildResult:
        return build(self.species, self.seed, self.params, self.params, lambda p, t: None)

    def rebuild_async(self) -> None:
        """Rebuild outline → veins → blade for the current species, seed and parameters in a
        background thread (a newer request supersedes a running one).  :meth:`poll` swaps
        the result in (the GUI calls it every frame)."""
        self.build_error = None
        self.builder.start(self.species, self.seed, self.params, self.params)

    def apply_rebuild(self) -> None:
        """Rebuild with the staged values (background)."""
        self.rebuild_async()

    def poll(self) -> bool:
        """Swap a finished background build in; True when a new model was installed."""
        done = self.builder.poll()
        if done is None:
            return False
        res, err = done
        if err is not None:
            self.build_error = err
            self.builder.progress, self.builder.progress_text = 0.0, "build failed"
            return False
        self._install(res)
        return True

    def wait(self, timeout: float | None = 120.0) -> bool:
        """Block until the running build has finished and is swapped in (tests, scripts)."""
        if not self.builder.join(timeout):
            return False
        self.poll()
        return self.build_error is None

    def _install(self, res: BuildResult) -> None:
        """Swap a finished build in (everything at once)."""
        self.species = res.species if res.species.key == self.species_key else self.species
        self._shown_species = res.species
        self.built_species, self.built_seed, self.built_params = res.species.key, res.seed, res.params
        self.shape, self.veins, self.model = res.shape, res.veins, res.model
        self.photo_rgba, self.photo_error = res.photo_rgba, res.photo_error
        self.build_seconds = res.seconds
        # live values may have changed while building: the simulator takes the current ones
        # (cheap unless Δt or D changed: the factorisation was done on the build thread)
        self._update_sim_params()
        self.simulator = res.simulator
        self.simulator.set_params(self.sim_params)
        self._fresh()
        self.generation += 1
        self.build_error = None
        self.builder.progress, self.builder.progress_text = 1.0, f"built in {res.seconds:.2f} s"

    def _fresh(self) -> None:
        """A fresh leaf of the current model, stepped by a new worker."""
        run = Run(self.model, simulator=self.simulator)
        self.view = LeafView(self.model, self.photo_rgba, run.state.pigments.copy(), self.photo_tint,
                             photo_colour=self.shown_species.photo_colour)
        self.playback.attach(run, partial(history_record, self.model, self.simulator),
                             partial(self._render_arrays, self.view))

    # ------------------------------------------------------------------ parameters
    def _update_sim_params(self) -> None:
        self.sim_params = self.params if self.built_params is None else live_params(self.built_params, self.params)
        self._params_version += 1

    def set_params(self, new: ParamSet | dict) -> bool:
        """Set parameters: live ones apply to the simulator at once, rebuild ones are staged
        until :meth:`apply_rebuild` (see :attr:`pending_rebuild`).  Returns pending_rebuild.
        A dict is read as overrides of the current values (validated)."""
        if not isinstance(new, ParamSet):
            new = self.params.with_overrides(new)
        self.params = new
        self._update_sim_params()
        self.playback.set_params(self.sim_params)
        return self.pending_rebuild

    def set_seed(self, seed: int) -> bool:
        """Stage a new seed (needs a rebuild); LeafsimError unless it is in [0, 2**63-1]."""
        self.seed = check_seed(seed, "Session.set_seed")
        return self.pending_rebuild

    def user_changes(self) -> dict:
        """Values the user changed from the current species' own values (CLI overrides too)."""
        base = self.species.params
        return {k: v for k, v in self.params.items() if v != base[k]}

    def set_species(self, key: str, rebuild: bool = True) -> dict:
        """Switch species, keeping the user's changes where they apply: a changed value of a
        parameter that neither species sets itself (osmosis rates, dynamics, mesh, ...) carries
        over; one that either species sets (its palette, its venation) takes the new
        species' value.  ``--set`` overrides always carry over.  Starts a background rebuild
        unless ``rebuild=False``.  Returns ``{"kept": [names], "reset": [names]}``."""
        sp = get_species(key, self.config)
        old, new = self.species.params, sp.params
        own = {k for k, p in PARAMS.items() if old[k] != p.default or new[k] != p.default}
        changed = self.user_changes()
        kept = {k: v for k, v in changed.items() if k not in own or k in self.overrides}
        reset = sorted(k for k in changed if k not in kept)
        self.species, self.species_key = sp, key
        self.set_params(new.with_overrides(kept, where="species switch"))
        if rebuild:
            self.rebuild_async()
        return {"kept": sorted(kept), "reset": reset}

    def species_defaults(self) -> list[str]:
        """Every parameter back to the current species' own values (``--set`` overrides
        dropped too); returns the names that changed."""
        changed = sorted(self.user_changes())
        self.overrides = {}
        self.set_params(self.species.params)
        return changed

    def save_params(self, path) -> Path:
        """Write species, seed and every parameter value as JSON (atomically)."""
        return write_param_set(path, self.species_key, self.seed, self.params)

    def read_params(self, path) -> tuple[str, int, ParamSet]:
        """Parse and validate a parameter-set file without touching the session
        (:func:`leafsim.config.presets_io.read_param_set`)."""
        return read_param_set(path, self.species_key, self.seed, self.config, self.species.params)

    def load_params(self, path, rebuild: bool = False) -> bool:
        """Load a parameter set (see :meth:`read_params`); on any error the session is unchanged.
        Live values apply at once; rebuild values are staged (or rebuilt now with
        ``rebuild=True``).  Returns pending_rebuild."""
        species, seed, params = self.read_params(path)
        if species != self.species_key:
            self.set_species(species, rebuild=False)
        self.seed = seed
        self.set_params(params)
        if rebuild and self.pending_rebuild:
            self.apply_rebuild()
        return self.pending_rebuild

    # ------------------------------------------------------------------ simulation
    def step(self, n: int = 1) -> dict:
        """Advance ``n`` frames on the caller's thread (scripts, tests): swaps a finished
        build in first; returns milliseconds per stage of the last frame."""
        self.poll()
        return self.playback.step(n)

    def reset(self, wait: bool = True) -> None:
        """Back to the fresh leaf (frame 0, full water, young colour); same model and
        simulator (:meth:`Playback.reset`)."""
        if self.model is not None:
            self.playback.reset(self._fresh, wait)

    def close(self) -> None:
        """Stop the worker thread (the window closes)."""
        self.playback.close()

    # ------------------------------------------------------------------ rendering data
    def _view(self) -> LeafView:
        self.view.photo_tint = self.photo_tint
        return self.view

    def _render_key(self) -> tuple:
        return (self._params_version, bool(self.photo_tint))

    def _render_arrays(self, view, state) -> tuple[dict, tuple]:
        """Renderer arrays of a snapshot (runs on the worker thread)."""
        return view.update(state, self.sim_params), self._render_key()


    def use_texture(self) -> bool:
        return bool(self.params["render.texture"]) and self.photo_rgba is not None

    def scalar_fields(self) -> dict:
        """Per layer-T vertex heat-map fields (see :meth:`leafsim.appearance.view.LeafView.scalar_fields`)."""
        return self._view().scalar_fields(self.state)

    def render_mesh(self):
        """A :class:`leafsim.appearance.mesh.RenderMesh` of the current model and state (populate
        once per :attr:`generation`, then pass :meth:`render_update` to ``Renderer.update``)."""
        if self.model is None:
            raise LeafsimError("session: no model yet (the first build has not finished)")
        return self._view().mesh(self.state, self.sim_params)

    def render_update(self) -> dict:
        """Keyword arguments for ``Renderer.update`` with the current state: the worker's
        precomputed arrays when they were made with the current parameters, else made now."""
        snap = self.playback.snapshot
        self._view()
        if snap is not None and snap.state is self.state and snap.render is not None and snap.render_key == self._render_key():
            return snap.render
        return self._view().update(self.state, self.sim_params)


def species_keys(config=None) -> list[str]:
    """Keys of the species library (for the species picker)."""
    return list(load_library(config))


__all__ = ["Session", "BuildResult", "species_keys"]
