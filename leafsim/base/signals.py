"""Ending a command by a signal: SIGINT or SIGTERM becomes :class:`Interrupted` (one line, exit
128 + signal, never a traceback), and :class:`DeferredSignals` lets a frame loop finish the
frame it is in before it stops."""

from __future__ import annotations

import signal
import threading


class Interrupted(BaseException):
    """SIGINT or SIGTERM ended a command: the CLI prints one line and exits with 128 + signal.
    A BaseException (like KeyboardInterrupt), so no ``except Exception`` swallows it."""

    def __init__(self, signum: int, message: str = ""):
        super().__init__(signum, message)
        self.signum, self.message = signum, message


def raise_interrupted(signum, frame):
    """A signal handler: end the command with :class:`Interrupted`."""
    raise Interrupted(signum)


def main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


class DeferredSignals:
    """Inside a frame loop, SIGINT/SIGTERM only set ``signum``: the loop finishes the frame it
    is in, saves a checkpoint and stops, so the state on disk is always a whole frame.  A
    second signal ends at once."""

    def __init__(self):
        self.signum = None

    def _handler(self, signum, frame):
        if self.signum is not None:
            raise Interrupted(signum)
        self.signum = signum

    def __enter__(self):
        self._old = {s: signal.signal(s, self._handler) for s in (signal.SIGINT, signal.SIGTERM)} if main_thread() else {}
        return self

    def __exit__(self, *exc):
        for s, h in self._old.items():
            signal.signal(s, h)
