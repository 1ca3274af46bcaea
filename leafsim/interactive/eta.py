"""How long a drying still needs, in wall seconds: the window's "Dry to end" and the CLI's
progress bar (``leafsim run --until dry``) say it.

The work-weighted progress (:meth:`Simulator.drying_progress`) tracks the wall time within
0.13 on maple but runs ahead once the leaf's own mesh carries the mechanics: the drying slows
there, so every unit of water costs more frames.  So :class:`DryingEta` extrapolates the pace
since the start while the drying path carries the mechanics, and after the hand-over the
water's decay over the own mesh's last frames, each of which costs the same
(:func:`time_left_from_decay`).
"""

from __future__ import annotations

import math
import threading
from collections import deque

#: "Dry to end" estimates its time left only after this long [s] and this share of its work
ETA_AFTER_S, ETA_AFTER_WORK = 2.0, 0.03
#: frames of the recent window the water's decay is measured over (on the leaf's own mesh)
ETA_WINDOW = 100


def time_left(elapsed: float, p0: float, p: float) -> float | None:
    """Seconds still needed to reach progress 1 at the pace of the last ``elapsed`` seconds,
    in which progress went from ``p0`` to ``p`` (the share of the drying's work,
    :meth:`Simulator.drying_progress`); None before ``ETA_AFTER_S`` and ``ETA_AFTER_WORK`` of
    the work."""
    done = p - p0
    if elapsed < ETA_AFTER_S or done < ETA_AFTER_WORK:
        return None
    return max(elapsed * (1.0 - p) / done, 0.0)


def time_left_from_decay(samples: list[tuple[float, float]], target: float) -> float | None:
    """Seconds still needed for the water fraction to fall to ``target``, from ``samples``
    (clock, water fraction) of consecutive frames of equal cost: the water's loss per frame
    is fitted as c wᵃ through the window's two halves (a = 1: exponential decay, a = 0: a
    constant rate; maple's own-mesh phase runs at a ≈ 0.6, oak's near 0) and integrated down
    to ``target``; the frames left cost the window's seconds per frame.  Offline on the whole
    drying curves from 100 frames after the hand-over on, the frames left are within 10 % (maple)
    and 17 % (oak); an exponential fit was up to 1.4× (maple) and 2.8× (oak) long.  None unless the
    water falls in both halves over a positive time."""
    n = len(samples) - 1
    h = n // 2
    if h < 1:
        return None
    (t0, w0), (_, wh), (t1, w1) = samples[0], samples[h], samples[-1]
    if t1 <= t0:
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
        frames = math.log(w1 / target) / c
    else:
        frames = (w1 ** (1.0 - a) - target ** (1.0 - a)) / (c * (1.0 - a))
    return max(frames, 0.0) * (t1 - t0) / n


def duration(seconds: float) -> str:
    """``"17 s"`` or ``"2 min 05 s"`` (rounded to the second)."""
    r = int(round(seconds))
    return f"{r} s" if r < 60 else f"{r // 60} min {r % 60:02d} s"


class DryingEta:
    """The time-left estimate of one drying toward the water fraction ``target``.  ``start``
    when it begins, ``frame`` after every frame (from any thread), ``left`` for the estimate."""

    def __init__(self, target: float):
        self.target = float(target)
        self._lock = threading.Lock()
        self._start: tuple[float, float] | None = None
        self._seen: deque = deque(maxlen=ETA_WINDOW + 1)

    def start(self, now: float, progress: float) -> None:
        with self._lock:
            self._start = (now, float(progress))
            self._seen.clear()

    def stop(self) -> None:
        with self._lock:
            self._start = None
            self._seen.clear()

    def frame(self, now: float, water_fraction: float, on_path: bool) -> None:
        """A frame ended at ``now`` with ``water_fraction`` left; ``on_path``: its mechanics ran
        on the drying path's coarse mesh (such frames are not the steady own-mesh ones)."""
        with self._lock:
            if on_path:
                self._seen.clear()
            else:
                self._seen.append((now, float(water_fraction)))

    def left(self, now: float, progress: float) -> float | None:
        """Wall seconds still needed at ``now`` with ``progress`` of the work done; None before
        :meth:`start` or while too early to tell."""
        with self._lock:
            start, seen = self._start, list(self._seen)
        if start is None:
            return None
        if len(seen) > ETA_WINDOW // 2:
            out = time_left_from_decay(seen, self.target)
            if out is not None:
                return out
        return time_left(now - start[0], start[1], progress)
