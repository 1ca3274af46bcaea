"""How much of a photo's within-leaf colour spread survives when its colour lives on the mesh.

    python tools/photo_blur_spread.py grapevine oak aspen

For each photo species: the hue and L* spread (``leafsim.compare.metrics.colour_spread``) of
the species texture inside the blade, at full size; then with its colour blurred over a
quarter, a half and a whole mesh spacing (``mesh.spacing`` × L, the default mesh) while every
pixel keeps its own luminance — what the "detail" albedo drew before it laid the photo's own
chromaticity on living tissue (the young colour is the photo blurred over half a spacing).
"""

from __future__ import annotations

import argparse

import cv2
import numpy as np

from leafsim.appearance.photo import species_photo_rgba
from leafsim.compare.metrics import colour_spread
from leafsim.config.species import get_species

W = np.array([0.2126, 0.7152, 0.0722])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("species", nargs="+")
    args = ap.parse_args()
    print("| species | blur (× spacing) | σ px | hue spread ° | L* spread |")
    print("|---|---|---|---|---|")
    for key in args.species:
        sp = get_species(key)
        im = species_photo_rgba(sp)
        a = im[..., 3] >= 128
        ys, xs = np.nonzero(a)
        length_px = float(max(np.ptp(ys), np.ptp(xs)))
        lin = (im[..., :3] / 255.0) ** 2.2
        for f in (0.0, 0.25, 0.5, 1.0):
            s = f * float(sp.params["mesh.spacing"]) * length_px
            if s > 0:
                num = cv2.GaussianBlur(lin * a[..., None], (0, 0), s)
                den = cv2.GaussianBlur(a.astype(float), (0, 0), s)
                bl = num / np.maximum(den[..., None], 1e-6)
                out = bl * ((lin @ W) / np.maximum(bl @ W, 1e-6))[..., None]
            else:
                out = lin
            rgb = np.clip(out ** (1 / 2.2) * 255 + 0.5, 0, 255).astype(np.uint8)
            c = colour_spread(rgb, a, length_px)
            print(f"| {key} | {f:g} | {s:.1f} | {c['hue_sd_deg']} | {c['lightness_sd']} |")


if __name__ == "__main__":
    main()
