"""Aging sheets: a species dried to the end at its defaults, drawn top-down every K frames (the
colour's whole trajectory in one strip), with the within-leaf colour numbers of every stage.

    python tools/aging_sheets.py --out docs/aging maple oak aspen hornbeam grapevine

Writes OUT/<species>.png and OUT/<species>.json (per stage: frame, water left, median sRGB,
CIELAB hue and its spread, L* and its spread, the colour-class mix; the compare metrics'
definitions, leafsim.compare.metrics).  Only osmosis and colour run (the pigments follow the
water, not the shape), so the leaf lies flat and every stage shows the whole blade.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from leafsim.compare import metrics as C  # noqa: E402
from leafsim.compare.run import DRY_LEFT, _Leaf  # noqa: E402
from leafsim.config.species import get_species  # noqa: E402
from leafsim.sim.run import Run  # noqa: E402


def stage(leaf, state, w0: float, length_px: float) -> tuple[dict, np.ndarray]:
    rgb, mask = leaf.render(state, True)
    inner = cv2.erode(mask.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    lab = C._lab(rgb)[inner]
    spread = C.colour_spread(rgb, inner, length_px)
    z = np.exp(1j * np.arctan2(lab[:, 2], lab[:, 1]))[np.hypot(lab[:, 1], lab[:, 2]) >= 8]
    row = {"frame": state.frame, "water": round(leaf.model.water_fraction(state.particle_water), 3),
           "srgb_median": np.median(rgb[inner], axis=0).astype(int).tolist(),
           "hue_deg": round(float(np.degrees(np.angle(z.mean())) % 360.0), 1) if z.size else None,
           "L": round(float(lab[:, 0].mean()), 1), **spread,
           "classes": {n: round(float(v), 3) for n, v in zip(C.CLASSES, C.colour_classes(rgb, inner)) if v >= 0.01}}
    return row, rgb


def sheet(key: str, every: int, out: Path, seed: int) -> None:
    sp = get_species(key)
    leaf = _Leaf(sp, sp.params, seed, ["osmosis", "colour"])
    try:
        run = Run(leaf.model, simulator=leaf.sim, state=leaf.state0.copy(), name=key)
        w0 = float(leaf.model.particle_water0.sum())
        length_px = sp.length_m * leaf.frame.scale
        rows, tiles = [], []

        def take():
            row, rgb = stage(leaf, run.state, w0, length_px)
            rows.append(row)
            im = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
            s = 320 / im.shape[0]
            im = cv2.resize(im, (max(1, int(im.shape[1] * s)), 320), interpolation=cv2.INTER_AREA)
            cv2.putText(im, f"frame {row['frame']}  water {100 * row['water']:.0f} %", (6, 18), cv2.FONT_HERSHEY_SIMPLEX,
                        0.5, (0, 0, 0), 1, cv2.LINE_AA)
            tiles.append(im)

        take()
        for _ in run.frames(until=lambda st: leaf.model.water_fraction(st.particle_water) <= DRY_LEFT):
            if run.state.frame % every == 0:
                take()
        if rows[-1]["frame"] != run.state.frame:
            take()
    finally:
        leaf.release()
    strip = np.hstack(tiles)
    head = np.full((30, strip.shape[1], 3), 255, np.uint8)
    cv2.putText(head, f"{sp.name} ({sp.latin}), seed {seed}: every {every} frames until {100 * DRY_LEFT:.0f} % of the water "
                "is left (leafsim defaults; osmosis and colour)", (6, 21), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (0, 0, 0), 1,
                cv2.LINE_AA)
    cv2.imwrite(str(out / f"{key}.png"), np.vstack([head, strip]))
    (out / f"{key}.json").write_text(json.dumps({"species": key, "seed": seed, "every": every, "stages": rows}, indent=1) + "\n")
    for r in rows:
        print(key, r["frame"], r["water"], r["srgb_median"], r["hue_deg"], r["hue_sd_deg"], r["lightness_sd"], r["spots"],
              r["classes"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("species", nargs="+")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "aging")
    ap.add_argument("--every", type=int, default=250)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    for key in a.species:
        sheet(key, a.every, a.out, a.seed)


if __name__ == "__main__":
    main()
