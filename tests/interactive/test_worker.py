"""The simulation worker (GL-free): background stepping, snapshots, live parameters, pacing,
dry-to-end; and that the numba kernels release the GIL so the worker thread lets the UI run."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from leafsim.interactive.session import Session
from leafsim.interactive.eta import (
    ETA_AFTER_S,
    ETA_AFTER_WORK,
    ETA_WINDOW,
    NO_PATH_FIT_BELOW,
    DryingEta,
    duration,
    time_left,
    time_left_from_decay,
)
from helpers.paths import HANG_S
from leafsim.sim.run import DRY_END_FRACTION


def until(cond, timeout=HANG_S):
    """Poll ``cond`` until it holds; ``timeout`` only bounds a hang (never a speed requirement)."""
    t0 = time.time()
    while time.time() - t0 < timeout:
        if cond():
            return True
        time.sleep(0.005)
    return cond()


def idle_waits(w) -> int:
    """How often the worker thread has gone to wait on its condition with nothing wanted
    (counted from the first call for ``w``, which wraps the wait).  ``_turn`` waits there when
    there is nothing to do (``_pace`` waits while playing, counted only once paused): the count
    rising after a pause means the step that was in flight has finished and the worker steps
    again only when asked."""
    n = getattr(w, "_test_idle_waits", None)
    if n is None:
        n = w._test_idle_waits = [0]
        real = w._cond.wait

        def wait(timeout=None):
            if not w._wanted():  # called holding the condition's lock
                n[0] += 1
            return real(timeout)

        w._cond.wait = wait
    return n[0]


def assert_stays_paused(pb):
    """The worker, told to stop stepping (paused, an error, a pause frame reached), steps at most
    the one step already in flight, then goes idle; after waking once more with nothing to do
    (its idle wait times out every 0.25 s) it has not stepped and published nothing new.
    Synchronised on the worker's own idle waits (progress), never on a clock."""
    w = pb.worker
    f_pause = w.run.state.frame  # read after the pause: at most one step can still be in flight
    n = idle_waits(w)
    assert until(lambda: idle_waits(w) > n or w.run.state.frame > f_pause + 1)
    f = w.run.state.frame
    assert f <= f_pause + 1, (f_pause, f)
    n = idle_waits(w)
    assert until(lambda: idle_waits(w) > n or w.run.state.frame != f)  # woke, nothing to do, waits again
    assert w.run.state.frame == f
    pb.take_snapshot()
    # the last frame stepped is the one shown (publishing is paced while playing: the frame a
    # pause stopped at was often never published, and the window showed an older one)
    assert pb.state.frame == f, (pb.state.frame, f)
    n = idle_waits(w)
    assert until(lambda: idle_waits(w) > n or w.run.state.frame != f)
    assert w.run.state.frame == f
    assert not pb.take_snapshot() and pb.state.frame == f  # nothing new published either
    return f


@pytest.fixture()
def s():
    s = Session("oak", overrides={"mesh.spacing": 0.05})
    s.playback.start_worker()
    yield s
    s.close()


def test_kernels_release_the_gil():
    from numba.core.registry import CPUDispatcher

    from leafsim.sim import pigments as colour
    from leafsim.sim.kernels import osmosis, pbd, shrink

    found = []
    for mod in (osmosis, pbd, shrink, colour):
        for name, obj in vars(mod).items():
            # the cached (top-level) kernels; inlined helpers run inside them
            if isinstance(obj, CPUDispatcher) and type(obj._cache).__name__ != "NullCache":
                found.append((mod.__name__, name, bool(obj.targetoptions.get("nogil"))))
    assert len(found) > 15
    assert all(ok for *_, ok in found), [f for f in found if not f[2]]


def test_plays_in_background_and_snapshots_stay_consistent(s):
    assert s.frame == 0
    s.playback.play(True)
    assert until(lambda: s.playback.take_snapshot() and s.frame >= 3)
    snap_state = s.state
    q = snap_state.particle_q.copy()
    w = snap_state.particle_water.copy()
    frame = snap_state.frame
    assert until(lambda: s.playback.take_snapshot() and s.frame >= frame + 5)
    # the snapshot the UI held was never touched by the worker
    assert snap_state.frame == frame
    np.testing.assert_array_equal(snap_state.particle_q, q)
    np.testing.assert_array_equal(snap_state.particle_water, w)
    assert s.state is not snap_state and s.water_fraction() < 1.0
    # every snapshot's history record arrived, in order
    fr = list(s.playback.history["frame"])
    assert fr == sorted(fr) and fr[0] == 0 and fr[-1] == s.frame
    s.playback.play(False)
    assert_stays_paused(s.playback)
    assert not s.playback.playing


