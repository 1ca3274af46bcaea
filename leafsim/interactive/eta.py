"""How long a drying still needs, in wall seconds: the window's "Dry to end" and the CLI's
progress bar (``leafsim run --until dry``) say it.

The work-weighted progress (:meth:`Simulator.drying_progress`) tracks the wall time within
0.13 on maple but runs ahead once the leaf's own mesh carries the mechanics: the drying slows
there, so every unit of water costs more frames.  So :class:`DryingEta` extrapolates the pace
since the start (:func:`time_left`) until the leaf's own mesh carries the mechanics and the
drying is in its tail: after the drying path's hand-over, or, for a leaf without a drying
path, once less than ``NO_PATH_FIT_BELOW`` of the water is left.  From then on it fits the
water's decay over the last steps, each of which costs the same (:func:`time_left_from_decay`).
"""

from __future__ import annotations

import math
import threading
from collections import deque

#: "Dry to end" estimates its time left only after this long [s] and this share of its work
ETA_AFTER_S, ETA_AFTER_WORK = 2.0, 0.03
#: steps (frames in which the water changed) of the recent window the water's decay is fitted over
ETA_WINDOW = 100
#: without a drying path the decay is fitted only below this water fraction: earlier the
#: drying's start-up (stomata, the weather's first hours) bends the curve (maple at balanced
#: quality with the weather driving it read 13–39× long at 80–90 % water)
NO_PATH_FIT_BELOW = 0.5


def time_left(elapsed: float, p0: float, p: float) -> float | None:
    """Seconds still needed to reach progress 1 at the pace of the last ``elapsed`` seconds,
    in which progress went from ``p0`` to ``p`` (the share of the drying's work,
    :meth:`Simulator.drying_progress`); None before ``ETA_AFTER_S`` and ``ETA_AFTER_WORK`` of
    the work."""
    done = p - p0
    if not (math.isfinite(elapsed) and math.isfinite(p) and math.isfinite(p0)):
        return None
    if elapsed < ETA_AFTER_S or done < ETA_AFTER_WORK:
        return None
    return max(elapsed * (1.0 - p) / done, 0.0)


def time_left_from_decay(samples: list[tuple[float, float]], target: float) -> float | None:
    """Seconds still needed for the water fraction to fall to ``target`` (> 0), from
    ``samples`` (clock, water fraction) of consecutive steps of equal cost, measured from the
    last sample's clock.  The water's loss per step is fitted as c wᵃ through the window's two
    halves (a = 1: exponential decay, a = 0: a constant rate; maple's own-mesh phase runs at
    a ≈ 0.6, oak's near 0) and integrated down to ``target``; the steps left cost the window's
    seconds per step.  Offline on the whole drying curves, from 100 frames after the hand-over
    on, the steps left came out 0.8–1.1× the real count on maple and oak; an exponential fit
    was up to 1.4× (maple) and 2.8× (oak) long.  0 once the last sample is at the target;
    None when the water does not fall in both halves over a positive time, or for a target
    of 0 (the fit's integral may not reach it)."""
    n = len(samples) - 1
    h = n // 2
    if h < 1 or not (target > 0.0):
        return None
    (t0, w0), (_, wh), (t1, w1) = samples[0], samples[h], samples[-1]
    if not all(math.isfinite(x) for x in (t0, w0, wh, t1, w1)) or t1 <= t0:
        return None
    if w1 <= target:
        return 0.0
    r1, r2 = (w0 - wh) / h, (wh - w1) / (n - h)
    m1, m2 = 0.5 * (w0 + wh), 0.5 * (wh + w1)
    if r1 <= 0.0 or r2 <= 0.0 or m2 <= 0.0 or m1 <= m2:
        return None
    a = min(max(math.log(r1 / r2) / math.log(m1 / m2), 0.0), 2.0)
    c = r2 / m2 ** a
    if abs(1.0 - a) < 1e-6:
        steps = math.log(w1 / target) / c
    else:
        steps = (w1 ** (1.0 - a) - target ** (1.0 - a)) / (c * (1.0 - a))
    out = max(steps, 0.0) * (t1 - t0) / n
    return out if math.isfinite(out) else None


def duration(seconds: float) -> str:
    """``"17 s"``, ``"2 min 05 s"`` or ``"3 h 07 min"`` (rounded)."""
    if not math.isfinite(seconds):
        return "?"
    r = int(round(max(seconds, 0.0)))
    if r < 60:
        return f"{r} s"
    if r < 3600:
        return f"{r // 60} min {r % 60:02d} s"
    m = int(round(r / 60))
    return f"{m // 60} h {m % 60:02d} min"


class DryingEta:
    """The time-left estimate of one drying toward the water fraction ``target``.  ``start``
    when it begins, ``frame`` after every frame (from any thread), ``left`` for the estimate."""

    def __init__(self, target: float):
        self.target = float(target)
        self._lock = threading.Lock()
        self._start: tuple[float, float] | None = None
        self._seen: deque = deque(maxlen=ETA_WINDOW + 1)
        self._handed_over = False

    def start(self, now: float, progress: float) -> None:
        with self._lock:
            self._start = (now, float(progress))
            self._seen.clear()
            self._handed_over = False

    def stop(self) -> None:
        with self._lock:
            self._start = None
            self._seen.clear()

    def frame(self, now: float, water_fraction: float, on_path: bool) -> None:
        """A frame ended at ``now`` with ``water_fraction`` left; ``on_path``: its mechanics ran
        on the drying path's coarse mesh.  Only frames in which the water changed are steps of
        the fit (with ``osmosis.every`` k the water moves every k-th frame, and each step then
        costs k frames)."""
        with self._lock:
            if on_path:
                self._seen.clear()
                self._handed_over = True  # the own mesh takes over after the path's last frame
            elif not self._seen or water_fraction != self._seen[-1][1]:
                self._seen.append((now, float(water_fraction)))

    def left(self, now: float, progress: float) -> float | None:
        """Wall seconds still needed at ``now`` with ``progress`` of the work done; None before
        :meth:`start` or while too early to tell."""
        with self._lock:
            start, seen, handed = self._start, list(self._seen), self._handed_over
        if start is None:
            return None
        tail = handed or (bool(seen) and seen[0][1] < NO_PATH_FIT_BELOW)
        if tail and len(seen) > ETA_WINDOW // 2:
            out = time_left_from_decay(seen, self.target)
            if out is not None:  # counted from the last step, read later
                return max(out - (now - seen[-1][0]), 0.0)
        return time_left(now - start[0], start[1], progress)
