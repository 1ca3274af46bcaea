import json
from pathlib import Path

import numpy as np
import pytest

from leafsim.base.errors import LeafsimError
from leafsim.base.geometry import points_in_polygon, polygon_area
from leafsim.base.resources import data_dir
from leafsim.config.species import get_species, load_library
from leafsim.pipeline import leaf_shape

LIB = load_library()


def test_library_has_the_required_species():
    assert len(LIB) >= 8
    photos = {k for k, s in LIB.items() if s.has_photo}
    drawn = {k for k, s in LIB.items() if not s.has_photo}
    assert {"grapevine", "oak", "aspen", "hornbeam"} <= photos
    assert {"maple", "chestnut", "walnut", "pokeweed"} <= drawn
    for s in LIB.values():
        if s.has_photo:
            assert s.image.is_file()


def test_every_photo_is_attributed():
    text = (data_dir("images") / "SOURCES.md").read_text()
    for s in LIB.values():
        if s.has_photo:
            assert s.image.name in text


@pytest.mark.parametrize("key", sorted(LIB))
def test_shape_in_metres(key):
    sp = LIB[key]
    sh = leaf_shape(sp)
    assert sh.contour.shape[1] == 2 and len(sh.contour) >= 40
    assert polygon_area(sh.contour) > 0  # counter-clockwise
    assert np.allclose(sh.base, 0) and np.isclose(sh.apex[1], sp.length_m) and np.isclose(sh.apex[0], 0)
    # the blade lies around the base-apex axis and the apex is inside or on the outline
    assert 0.05 * sp.length_m**2 < sh.area < 1.5 * sp.length_m**2
    mid = np.array([[0.0, 0.5 * sp.length_m]])
    assert points_in_polygon(mid, sh.contour)[0]


def _write(tmp_path, data):
    p = tmp_path / "leaves.json"
    p.write_text(json.dumps(data) if not isinstance(data, str) else data)
    return p


def _entry(**kw):
    e = {"length_m": 0.1, "outline": {"points": [[0, 0], [0.3, 0.5], [0, 1], [-0.3, 0.5]]}}
    e.update(kw)
    return e


