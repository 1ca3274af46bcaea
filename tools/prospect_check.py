"""Our pigment reflectance against PROSPECT-D along a senescence trajectory.

PROSPECT-D (Féret et al. 2017, Remote Sens. Environ. 193:204) is the standard radiative-transfer
model of a leaf's reflectance from its pigments, water and dry matter.  This tool takes a leaf
losing its chlorophyll (a fraction f of a summer content of 45 µg/cm², carotenoids held at
10 µg/cm², or lowered to 7), computes PROSPECT-D's reflectance spectrum, turns it into a colour
under a 6504 K illuminant (the CIE 1931 colour matching functions as the analytic fit of Wyman,
Sloan & Shirley 2013, JCGT 2(2)), and prints it beside our Beer–Lambert colour
(:func:`leafsim.appearance.reflectance.pigments_to_rgb`'s arithmetic) of a species' palette at
the same fraction f of its summer chlorophyll, carotenoids at 1 (or 0.7), no browning.  Both
are classed as ``leafsim compare`` classes them (:func:`leafsim.compare.metrics.classify_lab`).

Needs the ``prosail`` package, which is not a leafsim dependency::

    .venv/bin/pip install prosail
    .venv/bin/python tools/prospect_check.py [--species hornbeam] [--markdown]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from leafsim.appearance.reflectance import ABSORPTION, BASE_REFLECTANCE, SURFACE_REFLECTANCE  # noqa: E402
from leafsim.base.errors import LeafsimError  # noqa: E402
from leafsim.compare.metrics import CLASSES, _lab, classify_lab  # noqa: E402
from leafsim.config.species import get_species  # noqa: E402

#: summer chlorophyll a+b [µg/cm²] the fractions are of (a temperate broadleaf's)
CAB_SUMMER = 45.0
#: PROSPECT-D's leaf structure, water [cm] and dry matter [g/cm²] (a thin broadleaf)
N_STRUCT, CW, CM = 1.5, 0.010, 0.006
FRACTIONS = (1.0, 2 / 3, 0.5, 0.42, 1 / 3, 0.27, 0.2, 0.133, 0.089, 0.044)


def cmf(lam: np.ndarray) -> np.ndarray:
    """(n, 3) CIE 1931 2° colour matching functions, Wyman, Sloan & Shirley's multi-lobe fit."""
    def g(x, mu, s1, s2):
        t = (x - mu) * np.where(x < mu, s1, s2)
        return np.exp(-0.5 * t * t)
    x = 0.362 * g(lam, 442.0, 0.0624, 0.0374) + 1.056 * g(lam, 599.8, 0.0264, 0.0323) - 0.065 * g(lam, 501.1, 0.0490, 0.0382)
    y = 0.821 * g(lam, 568.8, 0.0213, 0.0247) + 0.286 * g(lam, 530.9, 0.0613, 0.0322)
    z = 1.217 * g(lam, 437.0, 0.0845, 0.0278) + 0.681 * g(lam, 459.0, 0.0385, 0.0725)
    return np.stack([x, y, z], 1)


def planck(lam_nm: np.ndarray, T: float = 6504.0) -> np.ndarray:
    lam = lam_nm * 1e-9
    return 1.0 / (lam ** 5 * (np.exp(1.4388e-2 / (lam * T)) - 1.0))


XYZ_TO_LINEAR_SRGB = np.array([[3.2406, -1.5372, -0.4986], [-0.9689, 1.8758, 0.0415], [0.0557, -0.2040, 1.0570]])


