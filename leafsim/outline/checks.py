"""Is the traced object a whole leaf?  Checks that refuse or warn before a wrong outline is
used as one: a leaf cut by the image border (the frame's straight edge would become leaf
margin), a region that fills the frame (the background was traced: a brightness gradient, a
screenshot), a rectangle, a leaf too few pixels long to trace, a flat single colour with no
texture at all.

:func:`leafness` measures; :func:`problems` turns the measures into one-line reasons, each
``("refuse" | "warn", text)``.
"""

from __future__ import annotations

import cv2
import numpy as np

#: a side of the image counts as cutting the leaf when the leaf covers more than this share of it
CUT_SIDE = 0.005
#: a traced region covering more than this share of the image is the background, not a leaf
MAX_AREA_FRACTION = 0.85
#: area / area of the smallest enclosing rectangle: an ellipse has 0.785, a leaf less; a
#: rectangle 1
MAX_RECTANGULARITY = 0.95
#: a leaf's lightness varies (veins, shading); a flat colour has (almost) none [CIELAB L, 0–255]
MIN_TEXTURE = 1.5
#: a leaf shorter than this [px] is too few pixels to place its base and apex or trace its
#: veins: a 30 × 40 px copy of a test leaf was traced upside down, with a zigzag midrib
MIN_LEAF_PX = 100


def leafness(traced, img: np.ndarray | None = None) -> dict:
    """The measures the checks use, of a :class:`~leafsim.outline.trace.TracedOutline` (its
    mask and contour at the working size): sides the leaf is cut by, the share of the image it
    fills, its rectangularity and (with the working image) its lightness texture inside."""
    mask = traced.mask > 0
    area = float(mask.sum())
    h, w = mask.shape[:2]
    cnt = traced.contour_px.astype(np.float32)
    (_, _), (rw, rh), _ = cv2.minAreaRect(cnt)
    poly_area = abs(float(cv2.contourArea(cnt)))
    out = {"cut_by": sorted(s for s, f in traced.border_sides.items() if f > CUT_SIDE),
           "area_fraction": area / float(h * w),
           "rectangularity": poly_area / max(float(rw * rh), 1e-9),
           "size_px": float(max(rw, rh)),  # at the working size: the caller scales it to the photo's
           "base_guessed": getattr(traced, "base_method", "") in ("shape", "veins")}
    if img is not None and img.shape[:2] == mask.shape and area > 0:
        lab = cv2.cvtColor(np.ascontiguousarray(img[:, :, :3]), cv2.COLOR_BGR2LAB)
        inner = cv2.erode(mask.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
        out["texture"] = float(lab[..., 0][inner].std()) if inner.any() else 0.0
    return out


def problems(m: dict) -> list[tuple[str, str]]:
    """(level, reason) for each check the measures ``m`` fail."""
    out = []
    if m["area_fraction"] > MAX_AREA_FRACTION:
        out.append(("refuse", f"the traced region fills {100 * m['area_fraction']:.0f} % of the image: the background "
                              "was traced, not a leaf (an uneven background or no leaf in the photo)"))
    if m["cut_by"]:
        out.append(("refuse", f"the leaf is cut by the image's {' and '.join(m['cut_by'])} border"
                              f"{'s' if len(m['cut_by']) > 1 else ''}: the frame's straight edge would become leaf margin "
                              "(photograph the whole leaf with a margin of background)"))
    if m.get("size_px", MIN_LEAF_PX) < MIN_LEAF_PX:
        out.append(("refuse", f"the leaf is only {m['size_px']:.0f} px long in the photo: expected at least {MIN_LEAF_PX} px "
                              "to place its base and apex and trace its veins (use a larger photo)"))
    if m["rectangularity"] > MAX_RECTANGULARITY:
        out.append(("refuse", f"the traced shape is a rectangle (it fills {100 * m['rectangularity']:.0f} % of its "
                              "bounding box), not a leaf"))
    if m.get("base_guessed"):  # an obovate leaf (oak) is blunter at its tip: upside down, without a word
        out.append(("warn", "no stalk was found, so the base was guessed from the leaf's shape and the direction of "
                            "its side veins and may be its tip: check the outline picture (leafsim outline: base red, "
                            "apex green) and give base_px and apex_px in the species entry if they are swapped"))
    if m.get("texture") is not None and m["texture"] < MIN_TEXTURE:
        out.append(("warn", f"the traced region is one flat colour (lightness varies by {m['texture']:.2g}): "
                            "no veins or shading, perhaps not a photographed leaf"))
    return out
