"""A photo's background showing through the blade where the tracer keeps no hole (the wedge where
a closed sinus narrows between overlapping lobes) is taken out of the texture; tissue is not."""

from __future__ import annotations

import cv2
import numpy as np

from helpers.leafimg import PAPER, photo
from leafsim.appearance.photo import background_specks, load_photo_rgba
from leafsim.appearance.texture import clean_texture
from leafsim.config.params import ParamSet
from leafsim.pipeline import trace_photo

SIZE = 600


def _specked_photo(tmp_path):
    """An elliptic leaf on paper with, inside its blade and next to its margin: a thin wedge of
    paper (too thin to be traced as a hole), a pale-green vein and a dark lesion."""
    img, poly = photo(SIZE)
    right = poly[np.argmax(poly[:, 0])]  # the blade's widest point on the right
    x, y = int(right[0]), int(right[1])
    wedge = np.array([[x - 1, y - 1], [x - 16, y], [x - 1, y + 1]], np.int32)  # 15 px long, 2 px wide at the margin
    cv2.fillPoly(img, [wedge], PAPER)
    cv2.line(img, (x - 30, y - 40), (x - 6, y - 40), (150, 210, 165), 2)  # pale vein (BGR), reaching the margin
    cv2.circle(img, (x - 12, y + 20), 4, (20, 30, 35), -1)  # dark lesion by the margin
    path = tmp_path / "specked.png"
    cv2.imwrite(str(path), img)
    return path, (x, y)


def test_background_specks_leave_the_texture_and_tissue_stays(tmp_path):
    path, (x, y) = _specked_photo(tmp_path)
    traced = trace_photo(path, ParamSet())
    rgba = load_photo_rgba(path, traced=traced)
    assert rgba.shape[:2] == (SIZE, SIZE)
    blade = cv2.resize(traced.mask, (SIZE, SIZE), interpolation=cv2.INTER_NEAREST) > 0
    assert blade[y, x - 8] and blade[y, x - 12]  # the wedge lies inside the traced blade ...
    assert rgba[y, x - 8, 3] == 0 and rgba[y, x - 12, 3] == 0  # ... and is out of the texture's leaf
    assert blade[y - 40, x - 20] and blade[y + 20, x - 12]
    assert rgba[y - 40, x - 20, 3] == 255 and rgba[y + 20, x - 12, 3] == 255  # vein and lesion are tissue
    assert rgba[SIZE // 2, SIZE // 2, 3] == 255
    # the cleaned texture shows no paper anywhere inside the traced blade
    tex = clean_texture(rgba)[:, :, :3].astype(int)
    paper = np.array(PAPER[::-1])  # RGB
    assert not (np.abs(tex[blade] - paper).max(axis=1) < 25).any()


def test_a_cut_out_or_speckless_photo_is_untouched():
    """Nothing in a blade whose pixels are all unlike the background is taken out; so, through
    the caller's guard, a cut-out photo (alpha: no background in it) is never searched."""
    rgb = np.zeros((400, 400, 3), np.uint8)
    rgb[:] = (240, 240, 240)
    blade = np.zeros((400, 400), bool)
    blade[100:300, 100:300] = True
    rgb[blade] = (60, 140, 40)
    rgb[125:127, 100:250] = (200, 230, 190)  # a pale vein from the margin
    assert not background_specks(rgb, blade).any()
    rgb[199:201, 100:106] = (240, 240, 240)  # a slit of background at the margin (reach: 6 px)
    got = background_specks(rgb, blade)
    assert got[199:201, 100:106].all() and not got[:, 120:].any() and not got[125:127].any()
    # on a dark background nothing is searched: dark tissue by the margin (a necrotic rim) is no speck
    dark = rgb.copy()
    dark[~blade] = (15, 15, 15)
    dark[150:152, 100:106] = (15, 15, 15)
    assert not background_specks(dark, blade).any()
