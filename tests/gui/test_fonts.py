"""The bundled UI font covers every character of every declared label, unit and help text
(read from the TTF's own character map by leafsim.gui.fonts.cmap, no font library needed)."""

from __future__ import annotations

import struct

import pytest

from leafsim.gui.fonts import FONT_PATH, cmap, missing_glyphs, ui_strings


def test_font_and_licence_are_bundled():
    assert FONT_PATH.is_file() and FONT_PATH.stat().st_size > 100_000
    lic = (FONT_PATH.parent / "LICENSE-DejaVu.txt").read_text()
    assert "Bitstream" in lic and "public domain" in lic


def test_every_declared_string_has_glyphs():
    covered = cmap(FONT_PATH)
    strings = ui_strings()
    assert len(strings) > 400
    text = "".join(strings)
    # the declaration uses the characters the old default font lacked (l⁰, water₀, ≲, ≫, τ̄)
    for ch in ("\u2070", "\u2080", "\u2272", "\u226b", "\u0304", "κ", "σ", "Δ", "×", "−"):
        assert ch in text, ch
    assert missing_glyphs(strings, covered) == {}


def test_cmap_parser_reads_real_coverage():
    covered = cmap(FONT_PATH)
    assert {ord("A"), ord("z"), 0x3C4, 0x2272, 0x304, 0x2080} <= covered
    assert 0x4E00 not in covered and 0xFFFF not in covered  # no CJK in DejaVu Sans


def test_missing_glyphs_reports_the_first_string():
    assert missing_glyphs(["ab", "a≲", "x≲y"], {ord("a"), ord("b"), ord("x"), ord("y")}) == {"≲": "a≲"}


def test_cmap_rejects_a_font_without_cmap(tmp_path):
    p = tmp_path / "bad.ttf"
    p.write_bytes(struct.pack(">IHHHH", 0x10000, 1, 16, 0, 0) + b"glyf" + struct.pack(">III", 0, 28, 0))
    with pytest.raises(ValueError, match="no cmap"):
        cmap(p)
