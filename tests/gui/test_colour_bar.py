"""The heat map's colour bar labels its ticks so that no two read alike."""

import numpy as np

from leafsim.gui.panels.view import tick_labels


def test_ticks_of_a_narrow_range_are_told_apart():
    # a field spanning 99.6-100 % (chlorophyll early in drying) read "100" at all five ticks
    assert tick_labels(np.linspace(99.6, 100.0, 5)) == ["99.6", "99.7", "99.8", "99.9", "100"]
    narrow = tick_labels(np.linspace(99.99, 100.0, 5))
    assert len(set(narrow)) == 5 and all(len(t) <= 8 for t in narrow)
    assert tick_labels(np.linspace(0.0, 100.0, 5)) == ["0", "25", "50", "75", "100"]  # wide: as before
    assert tick_labels([5.0, 5.0]) == ["5", "5"]  # equal values stay short
