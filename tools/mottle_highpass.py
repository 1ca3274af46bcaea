"""The colour below the mesh: how much chroma and lightness a photo and the model carry at
sub-millimetre scale, for choosing ``colour.mottle`` (docs/method.md §7, "Below the mesh").

    python tools/mottle_highpass.py --species hornbeam,aspen_senescent --mottle 0,0.6,1

For every species and mottle amount it runs ``leafsim compare`` (seed 0) and measures, on the
senescent row's photo and model pictures, the RMS over the blade of CIELAB L* and of (a*, b*)
minus their Gaussian blur over σ = 0.3 and 0.7 mm (the blade mask eroded by 3σ, the blur
normalised by the blurred mask).  Prints a markdown table.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from leafsim.compare import metrics as C  # noqa: E402

SIGMAS_MM = (0.3, 0.7)


def highpass(rgb: np.ndarray, mask: np.ndarray, sigma_px: float) -> tuple[float, float]:
    """(RMS of L* minus its blur, RMS of (a*, b*) minus theirs) over the eroded blade."""
    lab = C._lab(rgb)
    m = np.asarray(mask, bool)
    k = 2 * int(3 * sigma_px) + 1
    inner = cv2.erode(m.astype(np.uint8), np.ones((k, k), np.uint8)) > 0
    w = cv2.GaussianBlur(m.astype(np.float64), (0, 0), sigma_px)
    res = []
    for c in range(3):
        ch = lab[..., c].astype(np.float64) * m
        blur = cv2.GaussianBlur(ch, (0, 0), sigma_px) / np.maximum(w, 1e-9)
        res.append((lab[..., c] - blur)[inner])
    return float(res[0].std()), float(np.sqrt(res[1].var() + res[2].var()))


def measure(species: str, mottle: float) -> dict:
    """Run the comparison; returns {"photo": ..., "model": ..., "px_per_mm": ...} for its senescent row."""
    import contextlib
    import io
    import json

    from leafsim.cli import main

    seen: list = []
    spread = C.colour_spread

    def spy(rgb, mask, length_px):
        seen.append((np.array(rgb), np.array(mask, bool)))
        return spread(rgb, mask, length_px)

    C.colour_spread = spy
    try:
        out = ROOT / "build" / f"mottle_{species}_{mottle:g}.png"
        out.parent.mkdir(exist_ok=True)
        text = io.StringIO()
        with contextlib.redirect_stdout(text):
            code = main(["compare", "--species", species, "--seed", "0", "--out", str(out), "--json",
                         "--set", f"colour.mottle={mottle:g}"])
    finally:
        C.colour_spread = spread
    if code:
        raise SystemExit(f"mottle_highpass: leafsim compare --species {species} failed ({code})")
    # calls: young row (photo, model), senescent row (photo, model); the photo's is computed once
    # per reference, so the last call is the senescent model and the photo is the one before it
    photo, model = seen[-2], seen[-1]
    return {"photo": photo, "model": model, "px_per_mm": json.loads(text.getvalue())["frame_px_per_m"] / 1000.0}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--species", default="hornbeam,aspen_senescent")
    ap.add_argument("--mottle", default="0,0.6,1")
    args = ap.parse_args()
    cols = " | ".join(f"L* / chroma at {s} mm" for s in SIGMAS_MM)
    print(f"| species | picture | {cols} |")
    print("|---|---|" + "---|" * len(SIGMAS_MM))
    for key in args.species.split(","):
        photo_row = None
        for a in (float(x) for x in args.mottle.split(",")):
            r = measure(key, a)
            rgb, mask = r["model"]
            px_per_mm = r["px_per_mm"]

            def cells(rgb, mask):
                return " | ".join("%.2f / %.2f" % highpass(rgb, mask, s * px_per_mm) for s in SIGMAS_MM)

            if photo_row is None:
                photo_row = cells(*r["photo"])
                print(f"| {key} | photo | {photo_row} |")
            print(f"| {key} | model, colour.mottle {a:g} | {cells(rgb, mask)} |")


if __name__ == "__main__":
    main()
