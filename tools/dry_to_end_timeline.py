"""How long the window's "Dry to end" takes, from the press to 2 % of the water left.

Runs ``leafsim gui ... --until dry`` (the button pressed as the window opens) with a hook on the
simulation worker and prints three times on stderr: when the drying starts (the window is up
and the leaf built), when the leaf is dry, and when the process exits; then, at every tenth of the
drying's wall time, the bar's progress and the time left it showed against the time that was
really left.  Needs a display: under
Xvfb, ``Xvfb :77 & DISPLAY=:77 python tools/dry_to_end_timeline.py --species maple``; any other
``leafsim gui`` option passes through (``--set``, ``--quality``, ``--screenshot F.png``).
"""

from __future__ import annotations

import atexit
import sys
import time

T0 = time.perf_counter()


def _hook() -> None:
    from leafsim.interactive import worker

    cls = worker.SimWorker
    after = cls._after_step
    first: list[float] = []
    seen: list[tuple[float, float, float | None]] = []  # (seconds since the press, progress, time left shown)

    def timed(self, ms, publish_now):
        if self._dry and not first:
            first.append(time.perf_counter())
            print(f"[dry to end] starts at {first[0] - T0:.2f} s (frame {self.run.state.frame})", file=sys.stderr)
        was = self.dry_done
        after(self, ms, publish_now)
        if self._dry and first and (not seen or time.perf_counter() - first[0] - seen[-1][0] >= 0.25):
            seen.append((time.perf_counter() - first[0], self.dry_progress(), self.dry_time_left()))
        if self.dry_done and not was and first:
            t = time.perf_counter()
            total = t - first[0]
            print(f"[dry to end] dry at {t - T0:.2f} s: {total:.2f} s of wall time from the press "
                  f"(frame {self.run.state.frame})", file=sys.stderr)
            for k in range(1, 10 if seen else 1):
                e, p, left = min(seen, key=lambda x: abs(x[0] - k * total / 10))
                shown = "—" if left is None else f"{left:5.1f} s"
                print(f"[dry to end] at {e:5.1f} s: bar {100 * p:3.0f} %, time left shown {shown}, "
                      f"really {total - e:5.1f} s", file=sys.stderr)

    cls._after_step = timed


def main(argv: list[str]) -> int:
    _hook()
    atexit.register(lambda: print(f"[dry to end] process ends at {time.perf_counter() - T0:.2f} s", file=sys.stderr))
    from leafsim.cli import main as cli

    return cli(["gui", "--until", "dry", *argv])


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
