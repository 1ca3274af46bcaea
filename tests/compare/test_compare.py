"""``leafsim compare`` end to end on a synthetic photo: the rows it makes, and the senescent row
of a species whose own photo shows the aged leaf (the fresh leaf grown back so that the
matched stage has the photo's size)."""

import json

import cv2

from helpers.leafimg import photo
from leafsim.compare.run import run_compare
from leafsim.config.species import get_species

#: a coarse, fast-drying leaf: the whole drying run takes ≈ 900 frames
FAST = {"mesh.spacing": 0.06, "osmosis.evaporation_top": 0.07, "osmosis.evaporation_bottom": 0.0525}


def _species(tmp_path, stage: str):
    img, _ = photo(400, colour=(40, 120, 150))  # BGR: a yellow-brown leaf
    cv2.imwrite(str(tmp_path / "leaf.png"), img)
    entry = {"name": "test leaf", "latin": "Folium testis", "description": "synthetic", "image": "leaf.png",
             "length_m": 0.06, "photo_stage": stage, "senescent_photo": {"image": "leaf.png"},
             "targets": "auto", "main_origin": "base", "params": FAST}
    (tmp_path / "leaves.json").write_text(json.dumps({"species": {"t": entry}}))
    return get_species("t", tmp_path / "leaves.json")


def test_senescent_own_photo_is_matched_by_a_grown_back_leaf(tmp_path):
    """The photo shows the leaf after it shrank: the senescent row's model is built longer by
    1/√(top-down area kept at the first pass's match), moved onto the photo's centroid, and its
    silhouette then has the photo's area to within 3 % — closer than the first pass at photo
    size — with the young row unchanged."""
    sp = _species(tmp_path, "senescent")
    rep = run_compare(sp, sp.params, seed=0)
    kinds = [r["kind"] for r in rep["rows"]]
    assert kinds == ["young", "senescent"]
    young, sen = rep["rows"]
    assert "grown_back" not in young and young["iou"] > 0.97
    k = sen["grown_back"]
    first_kept = 1.0 / k ** 2
    assert 0.6 < first_kept < 0.99  # the leaf shrank before the match
    row = rep["_rows"][1]
    ratio = row.mask.sum() / row.ref.blade.sum()
    assert abs(ratio - 1.0) < 0.03 and abs(ratio - 1.0) < 0.5 * (1.0 - first_kept), (ratio, first_kept)
    assert sen["iou"] > 0.9 and 0.0 < sen["stage"]["water"] < 1.0
    assert "grown back" in sen["note"]


def test_young_photo_senescent_row_is_not_grown_back(tmp_path):
    """A young species photo with a senescent reference: the senescent row is the drying run of
    the leaf as built (no growing back), at a stage with water left between 0 and 1."""
    sp = _species(tmp_path, "young")
    rep = run_compare(sp, sp.params, seed=0)
    assert [r["kind"] for r in rep["rows"]] == ["young", "senescent"]
    sen = rep["rows"][1]
    assert "grown_back" not in sen and "grown back" not in sen["note"]
    assert 0.0 <= sen["stage"]["water"] <= 1.0


def _veined_leaf(speckles: int):
    """(RGB photo, blade mask, 1-px vein lines, length px): a 500 px leaf with a light midrib and
    light straight laterals, and ``speckles`` spots as light and as wide as a vein on its blade (seeded)."""
    import numpy as np

    from helpers.leafimg import leaf_polygon

    size = 600
    img = np.full((size, size, 3), (235, 240, 245), np.uint8)
    poly = np.round(leaf_polygon(size, length=0.8, width=0.5)).astype(np.int32)
    blade = cv2.fillPoly(np.zeros((size, size), np.uint8), [poly], 255) > 0
    img[blade] = (60, 140, 50)
    veins = np.zeros((size, size), np.uint8)
    base, apex = (300, 510), (300, 30)
    lines = [(base, apex)] + [((300, y), (300 + s * 150, y - 120)) for y in range(460, 150, -60) for s in (-1, 1)]
    rng = np.random.default_rng(5)
    for _ in range(speckles):
        x, y = (int(v) for v in rng.integers(0, size, 2))
        if blade[y, x]:
            cv2.circle(img, (x, y), 3, (120, 200, 110), -1, cv2.LINE_AA)
    for a, b in lines:
        cv2.line(img, a, b, (120, 200, 110), 3, cv2.LINE_AA)
        cv2.line(veins, a, b, 255, 1)
    return img, blade, veins > 0, 480.0