def test_sim_rate_reads_zero_once_paused(s):
    """The simulated-time rate is the playing leaf's; paused it is 0 (the last published rate
    used to stay on the status bar and the stats panel)."""
    s.playback.play(True)
    assert until(lambda: s.playback.take_snapshot() and s.frame >= 5 and s.playback.sim_rate > 0.0)
    s.playback.play(False)
    assert until(lambda: not s.playback.playing)
    s.playback.take_snapshot()
    assert s.playback.sim_rate == 0.0


def test_live_params_reach_the_worker_while_it_plays(s):
    s.playback.play(True)
    until(lambda: s.playback.take_snapshot() and s.frame >= 2)
    for k in range(20):  # a burst of slider changes while it steps
        s.set_params({"osmosis.evaporation_top": 0.5 + 0.1 * k, "colour.age_rate": 0.01 * (k + 1)})
    assert until(lambda: s.simulator.params["osmosis.evaporation_top"] == pytest.approx(2.4))
    assert s.simulator.params["colour.age_rate"] == pytest.approx(0.2)
    f = s.frame
    assert until(lambda: s.playback.take_snapshot() and s.frame > f + 2)  # still stepping
    assert s.playback.sim_error is None


def test_single_steps_while_paused(s):
    s.playback.request_steps(3)
    assert until(lambda: s.playback.take_snapshot() and s.frame >= 3)  # (== 3 would wait for ever past it)
    assert assert_stays_paused(s.playback) == 3 and s.frame == 3


def test_a_pause_as_the_worker_wakes_does_not_swallow_the_next_step(s):
    """The pause arriving just after the worker woke to play: it used to decide "a step is
    wanted" and "free play or a single step" in two locked sections, so it ran the step as a
    single one and took the count of requested steps to -1, and the next Step did nothing."""
    w = s.playback.worker
    real = w._wanted
    paused_at = []

    def wanted():  # called holding the worker's condition, as play(False) takes it
        r = real()
        if r and w._playing and not paused_at:
            paused_at.append(w.run.state.frame)
            w._playing = False  # the pause, right after the worker saw "playing"
        return r

    w._wanted = wanted
    s.playback.play(True)
    assert until(lambda: paused_at)
    f = assert_stays_paused(s.playback)
    assert w._steps == 0
    s.playback.request_steps(1)
    assert until(lambda: s.playback.take_snapshot() and s.frame >= f + 1)
    assert assert_stays_paused(s.playback) == f + 1


def test_speed_limits_simulated_time(s):
    dt = s.sim_params["dynamics.dt"]
    s.playback.set_speed(5 * dt)  # 5 frames per wall second
    s.playback.play(True)
    # waits for progress (the first step may compile the kernels), then counts the frames
    # published over a window of ten: never more than 5 a wall second (with slack for the pacing's
    # 0.25 s catch-up); a busy machine only makes the window longer
    assert until(lambda: s.playback.take_snapshot() and s.frame >= 3)
    f0, t0 = s.frame, time.time()
    assert until(lambda: s.playback.take_snapshot() and s.frame >= f0 + 10)
    frames, elapsed = s.frame - f0, time.time() - t0
    assert frames <= 5 * elapsed * 1.5 + 2, (frames, elapsed)
    # as fast as possible: no longer held to 5 frames per wall second.  Waits for progress
    # (oak at this size steps in ~1 ms), never for a clock: a busy machine only makes it late
    s.playback.set_speed(None)
    f, t1 = s.frame, time.time()
    assert until(lambda: (s.playback.take_snapshot() or True)
                 and s.frame - f > 5 * (time.time() - t1) * 1.5 + 30), (s.frame - f, time.time() - t1)


def test_dry_to_end(s):
    s.set_params({"osmosis.evaporation_top": 50.0, "osmosis.evaporation_bottom": 50.0})
    assert s.playback.dry_time_left() is None  # not drying: nothing to estimate
    s.playback.dry_to_end()
    assert s.playback.drying
    assert until(lambda: (s.playback.take_snapshot() or True) and not s.playback.drying)
    s.playback.take_snapshot()
    assert s.water_fraction() <= DRY_END_FRACTION + 1e-9
    assert s.playback.dry_progress() == pytest.approx(1.0) and not s.playback.playing
    assert s.playback.worker.dry_done
    assert s.playback.dry_time_left() is None  # done


