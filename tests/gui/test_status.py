"""The status bar's messages (no window): topics, expiry and order."""

from __future__ import annotations

from leafsim.gui import status as st


def test_an_older_note_never_outlives_a_newer_one(monkeypatch):
    """"defaults restored" (30 s) then "loaded preset" (12 s): once the newer note is gone the
    older one must not come back as the newest shown (it did, for the 18 s after); a note held by
    a condition and an error stay as they were."""
    now = [100.0]
    monkeypatch.setattr(st.time, "monotonic", lambda: now[0])
    s = st.Status()
    s.info("species", "Norway maple defaults restored (...)", seconds=30.0)
    s.info("record", "recording take_001", holds=lambda: True)
    s.error("params", "parameter 'x' = nan: expected a finite value")
    now[0] += 1.0
    s.info("preset", "loaded p.json")
    assert [m.topic for m in s.messages()] == ["params", "preset", "record", "species"]
    now[0] += 11.5
    assert [m.topic for m in s.messages()] == ["params", "preset", "record", "species"]
    now[0] += 1.0  # past the newer note's 12 s
    assert [m.topic for m in s.messages()] == ["params", "record"]
    s.clear("params", "info")  # (a level that does not match leaves it)
    assert s.error_text.startswith("parameter 'x'")
    s.clear("params", "error")
    assert [m.topic for m in s.messages()] == ["record"]
