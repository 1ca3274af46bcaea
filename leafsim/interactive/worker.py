"""The simulation worker: one leaf's :class:`~leafsim.sim.run.Run` stepped on a background
thread, so the window never waits for a step (core: no OpenGL, no imgui).

Double buffering: the worker steps its own :class:`~leafsim.sim.model.State` (the back
buffer) and publishes :class:`Snapshot` objects -- a ``State.copy()`` plus the renderer's
per-frame arrays made from that copy -- that nobody mutates afterwards (the front buffer).
The UI thread only ever reads the latest snapshot, so what it draws is one consistent frame.

Everything the UI asks for goes through a lock-protected mailbox the worker reads between
two steps: new live parameters (applied to the simulator on the worker thread, never in the
middle of a step), play/pause, a speed (simulated seconds per wall second, or ``None`` = as
fast as possible), a number of single steps, "dry to end", reset.  The numba kernels release
the GIL (``nogil=True``), so a step in the worker leaves the UI thread free; the worker thread
also runs at a lower scheduling priority (``WORKER_NICE``), so on a small machine the
rasteriser and the UI thread get the cores first and "as fast as possible" means as fast as
the UI leaves room for.

Example
-------
>>> w = SimWorker(Run(model, params), record=lambda state, ms: {})   # doctest: +SKIP
>>> w.start(); w.play(True)                                        # doctest: +SKIP
>>> snap = w.snapshot()            # latest consistent frame: snap.state, snap.render, snap.frame
"""

from __future__ import annotations

import os
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from leafsim.interactive.eta import DryingEta
from leafsim.sim.run import DRY_END_FRACTION, DRY_MAX_FRAMES, STALL_FRAMES, Run

#: nice increment of the worker thread (Linux: per thread); the UI and llvmpipe keep priority
WORKER_NICE = 5
#: the worker publishes at most this many snapshots per wall second while it runs freely
PUBLISH_HZ = 60.0
#: ... and this many during "dry to end", where each snapshot (a state copy and the renderer's
#: arrays) is time the drying does not get
DRY_PUBLISH_HZ = 5.0


@dataclass
class Snapshot:
    """One published frame.  ``state`` is a private copy (never mutated); ``render`` the
    ``LeafView.update`` arrays of that copy (or None); ``records`` the history entries made
    since the previous snapshot; ``sim_rate`` simulated seconds per wall second (recent)."""

    seq: int
    state: Any
    render: dict | None = None
    render_key: Any = None
    ms: dict = field(default_factory=dict)
    records: list = field(default_factory=list)
    sim_rate: float = 0.0
    error: str | None = None
    epoch: int = 0  # increments at every reset of the stepped state

    @property
    def frame(self) -> int:
        return self.state.frame

    @property
    def time(self) -> float:
        return self.state.time


def name_thread(name: str) -> None:
    """Give the calling thread an OS-level name (Linux; shows in top -H and /proc)."""
    try:
        import ctypes

        ctypes.CDLL(None).prctl(15, name.encode()[:15], 0, 0, 0)  # PR_SET_NAME
    except (OSError, AttributeError):
        pass


def lower_priority(nice: int = WORKER_NICE) -> None:
    """Lower the calling thread's scheduling priority (Linux: nice is per thread); no-op where
    unsupported or not permitted."""
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), min(19, os.getpriority(os.PRIO_PROCESS, 0) + nice))
    except (AttributeError, OSError):
        pass


