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
