"""One interactive leaf: species, seed, parameters, model, state, simulator and statistics.

The GUI (``leafsim.gui``) drives a :class:`Session`; it is plain Python/numpy and imports no
OpenGL and no imgui, so it is tested without a display.

Long work (outline → veins → blade) runs in a background thread (:meth:`Session.rebuild_async`)
that reports progress; the finished model is swapped in atomically on the caller's thread by
:meth:`Session.poll` (called by :meth:`step` and once per GUI frame), so the frame loop never
waits for a build and never sees half a model.

The simulation is stepped by a :class:`leafsim.worker.SimWorker`.  Scripts and tests call
:meth:`Session.step` (synchronous, on the caller's thread); the GUI calls
:meth:`Session.start_worker` once and then only asks (:meth:`play`, :meth:`set_speed`,
:meth:`request_steps`, :meth:`dry_to_end`) and reads: :meth:`take_snapshot` once per frame makes
:attr:`state` the worker's latest consistent snapshot and appends its history records.

Example
-------
>>> s = Session("oak")                          # doctest: +SKIP  (synchronous first build)
>>> s.step(10)                                  # doctest: +SKIP
>>> s.set_params(s.params.with_overrides({"osmosis.evaporation_top": 2.0}))   # live: applies at once
>>> s.set_params(s.params.with_overrides({"mesh.spacing": 0.04}))      # staged: pending_rebuild
>>> s.apply_rebuild(); s.wait()                 # doctest: +SKIP
"""

from __future__ import annotations

import json
import threading
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from .errors import LeafsimError
from .fileio import _public_mode, atomic_write_bytes
from .params import PARAMS, ParamSet, flatten, unknown_key_message
from .worker import SimWorker, lower_priority

#: stats history length (frames kept for the live plots)
HISTORY = 2000
#: file format tag of saved parameter sets
PRESET_FORMAT = "leafsim-params/1"
_PRESET_KEYS = {"format", "species", "seed", "params"}


@dataclass
class BuildResult:
    """Everything one build produces (swapped into the session as a whole)."""

    species: Any
    seed: int
    params: ParamSet
    shape: Any
    veins: Any
    model: Any
    photo_rgba: np.ndarray | None  # (H, W, 4) uint8 RGB + leaf mask, None for drawn species
    photo_error: str | None
    seconds: float
    simulator: Any = None  # made on the build thread: at 56 k particles the osmosis factorisation alone is ~1 s


public_mode = _public_mode  # file mode a plain open() would give (used for screenshots)

from .leaf import load_photo_rgba, species_photo_rgba  # noqa: E402  (re-exported: the GUI's photo panel)
from .view import PIGMENT_VIEWS  # noqa: E402,F401


