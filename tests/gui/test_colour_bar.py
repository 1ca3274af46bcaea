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


def test_the_label_wraps_between_words_to_the_card():
    """The label is broken between words into lines of at most the card's width (on one line
    "lamina's excess length (render.crinkle)" made a 265 px card over maple's right lobe)."""
    from leafsim.gui.layout import HEAT_UNITS
    from leafsim.gui.panels.view import LEGEND_TEXT_W, wrap_words

    px = lambda t: 7.0 * len(t)  # noqa: E731  (a monospace measure, 7 px a character)
    for label, _, _ in HEAT_UNITS.values():
        lines = wrap_words(label, LEGEND_TEXT_W, px)
        assert " ".join(lines) == " ".join(label.split())
        assert all(px(t) <= LEGEND_TEXT_W or " " not in t for t in lines), lines
    assert wrap_words("lamina's excess length (render.crinkle)", 120.0, px) == ["lamina's excess", "length", "(render.crinkle)"]
    assert wrap_words("", 120.0, px) == [""] and wrap_words("x" * 30, 120.0, px) == ["x" * 30]
