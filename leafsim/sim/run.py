"""The one run loop: :class:`Run` steps one leaf's :class:`~leafsim.sim.simulator.Simulator`
until a stopping rule holds, and checks every frame for NaN/Inf.  ``leafsim run``, ``leafsim
export``, scenes, ``leafsim compare``, the accuracy study, the bench and the GUI's worker all
drive a leaf through it; what they do with each frame (statistics, PNG frames, checkpoints,
snapshots, colour matching) is the body of their own ``for`` loop.

Example
-------
>>> run = Run(model, params, seed=0)                      # doctest: +SKIP
>>> for ms in run.frames(Stop(water_left=0.02, max_frames=100_000)):   # doctest: +SKIP
...     pass
>>> run.state.frame, run.water_left                       # doctest: +SKIP
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Callable, Iterator

import numpy as np

from leafsim.base.errors import Diverged, LeafsimError  # noqa: F401  (Diverged: also leafsim.sim.run.Diverged)
from leafsim.config.params import ParamSet, as_params, check_seed, show
from leafsim.sim.model import Model, State
from leafsim.sim.simulator import Simulator, check_built_with
from leafsim.sim.stats import StatsStream, frame_stats

#: "dry": the water left has fallen to this fraction of the fresh leaf's (GUI "Dry to end",
#: ``--until dry``)
DRY_END_FRACTION = 0.02
#: ... within this many frames (a leaf that never dries, e.g. evaporation switched off)
DRY_MAX_FRAMES = 200000
#: the most frames a run may be asked for (--frames, a scene's stop.frames): 2·10⁴ simulated seconds
#: at the default step, beyond any drying; a larger count is a typo, not a run
MAX_RUN_FRAMES = 10_000_000
#: a water or season criterion whose measure has not moved towards it in this many frames is
#: taken as unreachable (evaporation or aging switched off by a parameter) instead of running
#: on to ``max_frames``
STALL_FRAMES = 2000


class NotReached(LeafsimError):
    """A stopping criterion was not met within its frame budget."""


@dataclass(frozen=True)
class Stop:
    """When a run ends.  Checked before every step, so a criterion that already holds runs
    nothing: at absolute frame ``frames``, when the water left falls to ``water_left`` (a
    fraction of the fresh leaf's), or when the season clock reaches ``season``.  Past
    ``max_frames`` an unmet criterion raises :class:`NotReached`."""

    frames: int | None = None
    water_left: float | None = None
    season: float | None = None
    max_frames: int | None = None

    def __post_init__(self):
        """Each criterion checked where it is made, as ``--frames`` and ``--until`` are: NaN frames
        never held (the run went on for ever), ``water_left`` > 1 held before the first frame and
        a string failed deep in the loop; with no criterion at all the run stopped after 2 000
        frames blaming a season clock nobody asked for."""
        if self.frames is None and self.water_left is None and self.season is None:
            raise LeafsimError("Stop: no criterion: give frames, water_left or season (max_frames is only the budget)")
        for name, hi in (("frames", MAX_RUN_FRAMES), ("max_frames", None)):
            v = getattr(self, name)
            if v is not None:
                object.__setattr__(self, name, _count(f"Stop: {name}", v, hi))
        for name, hi, what in (("water_left", 1.0, "a fraction of the fresh leaf's water in [0, 1]"),
                               ("season", 1e12, "a season clock value ≥ 0")):
            v = getattr(self, name)
            if v is None:
                continue
            ok = isinstance(v, numbers.Real) and not isinstance(v, bool) and 0.0 <= float(v) <= hi
            if not ok:
                raise LeafsimError(f"Stop: {name} = {show(v)}: expected {what}")
            object.__setattr__(self, name, float(v))

    def reached(self, run: "Run") -> bool:
        s = run.state
        if self.frames is not None and s.frame >= self.frames:
            return True
        if self.water_left is not None and run.water_left <= self.water_left:
            return True
        return self.season is not None and run.season >= self.season

    def progress(self, run: "Run", start: int = 0) -> float:
        """How far the run is toward the nearest criterion, 0 … 1 (frames from ``start``,
        the drying's work toward ``water_left``: :meth:`Simulator.drying_progress`, the season clock
        toward ``season``)."""
        parts = []
        if self.frames is not None:
            parts.append((run.state.frame - start) / max(self.frames - start, 1))
        if self.water_left is not None:  # the work done, not just the water (a drying path's frames are cheaper)
            parts.append(run.sim.drying_progress(run.water_left, self.water_left))
        if self.season is not None:
            parts.append(run.season / max(self.season, 1e-12))
        return float(min(max(max(parts, default=0.0), 0.0), 1.0))

    def describe(self) -> str:
        parts = [f"{k} = {v:g}" for k, v in (("frames", self.frames), ("water_left", self.water_left),
                                             ("season", self.season)) if v is not None]
        return ", ".join(parts) or "no criterion"


def _count(name: str, v, hi: int | None) -> int:
    """A number of frames: a whole number (3 or 3.0), ≥ 0 and at most ``hi``; else one line naming ``name``."""
    whole = isinstance(v, numbers.Integral) or (isinstance(v, numbers.Real) and math.isfinite(v) and float(v).is_integer())
    if isinstance(v, bool) or not whole or v < 0 or (hi is not None and v > hi):
        upto = f" up to {hi:,}" if hi is not None else ""
        raise LeafsimError(f"{name} = {show(v)}: expected a whole number of frames ≥ 0{upto}")
    return int(v)


class Run:
    """One leaf simulated by one :class:`Simulator`.

    Parameters
    ----------
    model : Model
    params : ParamSet (used to make the simulator unless ``simulator`` is given).
    effects : effect names to enable (default: the ``effects.*`` parameters).
    seed : seeds the fresh leaf's colour variation and its shrinkage field (``shrink.patchiness``);
        default: the seed the model was built with (``model.seed``), else 0.
    state : continue this state (a checkpoint) instead of a fresh leaf; checked against ``model`` as a
        loaded checkpoint is (:func:`leafsim.sim.checkpoint.check_state`).
    simulator : use this simulator (made for ``model``).
    watchdog : let the simulator stop a blow-up that produces no NaN.
    name : prefix of error messages (the species key, a scene leaf's name).

    Attributes
    ----------
    model, sim (the Simulator), state (stepped in place), last_ms (stage timings of the last
    step).
    """

    def __init__(self, model: Model, params: ParamSet | None = None, effects=None, seed: int | None = None,
                 state: State | None = None, simulator: Simulator | None = None, watchdog: bool = True,
                 name: str = ""):
        # checked here, before any kernel sees them: a state of another model, or with arrays of
        # the wrong shape, aborted the interpreter (double free, segfault)
        if not isinstance(model, Model):
            hint = " (pass leaf.model, the model of build_leaf's result)" if hasattr(model, "model") else ""
            raise LeafsimError(f"Run: model {show(model)} ({type(model).__name__}): expected a Model{hint}")
        if simulator is None:
            params = as_params(params, "Run")
            check_built_with(model, params, "Run")
            seed = None if seed is None else check_seed(seed, "Run")  # None: the model's own (Simulator)
            simulator = Simulator(model, params, effects, seed=seed, watchdog=watchdog)
        elif not isinstance(simulator, Simulator) or simulator.model is not model:
            raise LeafsimError("Run: simulator: expected a Simulator made for this model (Simulator(model, params))")
        if state is not None:
            from leafsim.sim.checkpoint import check_state

            check_state(state, model, "Run: state")
        self.model = model
        self.sim = simulator
        self.state = simulator.state() if state is None else state
        self.last_ms: dict = {}
        self._prefix = f"{name}: " if name else ""
        self._produced = None  # (id, frame) of the state this run last stepped to

    # ------------------------------------------------------------------ measures
    @property
    def water_left(self) -> float:
        """The blade's water now / fresh (:meth:`Model.water_fraction`)."""
        return self.model.water_fraction(self.state.particle_water)

    @property
    def season(self) -> float:
        """The season clock of the pigments (0 without them)."""
        return float(self.state.pigments.age) if self.state.pigments is not None else 0.0

    def finite(self) -> bool:
        s = self.state
        return bool(np.isfinite(s.particle_q).all() and np.isfinite(s.particle_qd).all()
                    and np.isfinite(s.particle_water).all())

    def stats(self, ms: dict | None = None) -> dict:
        """:func:`~leafsim.sim.stats.frame_stats` of the current state."""
        return frame_stats(self.model, self.state, self.last_ms if ms is None else ms, self.sim)

    # ------------------------------------------------------------------ stepping
    def step(self) -> dict:
        """One frame; returns milliseconds per stage.  A kernel's arithmetic error becomes
        :class:`Diverged` (NaN/Inf in the state is reported by :meth:`frames`)."""
        try:
            self.last_ms = self.sim.step(self.state)
        except Diverged as e:  # (Simulator.step's: a kernel met NaN/Inf, division by zero, overflow)
            raise Diverged(f"{self._prefix}{e}") from None
        return self.last_ms

    def frames(self, stop: Stop | None = None, until: Callable[[State], bool] | None = None) -> Iterator[dict]:
        """Step frame by frame, yielding each step's stage timings, until ``stop`` holds
        (checked before each step) or ``until(state)`` is true (checked after each step).

        A frame that leaves NaN/Inf in the state is yielded (its statistics can still be
        written), then :class:`Diverged` is raised.  Breaking out of the loop stops the run
        at the frame just yielded."""
        if stop is not None and not isinstance(stop, Stop):
            raise LeafsimError(f"Run.frames: stop {show(stop)}: expected a Stop(...) or None")
        from leafsim.sim.checkpoint import check_edited, check_state

        # the state as it stands now (run.state may have been replaced or edited since the Run was
        # made): a NaN put there was reported as the simulation's, water × 5 was taken as found
        if until is not None and not callable(until):
            raise LeafsimError(f"{self._prefix}Run.frames: until {show(until)}: expected a function of the state "
                               "(until=lambda state: ...) or None; a frame count or water level is a Stop(...)")
        if self._produced != (id(self.state), self.state.frame):
            # (a state this run stepped to is its own: a free leaf that has fallen 100 leaf lengths
            # is no damaged state, and checking it in full each call cost a fresh state's arrays)
            check_state(self.state, self.model, f"{self._prefix}Run.frames: state")
        else:  # its own, but edited in place since (water × 5, a NaN put in by hand): the cheap checks
            check_edited(self.state, self.model, f"{self._prefix}Run.frames: state")
        if self.sim.effects["colour"] and self.state.pigments is None:
            # (the colour effect then did nothing, and a season stop waited for ever)
            raise LeafsimError(f"{self._prefix}Run.frames: the state has no pigments, yet effects.colour is on: make the "
                               "state with run.sim.state() or Simulator.state() (Model.state() makes one without them)")
        watch = None
        while True:
            if stop is not None:
                if stop.reached(self):
                    return
                if stop.max_frames is not None and self.state.frame >= stop.max_frames:
                    raise NotReached(f"{self._prefix}stopping criterion {stop.describe()} not reached within max_frames = "
                                     f"{stop.max_frames} (water left {self.water_left:.3g}, season {self.season:.3g})")
                if stop.frames is None:  # (made once the criterion is known not to hold already)
                    watch = watch or _Stall(self, stop)
                    watch.check()
            ms = self.step()
            finite = self.finite()
            self._produced = (id(self.state), self.state.frame)
            yield ms
            if not finite:
                raise Diverged(f"{self._prefix}the simulation produced NaN/Inf at frame {self.state.frame}")
            if until is not None and until(self.state):
                return


class _Stall:
    """Refuses a water or season criterion the run cannot reach: at once when the effect that
    moves its measure is off (no osmosis: the water never falls; no colour: the season clock
    stands), else when the measure has not moved towards it in :data:`STALL_FRAMES` frames
    (not while a weather record drives the drying)."""

    def __init__(self, run: Run, stop: Stop):
        self.run, self.stop = run, stop
        fx = run.sim.effects
        if stop.water_left is not None and not fx.get("osmosis", False):
            self._fail("the water left cannot fall with effects.osmosis off")
        if stop.season is not None and not fx.get("colour", False):
            self._fail("the season clock stands still with effects.colour off")
        self.best = self._measures()
        self.since = run.state.frame
        # a weather record may hold the air saturated for days (no drying): there only the
        # frame budget ends a run that does not dry
        self.patient = run.sim.params["environment.drive"] == "weather"

    def _measures(self) -> tuple:
        return (-self.run.water_left if self.stop.water_left is not None else 0.0,
                self.run.season if self.stop.season is not None else 0.0)

    def _fail(self, why: str) -> None:
        r = self.run
        raise NotReached(f"{r._prefix}stopping criterion {self.stop.describe()} cannot be reached: {why} "
                         f"(water left {r.water_left:.3g}, season {r.season:.3g} at frame {r.state.frame})")

    def check(self) -> None:
        now = self._measures()
        if any(n > b + 1e-9 * max(abs(b), 1.0) for n, b in zip(now, self.best)):
            self.best, self.since = now, self.run.state.frame
        elif self.run.state.frame - self.since >= STALL_FRAMES and not self.patient:
            what = "the water left" if self.stop.water_left is not None else "the season clock"
            self._fail(f"{what} has not moved towards it in {STALL_FRAMES} frames (evaporation or aging switched off?)")


def run_headless(model: Model, params: ParamSet, frames: int, effects=None, stats_path=None, on_frame=None,
                 seed: int | None = None, state: State | None = None, simulator: Simulator | None = None, stats_stream=None):
    """``frames`` frames of a :class:`Run` with every frame's statistics; returns (state, stats).

    ``stats_path``: stream the statistics there as JSON lines (or ``stats_stream``: an open
    :class:`~leafsim.sim.stats.StatsStream`, left open).  ``on_frame(frame, state, stats)`` is
    called after every frame; return False to stop.  A NaN frame ends the run (its statistics
    say ``"nan": true``) without raising.  ``seed``, ``state``, ``simulator``: as :class:`Run`.
    """
    frames = _count("run_headless: frames", frames, MAX_RUN_FRAMES)  # a whole number, as Stop's
    run = Run(model, params, effects, seed=seed, state=state, simulator=simulator)
    own = StatsStream(stats_path) if stats_path and stats_stream is None else None
    stream = stats_stream or own
    stats = []
    try:
        for ms in run.frames(Stop(frames=run.state.frame + frames)):
            st = run.stats(ms)
            stats.append(st)
            if stream is not None:
                stream.write(st)
            if (on_frame is not None and on_frame(run.state.frame, run.state, st) is False) or st["nan"]:
                break
        if own is not None:
            own.finish()  # (a run of no frame: the file, empty)
    finally:
        if own is not None:
            own.close()
    return run.state, stats