@pytest.mark.parametrize("data,needle", [
    ("{ not json", "malformed JSON at line 1"),
    ({"nospecies": {}}, "'species'"),
    ({"species": {"x": _entry(length_m=-1)}}, "species 'x', key 'length_m'"),
    ({"species": {"x": _entry(colour="red")}}, "species 'x', key 'colour'"),
    ({"species": {"x": _entry(params={"veins.main.kappa": 99})}}, "species 'x': parameter 'veins.main.kappa'"),
    ({"species": {"x": _entry(params={"veins.nope": 1})}}, "species 'x': unknown parameter 'veins.nope'"),
    # an entry key written inside params was answered with "did you mean outline.points" (a parameter)
    ({"species": {"x": _entry(params={"outline.smooth": 2})}}, "key 'params.outline.smooth': not a parameter but a key of the species entry's 'outline' object"),
    ({"species": {"x": _entry(params={"length_m": 0.2})}}, "key 'params.length_m': not a parameter but a key of the species entry's own"),
    # a quoted number or switch was read as one: refused, naming the key and the JSON type wanted
    ({"species": {"x": _entry(params={"shrink.alpha": "0.3"})}}, "parameter 'shrink.alpha' = \"0.3\" is a string"),
    ({"species": {"x": _entry(params={"veins": {"main": {"kappa": "4"}}})}}, "'veins.main.kappa' = \"4\" is a string"),
    ({"species": {"x": _entry(variants={"red": {"params": {"mesh.spacing": "0.03"}}})}}, "written as a JSON number"),
    ({"species": {"x": _entry(image="images/missing.png")}}, "species 'x', key 'image'"),
    ({"species": {"x": {"length_m": 0.1}}}, "needs either 'image'"),
    ({"species": {"x": _entry(outline={"points": [[0, 0], [1]]})}}, "key 'outline.points'"),
    ({"species": {"x": _entry(lateral_profile=[[50, 1], [10, 1]])}}, "key 'lateral_profile'"),
    # strings and true/false in a coordinate list were read as numbers
    ({"species": {"x": _entry(outline={"points": [[0, 0], ["0.3", "0.5"], [0, 1], [-0.3, 0.5]]})}},
     "key 'outline.points': pair 2 is [\"0.3\", \"0.5\"]: expected [x, y] as JSON numbers"),
    ({"species": {"x": _entry(targets=[[False, True]])}}, "key 'targets': pair 1 is [false, true]"),
    ({"species": {"x": _entry(lateral_profile=[["0", "1"], [100, 0.5]])}}, "key 'lateral_profile': pair 1"),
    # an unknown key inside teeth or senescent_photo is named
    ({"species": {"x": _entry(outline={"points": [[0, 0], [0.3, 0.5], [0, 1], [-0.3, 0.5]],
                                       "teeth": {"count": 30, "dept": 0.02}})}}, "key 'outline.teeth.dept': unknown key"),
    ({"species": {"x": _entry(senescent_photo={"image": "images/a.png", "base": [1, 2]})}},
     "key 'senescent_photo.base': unknown key"),
    ({"species": {"x": {"length_m": 0.1, "image": ""}}}, "key 'image': expected a path string relative to the config's project, not an empty one"),
    ({"species": {"x": {"length_m": 0.1, "image": "nowhere/leaf.png"}}}, "not found (a relative path is read from"),
    # the README's entry pasted at the top level used to be silently ignored
    ({"species": {"x": _entry()}, "birch": _entry()}, "unknown top-level key 'birch'"),
    ({"species": {"x": _entry(variants=[1])}}, "species 'x', key 'variants'"),
    ({"species": {"x": _entry(variants={"red": {"image": "a.png"}})}}, "key 'variants.red.image'"),
    ({"species": {"x": _entry(variants={"red": {"params": {"colour.nope": 1}}})}}, "species 'x_red': unknown parameter"),
    ({"species": {"x": _entry(variants={"red": {}}), "x_red": _entry()}}, "'x_red' is defined twice"),
    # a lone surrogate was an internal error when printed; a newline split the species table's row
    ({"species": {"x": _entry(name="X\ud800")}}, "key 'name': expected text that UTF-8 can write"),
    ({"species": {"x": _entry(name="X\nSECOND LINE")}}, "key 'name': expected one line of printable text"),
    ({"species": {"x": _entry(description="fine\n\ud800")}}, "key 'description': expected text that UTF-8"),
    ({"species": {"x": _entry(image=str(data_dir("images") / "autumn_carpinus_like_01_front.png"))}},
     "key 'outline': and 'image' both give"),
])
def test_bad_entries_name_file_species_and_key(tmp_path, data, needle):
    p = _write(tmp_path, data)
    with pytest.raises(LeafsimError) as e:
        load_library(p)
    assert str(p) in str(e.value) and needle in str(e.value) and "\n" not in str(e.value)


def test_variants_are_species_with_their_own_colours():
    lib = load_library()
    white, red = lib["grapevine"], lib["grapevine_red"]
    assert red.image == white.image and red.length_m == white.length_m
    assert white.params["colour.anthocyanin"] == 0.0 < red.params["colour.anthocyanin"]
    # everything else of the entry is the species'
    assert red.params["colour.vein_islands"] == white.params["colour.vein_islands"]
    assert lib["maple_sugar"].params["colour.anthocyanin"] > 5 * lib["maple"].params["colour.anthocyanin"]


def test_missing_config_and_unknown_species(tmp_path):
    with pytest.raises(LeafsimError, match="not found"):
        load_library(tmp_path / "nope.json")
    with pytest.raises(LeafsimError, match="unknown species 'fern'.*maple"):
        get_species("fern")
    # a library looked up by key: one line naming the file (was a bare KeyError: 'birch'), still
    # a KeyError for code that catches one
    lib = load_library()
    with pytest.raises(LeafsimError, match=r"^unknown species 'mapel' in .*leaves\.json \(did you mean 'maple'\? known: ") as e:
        lib["mapel"]
    assert isinstance(e.value, KeyError) and "\n" not in str(e.value)
    assert lib.get("mapel") is None and "maple" in lib


