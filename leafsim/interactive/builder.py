"""Building a leaf in the background: outline → veins → blade → simulator on a thread of its
own, with progress, cancellation by a newer request, and the result handed over whole
(:meth:`Builder.poll`), so the window never waits for a build and never sees half a model."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from leafsim.appearance.photo import species_photo_rgba
from leafsim.base.errors import LeafsimError
from leafsim.config.params import PARAMS, ParamSet
from leafsim.interactive.worker import lower_priority
from leafsim.pipeline import build_leaf
from leafsim.sim.simulator import Simulator


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


class Cancelled(Exception):
    """A newer build superseded this one."""


def build(sp, seed: int, params: ParamSet, live: ParamSet, report: Callable[[float, str], None]) -> BuildResult:
    """Build species ``sp`` with ``params`` (the simulator takes ``live``: the current live
    values on top); ``report(fraction, text)`` before each stage (it may raise
    :class:`Cancelled`)."""
    t0 = time.perf_counter()
    _warm_up(report)
    shape, veins, model = build_leaf(sp, params, seed, report)
    photo, photo_error = None, None
    if sp.image is not None:
        report(0.97, "photo: loading the species photo")
        try:
            photo = species_photo_rgba(sp, params)
        except LeafsimError as e:
            photo_error = str(e)
    report(0.98, "simulator: preparing the stages")
    sim = Simulator(model, live, seed=int(seed))
    return BuildResult(sp, int(seed), params, shape, veins, model, photo, photo_error, time.perf_counter() - t0, sim)


#: the status bar's text while the first build of a leafsim version compiles the kernels
WARM_TEXT = "compiling the simulation kernels (the first run of this version does it once)"


def _warm_up(report: Callable[[float, str], None]) -> None:
    """The first build of a leafsim version compiles the kernels first (:mod:`leafsim.interactive.warmup`),
    shown as its first stage with a count; a newer build request does not interrupt the
    compile (it is needed anyway): the cancellation takes effect after it."""
    from leafsim.interactive.warmup import is_warm, warm_up

    if is_warm():
        return
    cancelled = []

    def tell(n, s):
        try:
            report(0.0, f"{WARM_TEXT}: {n} done, {s:.0f} s")  # the status bar shortens it
        except Cancelled as e:
            cancelled.append(e)

    tell(0, 0.0)
    try:
        warm_up(tell)
    except Exception:  # a failed warm-up must not fail the build: the build compiles what it needs
        pass
    if cancelled:
        raise cancelled[0]


def live_params(built: ParamSet, current: ParamSet) -> ParamSet:
    """The live values of ``current`` on top of the values a model was ``built`` with."""
    return built.with_overrides({k: v for k, v in current.items() if not PARAMS[k].rebuild})


class Builder:
    """At most one background build that counts: a newer :meth:`start` supersedes a running
    one (its result is dropped at its next stage).  :attr:`progress` / :attr:`progress_text`
    report the running build; :meth:`poll` hands over a finished one."""

    def __init__(self):
        self.progress = 0.0
        self.progress_text = ""
        self._lock = threading.Lock()
        self._build_id = 0
        self._thread: threading.Thread | None = None
        self._ready: tuple[int, BuildResult | None, str | None] | None = None

    @property
    def busy(self) -> bool:
        """A build is running (or finished but not yet handed over)."""
        with self._lock:
            return (self._thread is not None and self._thread.is_alive()) or self._ready is not None

    def start(self, sp, seed: int, params: ParamSet, live: ParamSet) -> None:
        """Build in a background thread."""
        with self._lock:
            self._build_id += 1
            build_id = self._build_id
            self._ready = None
        self.progress, self.progress_text = 0.0, "starting"

        def report(p, text):
            if build_id != self._build_id:
                raise Cancelled()
            self.progress, self.progress_text = float(p), text

        def work():
            lower_priority()  # the window keeps the cores while a leaf builds
            res, err = None, None
            try:
                res = build(sp, seed, params, live, report)
            except Cancelled:
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

    def poll(self) -> tuple[BuildResult | None, str | None] | None:
        """(result, error) of a finished build, once; None while nothing new is ready."""
        with self._lock:
            ready, self._ready = self._ready, None
        if ready is None or ready[0] != self._build_id:
            return None
        return ready[1], ready[2]

    def join(self, timeout: float | None) -> bool:
        """Wait for the running build; False when it is still running after ``timeout``."""
        t = self._thread
        if t is not None:
            t.join(timeout)
            return not t.is_alive()
        return True