def test_time_left_extrapolates_the_pace_since_the_press():
    # 10 s for 0.2 → 0.45 of the work: 0.55 left at 0.025 a second
    assert time_left(10.0, 0.2, 0.45) == pytest.approx(22.0)
    assert time_left(30.0, 0.0, 1.0) == 0.0
    # too early to tell: under ETA_AFTER_S, or under ETA_AFTER_WORK of the work done
    assert time_left(ETA_AFTER_S * 0.99, 0.0, 0.5) is None
    assert time_left(100.0, 0.4, 0.4 + ETA_AFTER_WORK * 0.99) is None
    assert time_left(ETA_AFTER_S, 0.4, 0.4 + ETA_AFTER_WORK) is not None


def test_divergence_stops_and_reports(s):
    s.playback.play(True)
    until(lambda: s.playback.take_snapshot() and s.frame >= 1)
    with s.playback.worker._step_lock:  # poison the worker's own state between two steps
        s.playback.worker.run.state.particle_q[0, 0] = np.nan
    assert until(lambda: (s.playback.take_snapshot() or True) and s.playback.sim_error is not None)
    assert "diverged" in s.playback.sim_error
    assert_stays_paused(s.playback)
    s.reset()
    assert s.frame == 0 and s.playback.sim_error is None


def test_reset_and_rebuild_while_playing(s):
    s.playback.play(True)
    until(lambda: s.playback.take_snapshot() and s.frame >= 3)
    s.reset()
    assert s.frame == 0 and s.playback.playing  # playing carries over to the fresh leaf
    old = s.playback.worker
    s.set_params({"mesh.spacing": 0.06})
    s.apply_rebuild()
    assert s.wait(120)
    assert s.playback.worker is not old and s.playback.playing
    assert until(lambda: not old.running)  # the old worker thread ended
    assert until(lambda: s.playback.take_snapshot() and s.frame >= 2)


def test_reset_without_waiting_while_playing(s):
    s.playback.play(True)
    assert until(lambda: s.playback.take_snapshot() and s.frame >= 5)
    s.reset(wait=False)  # the GUI's Reset: returns at once, the worker makes the fresh leaf
    assert until(lambda: (s.playback.take_snapshot() or True) and s.playback.history["frame"] and s.playback.history["frame"][0] == 0
                 and s.frame < 5 and s.playback.worker.epoch >= 1)
    fr = list(s.playback.history["frame"])
    assert fr == sorted(fr)  # the old run's records were dropped with the reset


def test_simulator_is_made_on_the_build_thread(monkeypatch):
    import threading

    from leafsim.sim import simulator as simmod

    made = []
    orig = simmod.Simulator.__init__

    def init(self, *a, **k):
        made.append(threading.current_thread().name)
        orig(self, *a, **k)

    monkeypatch.setattr(simmod.Simulator, "__init__", init)
    s = Session("oak", overrides={"mesh.spacing": 0.06}, build=False)
    s.playback.start_worker()
    s.rebuild_async()
    assert s.wait(120) and s.ready
    s.close()
    assert made == ["leafsim-build"]  # installing it on the UI thread constructs none


def test_warming_up_until_the_first_step_and_play_until_pauses_there():
    """The status bar says the kernels compile while a new worker's first step runs; play_until
    pauses exactly at its frame (gui --frames)."""
    s = Session("oak", overrides={"mesh.spacing": 0.05})
    try:
        pb = s.playback
        assert not pb.warming_up  # not asked to step yet
        pb.play(True)
        assert pb.warming_up
        pb.play(False)
        pb.step(1)  # synchronous: the first step finishes
        assert not pb.warming_up
        pb.start_worker()
        pb.play_until(7)
        assert until(lambda: pb.take_snapshot() and s.frame >= 7 and not pb.playing)
        assert assert_stays_paused(pb) == 7 and s.frame == 7
    finally:
        s.close()


