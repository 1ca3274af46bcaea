"""Status messages for the fixed status bar (no imgui here: the app draws them).

Each message belongs to a *topic* ("build", "sim", "export", "preset", "record", ...): a new
message replaces the topic's old one, so a failed save replaces "saved ..." and a finished
take replaces "recording ...".  A message may carry a ``holds()`` condition (dropped as soon
as it is false: "recording" while recording, "diverged" until Reset) and information expires
after ``INFO_SECONDS`` (never after a newer note: notes go in the order they came); errors stay
until dismissed, replaced by their topic's next message, or cleared when what they were about
succeeds (a parameter accepted, the export folder usable).
Every text is kept as one line the window can draw (:func:`one_line`): a multi-line reason
(numba's errors) would be cut by the bar's fixed height, and a path that is not UTF-8 would
stop imgui from drawing the bar at all.
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass, field
from typing import Callable

INFO_SECONDS = 12.0


def printable(text) -> str:
    """``text`` as imgui can draw it: bytes of a path that are not UTF-8 (kept by Python as
    lone surrogates, e.g. from ``Path.cwd()`` in such a folder) shown as ``\\xNN``."""
    text = str(text)
    if not any("\ud800" <= c <= "\udfff" for c in text):
        return text
    try:
        return text.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
    except UnicodeEncodeError:  # a surrogate that no undecodable byte gives
        return text.encode("utf-8", "backslashreplace").decode("utf-8")


def one_line(text) -> str:
    """:func:`printable` ``text`` with its line breaks (and the blanks around them) made one space."""
    return re.sub(r"\s*[\r\n]+\s*", " ", printable(text)).strip()


@dataclass
class Message:
    topic: str
    text: str
    level: str = "info"          # "info" or "error"
    path: str | None = None      # a file or folder the message is about (copy button)
    holds: Callable[[], bool] | None = None
    expires: float | None = None
    t: float = field(default_factory=time.monotonic)


class Status:
    """The app's current messages by topic."""

    def __init__(self):
        self._msgs: dict[str, Message] = {}

    def info(self, topic: str, text: str, path=None, holds=None, seconds: float | None = INFO_SECONDS) -> None:
        exp = None if (seconds is None or holds is not None) else time.monotonic() + seconds
        if exp is not None:  # an older note never outlives a newer one (it came back as the newest shown:
            for m in self._msgs.values():  # "defaults restored" after a later "loaded preset")
                if m.level == "info" and m.holds is None and (m.expires is None or m.expires > exp):
                    m.expires = exp
        self._msgs[topic] = Message(topic, one_line(text), "info", None if path is None else str(path), holds, exp)

    def error(self, topic: str, text: str, path=None, holds=None) -> None:
        self._msgs[topic] = Message(topic, one_line(text), "error", None if path is None else str(path), holds)

    def clear(self, topic: str, level: str | None = None) -> None:
        m = self._msgs.get(topic)
        if m is not None and (level is None or m.level == level):
            del self._msgs[topic]

    def get(self, topic: str) -> Message | None:
        self.prune()
        return self._msgs.get(topic)

    def prune(self) -> None:
        now = time.monotonic()
        for k, m in list(self._msgs.items()):
            try:
                gone = (m.expires is not None and now > m.expires) or (m.holds is not None and not m.holds())
            except Exception:
                gone = True
            if gone:
                del self._msgs[k]

    def messages(self) -> list[Message]:
        """Current messages, errors first, newest first."""
        self.prune()
        return sorted(self._msgs.values(), key=lambda m: (m.level != "error", -m.t))

    @property
    def error_text(self) -> str | None:
        """The newest error's text (None when there is none)."""
        errs = [m for m in self.messages() if m.level == "error"]
        return errs[0].text if errs else None
