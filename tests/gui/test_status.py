"""The status bar's messages and the panels' short texts (no window): topics, expiry, order, masses."""

from __future__ import annotations

import numpy as np

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


def test_the_stats_panel_s_masses_stay_short():
    """The water line's masses in 3 digits, in mg below 0.1 g ("blade 0.0001238 g (0.0 %), stalk
    0.00198 g" ran past the panel's edge, its unit cut off)."""
    from leafsim.gui.panels.stats import grams

    assert [grams(x) for x in (1.772, 0.182, 0.0001238, 0.00198, 0.0)] == ["1.77 g", "0.182 g", "0.124 mg", "1.98 mg", "0 g"]
    assert all(len(grams(x)) <= 9 for x in np.geomspace(1e-7, 99.0, 200))  # (down to 0.1 µg)