def test_time_left_from_decay_integrates_the_fitted_loss_rate():
    # exponential (a = 1): the water halves every 100 frames at 0.05 s a frame, so 0.08 → 0.02
    # is two more halvings: 200 frames, 10 s (the halves' rates at their mean water: 1 % off)
    exp = [(0.05 * i, 0.16 * 0.5 ** (i / 100)) for i in range(101)]
    assert time_left_from_decay(exp, 0.02) == pytest.approx(10.0, rel=0.02)
    # a constant loss (a = 0) of 0.001 a frame: 0.06 → 0.02 is 40 frames, 2 s
    lin = [(0.05 * i, 0.16 - 0.001 * i) for i in range(101)]
    assert time_left_from_decay(lin, 0.02) == pytest.approx(2.0, rel=1e-3)
    # in between (dw/df = −c w^0.5): the closed form, w(f) = (√w0 − c f / 2)²
    c = 0.002
    mid = [(0.05 * i, (math.sqrt(0.16) - c * i / 2) ** 2) for i in range(101)]
    f_left = 2 * (math.sqrt(mid[-1][1]) - math.sqrt(0.02)) / c
    assert time_left_from_decay(mid, 0.02) == pytest.approx(0.05 * f_left, rel=0.02)
    assert time_left_from_decay([(0.0, 0.16), (1.0, 0.1), (2.0, 0.01)], 0.02) == 0.0
    # no estimate unless the water falls in both halves over a positive time
    assert time_left_from_decay([(0.05 * i, 0.08) for i in range(101)], 0.02) is None
    assert time_left_from_decay([(0.0, w) for _, w in exp], 0.02) is None
    assert time_left_from_decay(exp[:2], 0.02) is None
    # a target of 0 is never reached by some fits (a ≥ 1): no estimate, no division by zero
    assert time_left_from_decay(exp, 0.0) is None
    assert time_left_from_decay([(0.0, 0.16), (1.0, float("nan")), (2.0, 0.08)], 0.02) is None


