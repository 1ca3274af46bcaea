"""The bundled UI font and which characters it covers.

The window uses DejaVu Sans (``leafsim/gui/fonts/DejaVuSans.ttf``, Bitstream Vera licence with
public-domain DejaVu changes: ``fonts/LICENSE-DejaVu.txt``), which covers every character our
labels, units and help texts use (Greek, sub/superscripts, ≲ ≫ ≈, the combining macron of
τ̄).  :func:`cmap` reads a TrueType file's character map with a small parser (formats 4 and
12), so the coverage test needs no font library; this module imports no imgui.
"""

from __future__ import annotations

import struct
from pathlib import Path

from leafsim.base.resources import font_dir

FONT_PATH = font_dir() / "DejaVuSans.ttf"
FONT_SIZE = 15.0


def _format4(data: bytes, off: int) -> set[int]:
    seg2 = struct.unpack_from(">H", data, off + 6)[0]
    n = seg2 // 2
    ends = struct.unpack_from(f">{n}H", data, off + 14)
    starts = struct.unpack_from(f">{n}H", data, off + 16 + seg2)
    deltas = struct.unpack_from(f">{n}h", data, off + 16 + 2 * seg2)
    ro_pos = off + 16 + 3 * seg2
    ranges = struct.unpack_from(f">{n}H", data, ro_pos)
    out: set[int] = set()
    for k in range(n):
        for c in range(starts[k], ends[k] + 1):
            if c == 0xFFFF:
                continue
            if ranges[k] == 0:
                g = (c + deltas[k]) & 0xFFFF
            else:
                at = ro_pos + 2 * k + ranges[k] + 2 * (c - starts[k])
                g = struct.unpack_from(">H", data, at)[0]
                g = (g + deltas[k]) & 0xFFFF if g else 0
            if g:
                out.add(c)
    return out


def _format12(data: bytes, off: int) -> set[int]:
    ngroups = struct.unpack_from(">I", data, off + 12)[0]
    out: set[int] = set()
    for k in range(ngroups):
        start, end, glyph = struct.unpack_from(">III", data, off + 16 + 12 * k)
        out.update(c for c in range(start, end + 1) if glyph + (c - start))
    return out


def cmap(path=FONT_PATH) -> set[int]:
    """Code points that map to a real glyph (not .notdef) in a TrueType/OpenType font."""
    data = Path(path).read_bytes()
    ntables = struct.unpack_from(">H", data, 4)[0]
    tables = {data[12 + 16 * i: 16 + 16 * i].decode("latin-1"): struct.unpack_from(">II", data, 20 + 16 * i)
              for i in range(ntables)}
    if "cmap" not in tables:
        raise ValueError(f"{path}: no cmap table")
    base = tables["cmap"][0]
    nsub = struct.unpack_from(">H", data, base + 2)[0]
    out: set[int] = set()
    for i in range(nsub):
        platform, encoding, sub = struct.unpack_from(">HHI", data, base + 4 + 8 * i)
        if (platform, encoding) not in ((3, 1), (3, 10), (0, 3), (0, 4)):
            continue  # Unicode subtables only
        fmt = struct.unpack_from(">H", data, base + sub)[0]
        if fmt == 4:
            out |= _format4(data, base + sub)
        elif fmt == 12:
            out |= _format12(data, base + sub)
    return out


def ui_strings() -> list[str]:
    """Every declared label, unit, help and range text the panels show (from PARAMS)."""
    from leafsim.config.params import PARAMS

    out = []
    for p in PARAMS.values():
        out += [p.name, p.unit or "", p.help or "", p.describe(), *p.choices]
    return out


def missing_glyphs(strings, covered: set[int]) -> dict[str, str]:
    """{character: first string using it} for characters the font does not cover."""
    out: dict[str, str] = {}
    for s in strings:
        for ch in s:
            if ord(ch) >= 0x20 and ord(ch) not in covered and ch not in out:
                out[ch] = s
    return out


def load_ui_font():
    """Load the bundled font as imgui's default (a hello_imgui ``load_additional_fonts``
    callback).  ImGui ≥ 1.92 rasterises glyphs on demand, so no glyph ranges are needed."""
    from imgui_bundle import hello_imgui, imgui

    params = hello_imgui.FontLoadingParams(inside_assets=False)
    font = hello_imgui.load_font(str(FONT_PATH), FONT_SIZE, params)
    imgui.get_io().font_default = font
    return font