def test_vein_agreement_finds_veins_on_the_photo_s_lines_and_not_its_speckles():
    """Model veins on the drawn ones agree with the photo; the same veins moved by 6 % of the
    length do not (near chance); light speckles as wide as a vein are no ridge, so they take
    no share of the photo's ridge pixels from the veins (the plain Hessian ridge counted them)."""
    import numpy as np

    from leafsim.compare.metrics import vein_agreement

    for speckles in (0, 500):
        img, blade, veins, L = _veined_leaf(speckles)
        on = vein_agreement(img, blade, veins, L)
        assert on["precision"] > 0.9 and on["recall"] > 0.8, (speckles, on)
        off = vein_agreement(img, blade, np.roll(veins, int(0.06 * L), axis=1), L)
        assert off["precision"] < on["precision"] - 0.3 and off["recall"] < on["recall"] - 0.3, (speckles, off)


def test_a_drying_run_without_osmosis_is_refused_at_once():
    """The dried stage and the senescent row need the leaf to dry: with osmosis off it never
    does, and compare is refused before its first frame, naming the effect (it ran the whole
    12 000-frame budget, then said the leaf did not dry); a frame number still runs."""
    import pytest

    from leafsim.base.errors import LeafsimError

    for key, stage in (("oak", "dried"), ("hornbeam", None)):  # hornbeam's senescent photo: a senescent row
        sp = get_species(key)
        with pytest.raises(LeafsimError, match="effects.osmosis off"):
            run_compare(sp, sp.params.with_overrides({"mesh.spacing": 0.06}), stage=stage, effects=["pbd", "shrink"])
    sp = get_species("oak")
    rep = run_compare(sp, sp.params.with_overrides({"mesh.spacing": 0.06}), stage="3", effects=["pbd", "shrink"])
    assert rep["rows"][-1]["stage"]["frame"] == 3


def test_montage_text_is_wrapped_to_the_picture():
    """The montage's long lines are broken at spaces to fit its width (they ran off the right
    edge), keeping every word."""
    import cv2

    from leafsim.compare.metrics import _wrap

    line = ("best of 110 stages every 50 frames; grown back: the fresh leaf × 1.113 in length, so that at the "
            "matched stage it has the photo's size (first pass at photo size: frame 4100, top-down area kept 0.808)")
    out = _wrap([line, "short"], 400)
    assert len(out) > 2 and out[-1] == "short"
    assert all(cv2.getTextSize(t, cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1)[0][0] <= 400 for t in out)
    assert " ".join(t.strip() for t in out[:-1]).split() == line.split()


def test_colour_spread_counts_and_measures_the_dark_spots_it_is_given():
    """A uniform blade with dark squares: the spots at least (0.01 L)² large are counted, their
    median diameter and the share of the blade they cover are the squares' (smaller ones and
    a merely darker patch, 10 L* down, are not spots); one hue has no spread, two hues Δ apart
    half and half the circular spread √(−2 ln cos(Δ/2)) (Δ from OpenCV's own CIELAB)."""
    import numpy as np

    from leafsim.compare.metrics import colour_spread

    L = 1000.0  # leaf length in px: a spot must cover 10 × 10 px
    img = np.zeros((400, 400, 3), np.uint8)
    img[:] = (150, 170, 60)  # RGB yellow-green
    mask = np.zeros((400, 400), bool)
    mask[20:380, 20:380] = True
    base = colour_spread(img, mask, L)
    assert base["spots"] == 0 and base["dark_share"] == 0.0 and base["hue_sd_deg"] < 1e-3
    sides = (12, 20, 30, 6)  # the last is under the size threshold
    for k, a in enumerate(sides):
        img[40 + 80 * k:40 + 80 * k + a, 60:60 + a] = (40, 45, 20)
    img[300:340, 200:240] = (125, 143, 50)  # ~10 L* darker: no spot
    got = colour_spread(img, mask, L)
    assert got["spots"] == 3
    assert abs(got["spot_diameter_L"] - np.sqrt(4 * 20 ** 2 / np.pi) / L) < 1e-4
    assert abs(got["dark_share"] - (12 ** 2 + 20 ** 2 + 30 ** 2) / mask.sum()) < 1e-4
    two = np.zeros_like(img)
    two[:] = (150, 170, 60)
    two[:, 200:] = (170, 150, 60)  # another hue
    lab = cv2.cvtColor(np.array([[[150, 170, 60], [170, 150, 60]]], np.float32) / 255.0, cv2.COLOR_RGB2Lab)[0]
    hue = np.arctan2(lab[:, 2], lab[:, 1])
    want = np.degrees(np.sqrt(-2.0 * np.log(np.cos(0.5 * abs(hue[0] - hue[1])))))
    assert want > 5.0 and abs(colour_spread(two, mask, L)["hue_sd_deg"] - want) < 0.5
