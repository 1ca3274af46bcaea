"""The simulation of the leaf on screen: one :class:`~leafsim.interactive.worker.SimWorker` per
model, driven by the GUI's buttons (play, pause, step, reset, speed, "dry to end") and read
once per window frame (:meth:`Playback.take_snapshot`).  What the user asked for (playing,
speed) carries over when a rebuild brings a new model and a new worker."""

from __future__ import annotations

import time
from typing import Callable

from leafsim.interactive.history import new_history
from leafsim.interactive.worker import SimWorker
from leafsim.sim.run import Run


class Playback:
    """The stepping of one leaf at a time.

    Attributes
    ----------
    worker : the current SimWorker (None before the first model).
    state : the latest snapshot's state (never mutated).
    history : dict of deques, one record per published frame.
    last_ms : stage timings of the latest step; sim_rate : simulated s per wall s (recent);
    sim_error : why the simulation stopped (diverged), or None.
    """

    def __init__(self):
        self.worker: SimWorker | None = None
        self.state = None
        self.snapshot = None
        self.history = new_history()
        self.last_ms: dict[str, float] = {}
        self.sim_rate = 0.0
        self.sim_error: str | None = None
        self._threaded = False
        self._play_wanted = False
        self._pause_at: int | None = None
        self._dry_wanted = False
        self._speed_wanted: float | None = None
        self._hold_wanted: int | None = None
        self._snap_seq = -1
        self._epoch = 0

    # ------------------------------------------------------------------ a new model
    def attach(self, run: Run, record: Callable, render: Callable) -> None:
        """Step ``run`` from now on with a new worker (the old one is told to stop; its playing
        state and speed carry over)."""
        self.sim_error = None
        self.clear_history()
        old = self.worker
        self.worker = SimWorker(run, record, render)
        self.worker.set_speed(self._speed_wanted)
        self.worker.hold_every(self._hold_wanted)
        self.worker.play(self._play_wanted if old is None else (old.playing and not old.drying))
        if old is None and self._pause_at is not None:
            self.worker.play_until(self._pause_at)
        if old is None and self._dry_wanted:
            self.worker.dry_to_end(True)
        if old is not None:
            old.stop()
        if self._threaded:
            self.worker.start()
        self._snap_seq = -1
        self._epoch = 0
        self.take_snapshot()

    def clear_history(self) -> None:
        self.history = new_history()
        self.last_ms = {}

    # ------------------------------------------------------------------ reading
    def take_snapshot(self) -> bool:
        """Make :attr:`state` the worker's latest published frame and append its history
        records; True when it is a new one.  (The GUI calls this once per frame.)"""
        w = self.worker
        if w is None:
            return False
        snap = w.snapshot()
        if snap.epoch != self._epoch:  # the worker reset the leaf: a new history
            self._epoch = snap.epoch
            self.clear_history()
            self.sim_error = None
        for rec in snap.records:
            for k, v in rec.items():
                self.history[k].append(v)
        if snap.ms:
            self.last_ms = dict(snap.ms)
        error = w.error or snap.error  # the newest: a failed reset replaces the error it was to clear
        if error:
            self.sim_error = error
        # paused, the last published rate is history (it read on, e.g. 0.0614 sim s / s, after a pause)
        self.sim_rate = snap.sim_rate if w.running and (w.playing or w.drying) else 0.0
        if snap.seq == self._snap_seq:
            return False
        self._snap_seq = snap.seq
        self.state = snap.state
        self.snapshot = snap
        return True

    # ------------------------------------------------------------------ stepping
    def step(self, n: int = 1) -> dict:
        """Advance ``n`` frames on the caller's thread and take the result; milliseconds per
        stage of the last frame ({} before the first model or after a divergence)."""
        if self.worker is None or self.sim_error is not None:
            return {}
        ms = self.worker.step_sync(n)
        self.take_snapshot()
        return ms

    def start_worker(self) -> None:
        """Step in a background thread from now on (this and every later model)."""
        self._threaded = True
        if self.worker is not None:
            self.worker.start()

    def set_params(self, params) -> None:
        if self.worker is not None:
            self.worker.set_params(params)

    def play(self, on: bool = True) -> None:
        """Play or pause (before the first model: play once it is there)."""
        self._play_wanted = bool(on)
        if self.worker is not None:
            self.worker.play(on and self.sim_error is None)

    @property
    def warming_up(self) -> bool:
        """The first step is running (the kernels may be compiling)."""
        return self.worker is not None and self.worker.warming_up

    def play_until(self, frame: int) -> None:
        """Play as fast as possible up to simulation frame ``frame``, then pause (before the
        first model: once it is there)."""
        self._pause_at = int(frame)
        if self.worker is not None:
            self.worker.play_until(frame)

    @property
    def playing(self) -> bool:
        return self.worker is not None and self.worker.playing

    def set_speed(self, speed: float | None) -> None:
        """Simulated seconds per wall second (None: as fast as possible)."""
        self._speed_wanted = speed
        if self.worker is not None:
            self.worker.set_speed(speed)

    def hold_every(self, n: int | None) -> None:
        """Recording a take: playing waits at every ``n``-th frame until :meth:`release_hold`
        (:meth:`SimWorker.hold_every`); None: never.  Carries over to a rebuilt leaf's worker."""
        self._hold_wanted = n
        if self.worker is not None:
            self.worker.hold_every(n)

    def release_hold(self) -> None:
        if self.worker is not None:
            self.worker.release_hold()

    def request_steps(self, n: int = 1) -> None:
        """``n`` frames in the background (the Step button)."""
        if self.worker is not None and self.sim_error is None:
            self.worker.request_steps(n)

    @property
    def dry_done(self) -> bool:
        """The last "dry to end" reached the dry threshold (or its frame budget)."""
        return self.worker is not None and self.worker.dry_done

    @property
    def dry_stalled(self) -> str | None:
        """Why the last "dry to end" gave up (the water could not fall), or None."""
        return None if self.worker is None else self.worker.dry_stalled

    def dry_to_end(self, on: bool = True) -> None:
        """Fast-forward until the leaf is dry (:meth:`SimWorker.dry_to_end`; before the first
        model: once it is there)."""
        if self.worker is None:
            self._dry_wanted = bool(on)
        if self.worker is not None:
            self.worker.dry_to_end(on)

    @property
    def drying(self) -> bool:
        return self.worker is not None and self.worker.drying

    def dry_progress(self) -> float:
        return 0.0 if self.worker is None else self.worker.dry_progress()

    def dry_time_left(self) -> float | None:
        """Wall seconds "Dry to end" still needs (None: not drying, or too early to tell)."""
        return None if self.worker is None else self.worker.dry_time_left()

    def reset(self, fresh: Callable[[], None], wait: bool = True) -> None:
        """Back to the fresh leaf.  Without a running worker thread ``fresh()`` makes it at once;
        with one, the worker makes it between two steps (``wait=False``: return at once, the
        next snapshot shows it)."""
        w = self.worker
        if w is None:
            return
        if not w.running:
            fresh()
            return
        epoch = w.request_reset()
        while wait and w.running and w.epoch < epoch and w.reset_failed < epoch:  # a failed reset ends the wait
            time.sleep(0.002)
        if wait:
            self.take_snapshot()

    def close(self) -> None:
        """Stop the worker thread (the window closes)."""
        if self.worker is not None:
            self.worker.stop(join=2.0)