def spectrum_to_linear_srgb(lam: np.ndarray, refl: np.ndarray) -> np.ndarray:
    """Linear sRGB of a reflectance spectrum (sampled at ``lam`` nm, 400–700: the visible band the
    colour is integrated over) under a 6504 K blackbody (white normalised to Y 1)."""
    S, C = planck(lam), cmf(lam)
    xyz = (S[:, None] * C * refl[:, None]).sum(0) / (S * C[:, 1]).sum()
    white = (S[:, None] * C).sum(0) / (S * C[:, 1]).sum()
    # the blackbody's white scaled onto D65's in XYZ (a "wrong von Kries"; Bradford moves no
    # colour here by more than one 8-bit level), so that a grey reflectance is grey in sRGB
    d65 = np.array([0.95047, 1.0, 1.08883])
    return XYZ_TO_LINEAR_SRGB @ (xyz * d65 / white)


def to_srgb8(lin: np.ndarray) -> np.ndarray:
    lin = np.clip(lin, 0.0, 1.0)
    return np.round(255 * np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)).astype(np.uint8)


def describe(rgb8: np.ndarray) -> tuple:
    """(sRGB, L*, C*, hue°, class) of one 8-bit sRGB colour, with compare's CIELAB (the float
    conversion of ``leafsim.compare.metrics._lab``) and classes."""
    lab = _lab(np.asarray(rgb8, np.uint8).reshape(1, 1, 3))[0, 0]
    L, a, b = float(lab[0]), float(lab[1]), float(lab[2])
    cls = CLASSES[int(classify_lab(lab.reshape(1, 3))[0])]
    return tuple(int(v) for v in rgb8), L, float(np.hypot(a, b)), float(np.degrees(np.arctan2(b, a)) % 360), cls


def ours(sp, f: float, k: float) -> np.ndarray:
    """Our reflectance of the species' palette at chlorophyll f and carotenoids k (of summer)."""
    p = sp.params
    x = float(p["colour.chlorophyll"]) * f * ABSORPTION[0] + float(p["colour.carotenoid"]) * k * ABSORPTION[1]
    return to_srgb8(SURFACE_REFLECTANCE + BASE_REFLECTANCE * np.exp(-x))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--species", default="hornbeam")
    ap.add_argument("--markdown", action="store_true", help="a markdown table")
    args = ap.parse_args()
    try:
        import prosail
    except ImportError:
        sys.exit("prospect_check: needs the prosail package (pip install prosail; not a leafsim dependency)")
    try:
        sp = get_species(args.species)
    except LeafsimError as e:
        sys.exit(f"prospect_check: {e}")
    rows = []
    for car, k in ((10.0, 1.0), (7.0, 0.7)):
        for f in FRACTIONS:
            lam, refl, _ = prosail.run_prospect(N_STRUCT, CAB_SUMMER * f, car, 0.0, CW, CM, ant=0.0, prospect_version="D")
            vis = (lam >= 400) & (lam <= 700)
            a = describe(to_srgb8(spectrum_to_linear_srgb(lam[vis].astype(float), refl[vis])))
            b = describe(ours(sp, f, k))
            rows.append((f, car, k, a, b))
    if args.markdown:
        print(f"| chlorophyll left | PROSPECT-D (Cab, Car µg/cm²): sRGB, L*, C*, hue, class | ours ({sp.key}, K): sRGB, L*, C*, hue, class |")
        print("|---|---|---|")
        for f, car, k, a, b in rows:
            print(f"| {f:.0%} | {CAB_SUMMER * f:.1f}, {car:g}: {a[0]}, {a[1]:.1f}, {a[2]:.1f}, {a[3]:.1f}°, {a[4]} "
                  f"| {k:g}: {b[0]}, {b[1]:.1f}, {b[2]:.1f}, {b[3]:.1f}°, {b[4]} |")
        return
    for f, car, k, a, b in rows:
        print(f"f {f:5.3f}  PROSPECT-D Cab {CAB_SUMMER * f:5.1f} Car {car:4.1f}: {a[0]} L* {a[1]:5.1f} C* {a[2]:5.1f} "
              f"hue {a[3]:6.1f} {a[4]:7s} | ours K {k}: {b[0]} L* {b[1]:5.1f} C* {b[2]:5.1f} hue {b[3]:6.1f} {b[4]}")


if __name__ == "__main__":
    main()