def test_the_readme_species_snippet_loads(tmp_path):
    """The README's "Adding a species" JSON, with its photo path pointing at a shipped photo,
    is a loadable config with the species in it."""
    from helpers.paths import REPO

    text = (REPO / "README.md").read_text()
    block = text.split("## Adding a species", 1)[1].split("```json", 1)[1].split("```", 1)[0]
    data = json.loads(block)
    (tmp_path / "images").mkdir()
    (tmp_path / "images" / "birch.jpg").write_bytes((data_dir("images") / "populus_01.jpg").read_bytes())
    p = tmp_path / "mine.json"
    p.write_text(json.dumps(data))
    sp = get_species("birch", p)
    assert sp.name == "Birch" and sp.params["veins.main.kappa"] == 3.0 and sp.has_photo


def test_user_adds_a_species(tmp_path):
    p = _write(tmp_path, {"species": {"kite": _entry(params={"veins.main.kappa": 2})}})
    sp = get_species("kite", p)
    assert sp.params["veins.main.kappa"] == 2.0 and not sp.has_photo
    sh = leaf_shape(sp)
    assert np.isclose(sh.length, 0.1)


def test_a_configs_folder_config_finds_its_photos_however_its_path_is_written(tmp_path, monkeypatch):
    """A config in a folder called ``configs/`` takes its photo paths from the folder above,
    also when its path is written without a folder (``leaves.json`` or ``./leaves.json`` from
    inside it: the rule tested the path as typed, so the photos were looked for in configs/)."""
    import shutil

    (tmp_path / "configs").mkdir()
    (tmp_path / "images").mkdir()
    lib = json.loads((data_dir("configs") / "leaves.json").read_text())
    oak = lib["species"]["oak"]
    shutil.copy(data_dir("images") / Path(oak["image"]).name, tmp_path / "images" / "oak.jpg")
    entry = {k: v for k, v in oak.items() if k not in ("senescent_photo",)}
    entry["image"] = "images/oak.jpg"
    (tmp_path / "configs" / "mine.json").write_text(json.dumps({"species": {"myoak": entry}}))
    monkeypatch.chdir(tmp_path / "configs")
    for written in ("mine.json", "./mine.json", str(tmp_path / "configs" / "mine.json")):
        lib2 = load_library(written)
        assert lib2["myoak"].image == (tmp_path / "images" / "oak.jpg").resolve(), written


def test_a_copy_of_the_shipped_library_anywhere_finds_the_shipped_photos(tmp_path):
    """Copying configs/leaves.json elsewhere to tweak one species is the obvious workflow: the
    copy's photo entries (images/...) are not beside it, and every one was refused, so even a
    drawn species of the copy could not be loaded.  A photo of the user's own beside the copy
    still wins over a shipped one of the same name."""
    import shutil

    lib = tmp_path / "copy.json"
    shutil.copy(data_dir("configs") / "leaves.json", lib)
    got = load_library(lib)
    assert got["oak"].image == (data_dir("images") / Path(got["oak"].image).name).resolve()
    assert got["maple"].image is None
    (tmp_path / "images").mkdir()
    mine = tmp_path / "images" / got["oak"].image.name
    shutil.copy(got["oak"].image, mine)
    assert load_library(lib)["oak"].image == mine.resolve()


def test_a_photo_without_a_leaf_names_the_config_species_and_key(tmp_path):
    """A blank photo (or one with no leaf) named by a config entry: the one line names the
    config, the species and its key 'image', not only the picture's path."""
    import cv2

    cv2.imwrite(str(tmp_path / "white.png"), np.full((200, 200, 3), 255, np.uint8))
    p = _write(tmp_path, {"species": {"x": {"image": "white.png", "length_m": 0.1}}})
    sp = get_species("x", p)
    with pytest.raises(LeafsimError) as e:
        leaf_shape(sp, sp.params)
    text = str(e.value)
    assert text.startswith(f"{p}: species 'x', key 'image': ") and "no leaf found" in text and "\n" not in text