class Session:
    """One leaf being simulated, plus what the GUI needs to show it.

    Parameters
    ----------
    species : str — species key of the config (default ``maple``).
    config : path of the species config (default ``configs/leaves.json``).
    seed : int — random seed of veins, mesh and colour variation.
    overrides : dict of dotted parameter values applied over the species' own values.
    build : True = build the model now (synchronously); False = start empty and call
        :meth:`rebuild_async` (the GUI does this so its first frame appears at once).

    Attributes
    ----------
    species_key, species, seed, params (ParamSet, what the widgets show), built_params (what the
    current model was built with), shape, veins, model, state, simulator, pigments,
    photo_rgba, generation (increments whenever a new model is swapped in), pending_rebuild,
    progress (0..1), progress_text, build_error, sim_error, history (dict of deques), last_ms.
    """

    def __init__(self, species: str | None = None, config=None, seed: int = 0,
                 overrides: dict | None = None, build: bool = True):
        from .species import DEFAULT_SPECIES, get_species

        self.config = config
        self.species_key = species or DEFAULT_SPECIES
        self.species = get_species(self.species_key, config)
        self.overrides = dict(overrides or {})
        self.params: ParamSet = self.species.params.with_overrides(self.overrides, where="--set")
        self.seed = int(seed)
        self.built_params: ParamSet | None = None
        self.built_seed: int | None = None
        self.built_species: str | None = None
        self.shape = self.veins = self.model = self.state = self.simulator = None
        self.worker: SimWorker | None = None
        self.sim_params: ParamSet | None = None  # live values on top of the built ones
        self._params_version = 0
        self._threaded = False
        self._play_wanted = False
        self._speed_wanted: float | None = None
        self._snap_seq = -1
        self._render_cache = None
        self.sim_rate = 0.0
        self.pigments0 = None
        self.view = None
        self.photo_rgba: np.ndarray | None = None
        self.photo_error: str | None = None
        self.generation = 0
        self.progress = 0.0
        self.progress_text = ""
        self.build_error: str | None = None
        self.sim_error: str | None = None
        self.build_seconds = 0.0
        self.last_ms: dict[str, float] = {}
        self.history: dict[str, deque] = {}
        #: with a photo as albedo: tint it by the pigment change (True), or leave the tint at 1
        #: (for renderers that take the pigment colour with the photo's detail)
        self.photo_tint = True
        self._lock = threading.Lock()
        self._build_id = 0
        self._thread: threading.Thread | None = None
        self._ready: tuple[int, BuildResult | None, str | None] | None = None
        self._clear_history()
        if build:
            self._install(self._build(self.species, self.seed, self.params, lambda p, t: None, 0))

    # ------------------------------------------------------------------ properties
    @property
    def frame(self) -> int:
        """Frames simulated since the last build or reset."""
        return 0 if self.state is None else self.state.frame

    @property
    def time(self) -> float:
        return 0.0 if self.state is None else self.state.time

    @property
    def building(self) -> bool:
        """A background build is running (or finished but not yet swapped in)."""
        with self._lock:
            return (self._thread is not None and self._thread.is_alive()) or self._ready is not None

    @property
    def pending_rebuild(self) -> bool:
        """Rebuild-needing values (parameters, seed or species) differ from the current model's."""
        if self.built_params is None:
            return self.model is None and not self.building
        return (self.params.rebuild_differs(self.built_params) or self.seed != self.built_seed
                or self.species_key != self.built_species)

    @property
    def ready(self) -> bool:
        return self.model is not None

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
        return float(self.state.particle_water.sum() / max(self.model.particle_water0.sum(), 1e-300))

    # ------------------------------------------------------------------ building
    def _build(self, sp, seed: int, params: ParamSet, report: Callable[[float, str], None], build_id: int) -> BuildResult:
        from .leaf import build_leaf

        t0 = time.perf_counter()

        def stage(p, text):
            if build_id and build_id != self._build_id:
                raise _Cancelled()
            report(p, text)

        shape, veins, model = build_leaf(sp, params, seed, stage)
        photo, photo_error = None, None
        if sp.image is not None:
            stage(0.97, "photo: loading the species photo")
            try:
                photo = species_photo_rgba(sp, params)
            except LeafsimError as e:
                photo_error = str(e)
        stage(0.98, "simulator: preparing the stages")
        from .sim.simulator import Simulator

        live = {k: v for k, v in self.params.items() if not PARAMS[k].rebuild}
        sim = Simulator(model, params.with_overrides(live), seed=int(seed))
        return BuildResult(sp, int(seed), params, shape, veins, model, photo, photo_error, time.perf_counter() - t0, sim)

    def _install(self, res: BuildResult) -> None:
        """Swap a finished build in (everything at once)."""
        from .sim.simulator import Simulator

        self.species = res.species if res.species.key == self.species_key else self.species
        self._shown_species = res.species
        self.built_species = res.species.key
        self.built_seed = res.seed
        self.built_params = res.params
        self.shape, self.veins, self.model = res.shape, res.veins, res.model
        self.photo_rgba, self.photo_error = res.photo_rgba, res.photo_error
        self.build_seconds = res.seconds
        # live values may have changed while building: the simulator takes the current ones
        # (cheap unless Δt or D changed: the factorisation was done on the build thread)
        self._update_sim_params()
        self.simulator = res.simulator or Simulator(self.model, self.sim_params, seed=self.built_seed)
        self.simulator.set_params(self.sim_params)
        self._fresh_state()
        self.generation += 1
        self.build_error = None
        self.progress, self.progress_text = 1.0, f"built in {res.seconds:.2f} s"

    def _sim_params(self) -> ParamSet:
        """Current live values on top of the values the model was built with."""
        if self.sim_params is None:
            self._update_sim_params()
        return self.sim_params

    def _update_sim_params(self) -> None:
        if self.built_params is None:
            self.sim_params = self.params
        else:
            live = {k: v for k, v in self.params.items() if not PARAMS[k].rebuild}
            self.sim_params = self.built_params.with_overrides(live)
        self._params_version += 1

    def rebuild_async(self) -> None:
        """Rebuild outline → veins → blade for the current species, seed and parameters in a
        background thread.  A newer request supersedes a running one (its result is dropped).
        Progress is in :attr:`progress` / :attr:`progress_text`; call :meth:`poll` to swap the
        result in (the GUI does so every frame)."""
        with self._lock:
            self._build_id += 1
            build_id = self._build_id
            self._ready = None
        sp, seed, params = self.species, self.seed, self.params
        self.progress, self.progress_text = 0.0, "starting"
        self.build_error = None

        def report(p, text):
            if build_id == self._build_id:
                self.progress, self.progress_text = float(p), text

        def work():
            lower_priority()  # the window keeps the cores while a leaf builds
            res, err = None, None
            try:
                res = self._build(sp, seed, params, report, build_id)
            except _Cancelled:
                return
            except LeafsimError as e:
                err = str(e)
            except Exception as e:  # never kill the GUI: report it
                err = f"internal error while building: {type(e).__name__}: {e}"
            with self._lock:
                if build_id == self._build_id:
                    self._ready = (build_id, res, err)

        t = threading.Thread(target=work, name="leafsim-build", daemon=True)
        with self._lock:
            self._thread = t
        t.start()

    def poll(self) -> bool:
        """Swap a finished background build in; True when a new model was installed."""
        with self._lock:
            ready, self._ready = self._ready, None
        if ready is None:
            return False
        build_id, res, err = ready
        if build_id != self._build_id:
            return False
        if err is not None:
            self.build_error = err
            self.progress, self.progress_text = 0.0, "build failed"
            return False
        self._install(res)
        return True

    def wait(self, timeout: float | None = 120.0) -> bool:
        """Block until the running build has finished and is swapped in (tests, scripts)."""
        t = self._thread
        if t is not None:
            t.join(timeout)
            if t.is_alive():
                return False
        self.poll()
        return self.build_error is None

    def apply_rebuild(self) -> None:
        """Rebuild with the staged values (background)."""
        self.rebuild_async()

    # ------------------------------------------------------------------ parameters
    def set_params(self, new: ParamSet | dict) -> bool:
        """Set parameters: live ones apply to the simulator at once, rebuild ones are staged
        until :meth:`apply_rebuild` (see :attr:`pending_rebuild`).  Returns pending_rebuild.
        A dict is read as overrides of the current values (validated)."""
        if not isinstance(new, ParamSet):
            new = self.params.with_overrides(new)
        self.params = new
        self._update_sim_params()
        if self.worker is not None:
            self.worker.set_params(self.sim_params)
        return self.pending_rebuild

    def set_seed(self, seed: int) -> bool:
        """Stage a new seed (needs a rebuild)."""
        self.seed = int(seed)
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
        from .species import get_species

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

    @property
    def shown_species(self):
        """The species of the model on screen (the old one while a switch is building)."""
        return self._shown_species if self.model is not None else self.species

    def save_params(self, path) -> Path:
        """Write species, seed and every parameter value as JSON (atomically)."""
        doc = {"format": PRESET_FORMAT, "species": self.species_key, "seed": self.seed,
               "params": self.params.to_dict()}
        return atomic_write_bytes(path, (json.dumps(doc, indent=1, sort_keys=True) + "\n").encode())

    def read_params(self, path) -> tuple[str, int, ParamSet]:
        """Parse and validate a parameter-set JSON without touching the session.

        Accepts ``{"format", "species", "seed", "params": {...}}`` (what :meth:`save_params`
        writes; every key optional but ``params``) or a plain object of dotted values.
        Missing values come from the (file's) species.  Raises LeafsimError naming the file.
        """
        from .species import get_species

        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except FileNotFoundError:
            raise LeafsimError(f"{path}: parameter file not found") from None
        except (OSError, UnicodeDecodeError) as e:
            raise LeafsimError(f"{path}: cannot read parameter file ({getattr(e, 'strerror', None) or e})") from None
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as e:
            raise LeafsimError(f"{path}: malformed JSON at line {e.lineno} column {e.colno}: {e.msg}") from None
        if not isinstance(doc, dict):
            raise LeafsimError(f"{path}: expected a JSON object of parameter values")
        if "params" in doc:
            bad = sorted(set(doc) - _PRESET_KEYS)
            if bad:
                raise LeafsimError(f"{path}: unknown key '{bad[0]}' (expected {', '.join(sorted(_PRESET_KEYS))})")
            values = doc["params"]
            if not isinstance(values, dict):
                raise LeafsimError(f"{path}: 'params' must be an object of parameter values")
            species = doc.get("species", self.species_key)
            seed = doc.get("seed", self.seed)
            if not isinstance(species, str):
                raise LeafsimError(f"{path}: 'species' must be a species key string")
            if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
                raise LeafsimError(f"{path}: 'seed' must be a non-negative integer")
        else:
            values, species, seed = doc, self.species_key, self.seed
        for k in flatten(values):
            if k not in PARAMS:
                raise LeafsimError(unknown_key_message(k, str(path)))
        base = get_species(species, self.config).params if species != self.species_key else self.species.params
        params = base.with_overrides(values, where=str(path))
        return species, int(seed), params

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
    def _clear_history(self) -> None:
        keys = ("frame", "time", "water_T", "water_V", "water", "residual", "kinetic", "iterations",
                "ms_osmosis", "ms_shrink", "ms_dynamics", "ms_colour", "ms_total")
        self.history = {k: deque(maxlen=HISTORY) for k in keys}
        self.last_ms = {}

    def _fresh_state(self) -> None:
        """A fresh leaf for the current simulator, stepped by a new worker (the old one is
        told to stop; its playing state and speed carry over)."""
        from functools import partial

        from .view import LeafView

        state = self.simulator.state()
        self.pigments0 = state.pigments.copy()
        self.view = LeafView(self.model, self.photo_rgba, self.pigments0, self.photo_tint,
                             photo_colour=self.shown_species.photo_colour)
        self.sim_error = None
        self._clear_history()
        old = self.worker
        self.worker = SimWorker(self.simulator, state, partial(_history_entry, self.model, self.simulator),
                                partial(self._render_arrays, self.view), water0=float(self.model.particle_water0.sum()))
        self.worker.set_speed(self._speed_wanted)
        self.worker.play(self._play_wanted if old is None else (old.playing and not old.drying))
        if old is not None:
            old.stop()
        if self._threaded:
            self.worker.start()
        self._snap_seq = -1
        self._epoch = 0
        self.take_snapshot()

    @property
    def pigments(self):
        """Pigments of the current state (None before the first build)."""
        return None if self.state is None else self.state.pigments

    def reset(self, wait: bool = True) -> None:
        """Back to the fresh leaf (frame 0, full water, young colour); same model and
        simulator.  With the worker thread running the worker makes the fresh state between
        two steps; ``wait=False`` (the GUI) returns at once and the next snapshot shows it."""
        if self.model is None:
            return
        w = self.worker
        if w is None or not w.running:
            self._fresh_state()
            return
        epoch = w.request_reset()
        while wait and w.running and w.epoch < epoch:
            time.sleep(0.002)
        if wait:
            self.take_snapshot()

    def take_snapshot(self) -> bool:
        """Make :attr:`state` the worker's latest published frame and append its history
        records; True when it is a new one.  (The GUI calls this once per frame.)"""
        w = self.worker
        if w is None:
            return False
        snap = w.snapshot()
        if snap.epoch != self._epoch:  # the worker reset the leaf: a new history
            self._epoch = snap.epoch
            self._clear_history()
            self.sim_error = None
        for rec in snap.records:
            for k, v in rec.items():
                self.history[k].append(v)
        if snap.ms:
            self.last_ms = dict(snap.ms)
        if snap.error and self.sim_error is None:
            self.sim_error = snap.error
        self.sim_rate = snap.sim_rate if w.running else 0.0
        if snap.seq == self._snap_seq:
            return False
        self._snap_seq = snap.seq
        self.state = snap.state
        self._snap = snap
        return True

    def step(self, n: int = 1) -> dict:
        """Advance ``n`` frames on the caller's thread (enabled effects only; colour when
        ``effects.colour``) and take the result.  Returns milliseconds per stage of the last
        frame.  Does nothing before the first build or after the simulation diverged."""
        self.poll()
        if self.worker is None or self.sim_error is not None:
            return {}
        ms = self.worker.step_sync(n)
        self.take_snapshot()
        return ms

    # --- the worker, driven by the GUI
    def start_worker(self) -> None:
        """Step in a background thread from now on (this and every later model)."""
        self._threaded = True
        if self.worker is not None:
            self.worker.start()

    def play(self, on: bool = True) -> None:
        """Play or pause (before the first build: play once it is there)."""
        self._play_wanted = bool(on)
        if self.worker is not None:
            self.worker.play(on and self.sim_error is None)

    @property
    def playing(self) -> bool:
        return self.worker is not None and self.worker.playing

    def set_speed(self, speed: float | None) -> None:
        """Simulated seconds per wall second (None: as fast as possible)."""
        self._speed_wanted = speed
        if self.worker is not None:
            self.worker.set_speed(speed)

    def request_steps(self, n: int = 1) -> None:
        """``n`` frames in the background (the Step button)."""
        if self.worker is not None and self.sim_error is None:
            self.worker.request_steps(n)

    def dry_to_end(self, on: bool = True) -> None:
        """Fast-forward until the leaf is dry (see :meth:`leafsim.worker.SimWorker.dry_to_end`)."""
        if self.worker is not None:
            self.worker.dry_to_end(on)

    @property
    def drying(self) -> bool:
        return self.worker is not None and self.worker.drying

    def dry_progress(self) -> float:
        return 0.0 if self.worker is None else self.worker.dry_progress()

    def close(self) -> None:
        """Stop the worker thread (the window closes)."""
        if self.worker is not None:
            self.worker.stop(join=2.0)

    # ------------------------------------------------------------------ rendering data
    def _view(self):
        self.view.photo_tint = self.photo_tint
        return self.view

    def _render_key(self) -> tuple:
        return (self._params_version, bool(self.photo_tint))

    def _render_arrays(self, view, state) -> tuple[dict, tuple]:
        """Renderer arrays of a snapshot (runs on the worker thread)."""
        key = self._render_key()
        return view.update(state, self._sim_params()), key

    def render_colours(self):
        """(colours, tint) of layer T — see :meth:`leafsim.view.LeafView.colours`."""
        return self._view().colours(self.state, self._sim_params())

    def use_texture(self) -> bool:
        return bool(self.params["render.texture"]) and self.photo_rgba is not None

    def scalar_fields(self) -> dict:
        """Per layer-T vertex heat-map fields (see :meth:`leafsim.view.LeafView.scalar_fields`)."""
        return self._view().scalar_fields(self.state)

    def render_mesh(self):
        """A :class:`leafsim.render.RenderMesh` of the current model and state (populate once
        per :attr:`generation`, then pass :meth:`render_update` to ``Renderer.update``)."""
        if self.model is None:
            raise LeafsimError("session: no model yet (the first build has not finished)")
        return self._view().mesh(self.state, self._sim_params())

    def render_update(self) -> dict:
        """Keyword arguments for ``Renderer.update`` with the current state: the worker's
        precomputed arrays when they were made with the current parameters, else made now."""
        snap = getattr(self, "_snap", None)
        self._view()
        if snap is not None and snap.state is self.state and snap.render is not None and snap.render_key == self._render_key():
            return snap.render
        return self._view().update(self.state, self._sim_params())


def _history_entry(model, simulator, state, ms: dict) -> dict:
    """One history record of a state (runs on the worker thread)."""
    from .sim.kernels.pbd import residual
    from .sim.model import LAYER_T, LAYER_V

    w = state.particle_water
    lay = model.particle_layer
    finite = bool(np.isfinite(state.particle_q).all() and np.isfinite(w).all())
    mass = model.particle_cytosol + w
    qd = state.particle_qd
    rec = {"frame": state.frame, "time": state.time, "water_T": float(w[lay == LAYER_T].sum()),
           "water_V": float(w[lay == LAYER_V].sum()), "water": float(w.sum() / max(model.particle_water0.sum(), 1e-300)),
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


class _Cancelled(Exception):
    pass


def species_keys(config=None) -> list[str]:
    """Keys of the species library (for the species picker)."""
    from .species import load_library

    return list(load_library(config))


__all__ = ["Session", "BuildResult", "load_photo_rgba", "species_keys", "PRESET_FORMAT"]