class SimWorker:
    """Steps ``run`` in a daemon thread (see the module docstring).

    Parameters
    ----------
    run : Run (owned by the worker from now on: change its simulator's parameters only
        through :meth:`set_params`; the UI gets copies of its state).
    record : ``record(state, ms) -> dict`` history entry (called on the worker thread).
    render : optional ``render(state) -> (dict, key)`` per-frame renderer arrays of a snapshot
        (made on the worker thread, so the UI thread only uploads).
    """

    def __init__(self, run: Run, record: Callable, render: Callable | None = None):
        self.run = run
        self.simulator = run.sim
        self._record = record
        self._render = render
        self._cond = threading.Condition()
        self._step_lock = threading.Lock()
        self._params = None        # pending live parameters (latest wins)
        self._playing = False
        self._speed: float | None = None
        self._steps = 0            # single steps requested
        self._dry = False
        self._dry_until = 0
        self._dry_best = (1.0, 0)  # (least water fraction seen while drying, the frame it was seen)
        self.dry_stalled: str | None = None  # why the last "Dry to end" gave up (None: it did not)
        self._eta = DryingEta(DRY_END_FRACTION)  # the time "Dry to end" still needs
        self._pause_at: int | None = None  # play pauses at this frame (scripted runs)
        self._hold_every: int | None = None  # recording: free play waits at every this many frames
        self._hold_next = 0  # ... the next frame it waits at
        self._held = False  # waiting there until the UI has drawn it (release_hold)
        self._steps_done = 0  # steps finished by this worker (0: the first may be compiling)
        self._unpublished = False  # a step's frame is not published yet (publishing is paced)
        self._last_ms: dict = {}  # that step's timings
        self._stop = False
        self._thread: threading.Thread | None = None
        self._records: list = []
        self._rate = deque(maxlen=64)  # (wall, sim time) samples
        self._seq = 0
        self.epoch = 0
        self._reset_wanted = 0
        self.reset_failed = 0  # the last epoch a failed reset was asked for (its waiters stop waiting)
        self.error: str | None = None
        self.dry_done = False
        self._snap = self._make_snapshot({})
        self._snap_taken = False  # the first snapshot's record (frame 0) is handed out too

    # ------------------------------------------------------------------ thread
    def start(self) -> "SimWorker":
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="leafsim-sim", daemon=True)
            self._thread.start()
        return self

    def stop(self, join: float | None = None) -> None:
        """Ask the thread to end after its current step (``join`` seconds to wait, or none)."""
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        if join is not None and self._thread is not None:
            self._thread.join(join)

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def _wanted(self) -> bool:
        return (self._stop or self._steps > 0 or self._reset_wanted > self.epoch
                or ((self._playing or self._dry) and self.error is None and not self._held))

    def _run(self) -> None:
        name_thread("leafsim-sim")
        lower_priority()
        t_next = time.perf_counter()
        while t_next is not None:
            try:
                t_next = self._turn(t_next)
            except Exception as e:  # the thread must survive anything: the UI shows it
                self._failed(e)
                t_next = time.perf_counter()

    def _turn(self, t_next: float) -> float | None:
        """One request served (a step, a reset, the last step's frame published); None when
        asked to stop.  Whether a step is wanted and which kind it is are decided in one locked
        section: decided apart, a pause between the two ran a step as a "single" one and took
        the count below zero, so the next Step did nothing."""
        with self._cond:
            while not self._wanted() and not self._unpublished:
                self._cond.wait(0.25)
                self._apply_params()  # parameters change while paused too
            if self._stop:
                return None
            reset = self._reset_wanted if self._reset_wanted > self.epoch else 0  # the request served
            step = not reset and self._wanted()
            free = (self._playing or self._dry) and self.error is None and not self._held
            if step and not free:
                self._steps -= 1
            speed = None if self._dry else self._speed
            last_single = not free and self._steps == 0
        if reset:
            try:
                with self._step_lock:
                    self._reset_locked(self.simulator.state())
            except Exception as e:
                self._failed(e, reset)
            return t_next
        if not step:  # paused after free play: its last frame (publishing is paced) is shown
            with self._step_lock:
                if self._unpublished:
                    self._publish(self._last_ms)
            return time.perf_counter()
        self._step_once(publish_now=last_single)
        return self._pace(speed, t_next) if free else time.perf_counter()

    def _failed(self, e: Exception, reset: int = 0) -> None:
        """Something besides a step failed (applying parameters, a reset, a snapshot): the run
        stops with an error, as after a failed step, instead of the thread ending silently
        (the window showed "playing" while nothing moved).  ``reset``: the reset request that
        failed; it is not retried and whoever waits for it stops waiting (:attr:`reset_failed`),
        while a reset asked for meanwhile is still made."""
        with self._cond:
            if reset:
                self.error = (f"reset failed ({type(e).__name__}: {e}): change the parameters or rebuild the leaf")
                self.reset_failed = max(self.reset_failed, reset)
                if self._reset_wanted == reset:  # nothing newer asked for
                    self._reset_wanted = self.epoch
            elif self.error is None:
                self.error = (f"simulation failed ({type(e).__name__}: {e}) at frame {self.run.state.frame}: "
                              "press Reset or change the parameters")
            self._dry = self._playing = False
            # the frame is published below or not at all: left "unpublished", a snapshot that
            # keeps failing (a record or render raising) made _turn retry it without waiting
            self._unpublished = False
            self._cond.notify_all()
        try:
            with self._step_lock:  # as every other publish: not beside a step of the caller's thread
                self._publish({})
        except Exception:  # the UI reads the error from the worker itself (Playback.take_snapshot)
            pass

    def _pace(self, speed: float | None, t_next: float) -> float:
        """Sleep so that simulated time advances at ``speed`` s per wall second."""
        now = time.perf_counter()
        if speed is None or speed <= 0:
            return now
        t_next = max(t_next + float(self.simulator.dt) / speed, now - 0.25)  # no debt build-up
        if t_next > now:
            with self._cond:
                self._cond.wait(t_next - now)  # woken early by any new request
        return t_next

    # ------------------------------------------------------------------ stepping
    def _apply_params(self) -> None:
        p, self._params = self._params, None
        if p is not None:
            self.simulator.set_params(p)

    def _step_once(self, publish_now: bool = False) -> dict:
        with self._step_lock:
            with self._cond:
                self._apply_params()
            if self.error is not None:
                return {}
            ms = self._advance(1)
            self._after_step(ms, publish_now)
        return ms

    def _advance(self, n: int) -> dict:
        """``n`` steps; a step that raises (a kernel meeting NaN, a solver failing) ends the
        run with an error instead of killing the thread."""
        ms: dict = {}
        s = self.run.state
        try:
            for _ in range(n):
                ms = self.run.step()
                if not np.isfinite(s.particle_q[:1]).all():
                    break
        except Exception as e:  # the worker must survive anything: the UI shows it
            finite = bool(np.isfinite(s.particle_q).all())
            why = "diverged (NaN/Inf)" if not finite else f"failed ({type(e).__name__}: {e})"
            self.error = f"simulation {why} at frame {s.frame}: press Reset or lower dynamics.dt"
        self._rate.append((time.perf_counter(), s.time))
        self._steps_done += n
        self._last_ms = ms
        with self._cond:
            self._unpublished = True
        return ms

    def _after_step(self, ms: dict, publish_now: bool) -> None:
        s = self.run.state
        if not np.isfinite(s.particle_q).all() and self.error is None:
            self.error = f"simulation diverged (NaN/Inf) at frame {s.frame}: press Reset or lower dynamics.dt"
        drying = self._dry
        wf = self.water_fraction(s) if drying else 1.0
        if drying:
            self._eta.frame(time.monotonic(), wf, self.simulator.on_coarsest)
        stalled = drying and self._dry_stall(wf, s.frame)
        done = drying and (wf <= DRY_END_FRACTION or self.error is not None or s.frame >= self._dry_until or stalled)
        pause = self._pause_at is not None and s.frame >= self._pause_at
        hold = self._hold_every is not None and s.frame >= self._hold_next
        if hold:
            with self._cond:
                self._held = True
        hz = DRY_PUBLISH_HZ if drying else PUBLISH_HZ
        if done or pause or hold or publish_now or self.error is not None or time.perf_counter() - self._t_pub >= 1.0 / hz:
            self._publish(ms)  # before the flags change: whoever sees "done" sees its frame
        if pause:
            with self._cond:
                self._playing = False
                self._pause_at = None
        if done:
            with self._cond:
                self._dry = self._playing = False
                self.dry_done = True

    def _dry_stall(self, wf: float, frame: int) -> bool:
        """True (and :attr:`dry_stalled` says why) when the water left has not fallen in
        :data:`~leafsim.sim.run.STALL_FRAMES` frames, as a command-line ``--until dry`` gives up
        (not under a weather record, which may hold the air saturated for days): with no
        evaporation the button ran for ever, its bar at 0 %, and said nothing."""
        best, since = self._dry_best
        if wf < best - 1e-9 * max(best, 1.0):
            self._dry_best = (wf, frame)
        elif frame - since >= STALL_FRAMES and self.simulator.params["environment.drive"] != "weather":
            self.dry_stalled = (f"Dry to end stopped at frame {frame}: the water left ({100 * wf:.1f} %) has not fallen in "
                                f"{STALL_FRAMES} frames (evaporation 0, or air that cannot take more water?)")
            return True
        return False

    def water_fraction(self, state=None) -> float:
        s = self.run.state if state is None else state
        return self.run.model.water_fraction(s.particle_water)

    def sim_rate(self) -> float:
        """Simulated seconds per wall second over the last samples (0 when not running)."""
        r = list(self._rate)
        if len(r) < 2 or time.perf_counter() - r[-1][0] > 1.0:
            return 0.0
        (w0, s0), (w1, s1) = r[0], r[-1]
        return (s1 - s0) / max(w1 - w0, 1e-9)

    def _make_snapshot(self, ms: dict, epoch: int | None = None) -> Snapshot:
        st = self.run.state.copy()
        rec = self._record(st, ms)
        render, key = self._render(st) if self._render is not None else (None, None)
        self._t_pub = time.perf_counter()
        self._seq += 1
        return Snapshot(self._seq, st, render, key, dict(ms), [rec] if rec else [], 0.0, self.error,
                        self.epoch if epoch is None else epoch)

    def _publish(self, ms: dict, epoch: int | None = None) -> None:
        snap = self._make_snapshot(ms, epoch)
        snap.sim_rate = self.sim_rate()
        with self._cond:
            if not self._snap_taken:  # the UI has not seen the previous one: keep its records
                snap.records = self._snap.records + snap.records
            self._snap = snap
            self._snap_taken = False
            self._unpublished = False
            self.epoch = snap.epoch  # whoever sees the new epoch finds its snapshot published

    # ------------------------------------------------------------------ UI side
    def snapshot(self) -> Snapshot:
        """The latest published frame (its ``records`` are handed out once)."""
        with self._cond:
            snap = self._snap
            if not self._snap_taken:
                self._snap_taken = True
                return snap
            return Snapshot(snap.seq, snap.state, snap.render, snap.render_key, snap.ms, [], snap.sim_rate, snap.error,
                            snap.epoch)

    def set_params(self, params) -> None:
        """Hand new live parameters to the worker: applied before its next step (at once when
        no step is running)."""
        with self._cond:
            self._params = params
            self._cond.notify_all()
        if self._step_lock.acquire(blocking=False):
            try:
                with self._cond:
                    self._apply_params()
            finally:
                self._step_lock.release()

    def play(self, on: bool) -> None:
        with self._cond:
            self._playing = bool(on)
            self._cond.notify_all()

    def play_until(self, frame: int) -> None:
        """Play as fast as possible and pause at simulation frame ``frame`` (published)."""
        with self._cond:
            self._pause_at = int(frame)
            self._speed = None
            self._playing = self.run.state.frame < frame
            self._cond.notify_all()

    def hold_every(self, n: int | None) -> None:
        """While a take is recorded: free play and "Dry to end" wait at every ``n``-th frame from
        now until :meth:`release_hold`, so that every one of them is drawn and written (they
        were recorded per published snapshot: a take "every 1" held frames 0, 3, 8, 12, 31, ...).
        None: no waiting."""
        with self._cond:
            self._hold_every = None if n is None else max(int(n), 1)
            self._held = False
            self._hold_next = self.run.state.frame + (self._hold_every or 0)
            self._cond.notify_all()

    def release_hold(self) -> None:
        """The frame held at is written: go on to the next one."""
        with self._cond:
            if self._held:
                self._held = False
                self._hold_next = self.run.state.frame + (self._hold_every or 0)
                self._cond.notify_all()

    @property
    def held(self) -> bool:
        """Waiting at a frame of the take for the UI (:meth:`hold_every`)."""
        return self._held

    @property
    def playing(self) -> bool:
        return self._playing or self._dry

    @property
    def warming_up(self) -> bool:
        """Asked to step but no step finished yet: on a first run numba is compiling the
        kernels (about a minute; they are cached for later runs)."""
        return self._steps_done == 0 and self.error is None and (self._playing or self._dry or self._steps > 0)

    def set_speed(self, speed: float | None) -> None:
        """Simulated seconds per wall second, or None = as fast as possible."""
        with self._cond:
            self._speed = None if speed is None else max(float(speed), 1e-6)
            self._cond.notify_all()

    @property
    def speed(self) -> float | None:
        return self._speed

    def request_steps(self, n: int = 1) -> None:
        """Advance ``n`` single frames in the background (while paused)."""
        with self._cond:
            self._steps += max(int(n), 0)
            self._cond.notify_all()

    def dry_to_end(self, on: bool = True) -> None:
        """Run as fast as possible until the water left is at most ``DRY_END_FRACTION`` of the
        initial water (then pause), or stop doing so (``on=False``)."""
        with self._cond:
            self._dry = bool(on) and self.error is None
            self._dry_until = self.run.state.frame + DRY_MAX_FRAMES
            self._dry_best = (self.water_fraction(), self.run.state.frame)
            self.dry_stalled = None
            if self._dry and not self.simulator.effects.get("osmosis", False):
                self._dry = False
                self.dry_stalled = "Dry to end: the water left cannot fall with effects.osmosis off"
            self.dry_done = False
            if self._dry:
                self._eta.start(time.monotonic(), self.dry_progress())
            else:
                self._eta.stop()
            self._cond.notify_all()

    @property
    def drying(self) -> bool:
        return self._dry

    def dry_progress(self) -> float:
        """0 at full water, 1 at the "dry to end" threshold: the share of the drying's work
        done (:meth:`Simulator.drying_progress`)."""
        wf = self.water_fraction(self._snap.state)
        return self.simulator.drying_progress(wf, DRY_END_FRACTION)

    def dry_time_left(self) -> float | None:
        """Wall seconds "Dry to end" still needs (:class:`DryingEta`); None when not drying or
        too early to tell."""
        return self._eta.left(time.monotonic(), self.dry_progress()) if self._dry else None

    def step_sync(self, n: int = 1) -> dict:
        """Advance ``n`` frames on the caller's thread (scripts, tests); waits for a running step."""
        with self._step_lock:
            with self._cond:
                self._apply_params()
            if self.error is not None or n <= 0:
                return {}
            ms = self._advance(n)
            self._after_step(ms, True)
        return ms

    def request_reset(self) -> int:
        """Ask the worker thread for a fresh leaf (made by its simulator between two steps);
        returns the epoch whose first snapshot shows it."""
        with self._cond:
            self._reset_wanted = max(self._reset_wanted, self.epoch, self.reset_failed) + 1  # past a failed one
            self._cond.notify_all()
            return self._reset_wanted

    def reset(self, state) -> None:
        """Replace the stepped state (a fresh leaf) and publish it (caller's thread)."""
        with self._step_lock:
            self._reset_locked(state)

    def _reset_locked(self, state) -> None:
        self.run.state = state
        self.error = None
        with self._cond:
            self._held = False
            self._hold_next = state.frame + (self._hold_every or 0)
        self._dry = False
        self.dry_done = False
        self.dry_stalled = None
        self._rate.clear()
        with self._cond:
            self._apply_params()
            self._snap_taken = True
            epoch = max(self.epoch + 1, self._reset_wanted)
        self._publish({}, epoch)