def _feed(eta, curve, t0=0.0, every=1, on_path=False):
    """Frames of 0.05 s whose water follows ``curve`` (a function of the osmosis step), the
    water moving every ``every``-th frame only; returns the clock after the last frame."""
    t = t0
    for f in range(every * 150):
        t += 0.05
        eta.frame(t, curve(f // every), on_path)
    return t


def test_drying_eta_fits_the_tail_per_water_step_and_counts_down():
    curve = lambda k: 0.3 * 0.5 ** (k / 100)  # noqa: E731  halves every 100 water steps
    for every in (1, 4):
        eta = DryingEta(0.02)
        eta.start(0.0, 0.0)
        t = _feed(eta, curve, every=every)  # no drying path, all below NO_PATH_FIT_BELOW
        w = curve(149)
        frames_left = every * 100 * math.log2(w / 0.02)
        assert eta.left(t, 0.5) == pytest.approx(0.05 * frames_left, rel=0.03)
        # read 2 s later without a new frame: 2 s less
        assert eta.left(t + 2.0, 0.5) == pytest.approx(0.05 * frames_left - 2.0, rel=0.03)


def test_drying_eta_uses_the_pace_until_the_tail():
    eta = DryingEta(0.02)
    eta.start(0.0, 0.0)
    t = _feed(eta, lambda k: 0.95 - 0.001 * k)  # no path, above NO_PATH_FIT_BELOW: the pace
    assert eta.left(t, 0.4) == pytest.approx(t * 0.6 / 0.4)
    eta.start(0.0, 0.0)
    t = _feed(eta, lambda k: 0.9 - 0.001 * k, on_path=True)  # path frames: never fitted
    assert eta.left(t, 0.3) == pytest.approx(t * 0.7 / 0.3)
    # after the hand-over the own mesh's frames are fitted, above NO_PATH_FIT_BELOW too
    t = _feed(eta, lambda k: 0.8 * 0.5 ** (k / 100), t0=t)
    assert len(eta._seen) == ETA_WINDOW + 1 and 0.8 * 0.5 ** 0.49 > NO_PATH_FIT_BELOW
    frames_left = 100 * math.log2(0.8 * 0.5 ** 1.49 / 0.02)
    assert eta.left(t, 0.8) == pytest.approx(0.05 * frames_left, rel=0.03)
    eta.stop()
    assert eta.left(t, 0.8) is None


def test_durations_read_as_seconds_minutes_hours():
    assert [duration(x) for x in (0.4, 17.2, 59.6, 125.0, 3599.0, 3600.0 * 19.4, float("inf"))] == [
        "0 s", "17 s", "1 min 00 s", "2 min 05 s", "59 min 59 s", "19 h 24 min", "?"]


def test_a_failed_reset_ends_the_wait_and_is_shown(s, monkeypatch):
    """A reset whose fresh leaf cannot be made (here the simulator fails) used to end the worker
    thread, which ended the waiting; now the thread survives it, so the waiter must be told:
    ``reset(wait=True)`` returns, the error is the worker's, and a later reset works again."""
    w = s.playback.worker
    sim = w.simulator

    def boom():
        raise RuntimeError("fresh state failed")

    monkeypatch.setattr(sim, "state", boom)
    s.reset(wait=True)  # returned: it hung for ever before
    assert w.running and w.error is not None and "reset failed" in w.error and "fresh state failed" in w.error
    s.playback.take_snapshot()
    assert "reset failed" in s.playback.sim_error  # shown in place of whatever error it was to clear
    monkeypatch.undo()
    s.reset(wait=True)
    assert w.error is None and s.frame == 0


def test_a_reset_asked_for_while_one_fails_is_still_made(s, monkeypatch):
    """A second reset requested while the first is failing is made afterwards (the failure
    dropped it, and its waiter returned at once, with the leaf not reset)."""
    import threading

    w = s.playback.worker
    sim = w.simulator
    real = sim.state
    entered, release = threading.Event(), threading.Event()
    calls = []

    def first_fails():
        calls.append(1)
        if len(calls) == 1:
            entered.set()
            release.wait(120)
            raise RuntimeError("first reset failed")
        return real()

    monkeypatch.setattr(sim, "state", first_fails)
    w.request_reset()
    assert entered.wait(120)
    second = w.request_reset()
    release.set()
    assert until(lambda: w.epoch >= second)
    assert len(calls) == 2 and w.error is None


def test_dry_to_end_gives_up_with_a_reason_when_the_water_cannot_fall(s, monkeypatch):
    """No evaporation: the button ran for ever, its bar at 0 %, and said nothing.  Now it stops
    once the water left has not fallen for STALL_FRAMES frames (as ``--until dry`` does) and says
    why; with osmosis off it refuses at once; a later press with evaporation dries as before."""
    from leafsim.interactive import worker as wmod

    monkeypatch.setattr(wmod, "STALL_FRAMES", 40)
    s.set_params({"osmosis.evaporation_top": 0.0, "osmosis.evaporation_bottom": 0.0})
    pb = s.playback
    pb.dry_to_end()
    assert until(lambda: (pb.take_snapshot() or True) and not pb.drying)
    pb.take_snapshot()  # the frame it stopped at (published before "drying" went off)
    assert pb.dry_stalled and "has not fallen in 40 frames" in pb.dry_stalled and "\n" not in pb.dry_stalled
    assert 40 <= s.frame <= 60 and s.water_fraction() > 0.99
    s.set_params({"osmosis.evaporation_top": 50.0, "osmosis.evaporation_bottom": 50.0})
    pb.dry_to_end()
    assert pb.dry_stalled is None
    assert until(lambda: (pb.take_snapshot() or True) and not pb.drying)
    pb.take_snapshot()
    assert pb.dry_stalled is None and s.water_fraction() <= DRY_END_FRACTION + 1e-9
    s.set_params({"effects.osmosis": False})
    pb.dry_to_end()
    assert not pb.drying and "effects.osmosis off" in pb.dry_stalled


def test_a_snapshot_that_keeps_failing_leaves_the_worker_idle(s):
    """A record (or render) that raises: the run stops with the error and the worker waits.
    The stepped frame stayed "unpublished", so the worker retried publishing it at once, failed
    again, and spun without ever waiting (a whole core, the GIL taken from the UI thread)."""
    w = s.playback.worker
    real = w._record

    def record(state, ms):
        if state.frame >= 1:
            raise RuntimeError("record broke")
        return real(state, ms)

    w._record = record
    turns = [0]
    turn = w._turn

    def counted(t):
        turns[0] += 1
        return turn(t)

    w._turn = counted
    s.playback.play(True)
    assert until(lambda: w.error is not None)
    assert "record broke" in w.error and not w.playing
    n, t0 = idle_waits(w), turns[0]
    # spinning, it served thousands of turns without one idle wait
    assert until(lambda: idle_waits(w) > n + 1 or turns[0] > t0 + 1000)
    assert turns[0] <= t0 + 10, turns[0] - t0
    assert w.running
