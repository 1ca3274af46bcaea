"""The command-line contract: --json prints one object, bad input gives one line and exit 2."""

import json
import subprocess
import sys

import numpy as np
import pytest

from helpers.cli_contract import stdout_of_a_failure
from leafsim.cli import main


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_species_json(capsys):
    code, out, err = run(capsys, "species", "--json")
    assert code == 0 and err == ""
    data = json.loads(out)
    assert len(data["species"]) >= 8


def test_veins_json_and_png(capsys, tmp_path):
    png = tmp_path / "v.png"
    code, out, err = run(capsys, "veins", "--species", "oak", "--seed", "2", "--json", "--out", str(png))
    assert code == 0
    d = json.loads(out)
    assert d["crossings"] == 0 and d["outside_length"] == 0 and d["counts"]["main"] >= 5
    import cv2

    img = cv2.imread(str(png))
    assert img is not None and img.shape[0] > 200
    # the right half (veins over the photo) has the red midrib colour somewhere
    right = img[:, img.shape[1] // 2 :]
    assert ((right[:, :, 2] > 150) & (right[:, :, 1] < 60) & (right[:, :, 0] < 60)).sum() > 100


def test_same_seed_byte_identical_json(capsys):
    a = run(capsys, "veins", "--species", "maple", "--seed", "7", "--json")[1]
    b = run(capsys, "veins", "--species", "maple", "--seed", "7", "--json")[1]
    c = run(capsys, "veins", "--species", "maple", "--seed", "8", "--json")[1]
    assert a == b and a != c


def test_outline_json(capsys, tmp_path):
    code, out, err = run(capsys, "outline", "images/quercus_01.png", "--json", "--out", str(tmp_path / "o.png"))
    d = json.loads(out)
    assert code == 0 and d["iou"] >= 0.98 and {"points", "area_px", "base", "apex", "lobes"} <= set(d)
    assert (tmp_path / "o.png").is_file()


def _bad(capsys, argv, needle):
    code, out, err = run(capsys, *argv)
    assert code == 2, (code, err)
    stdout_of_a_failure(code, out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("leafsim: "), err
    assert needle in err, err
    assert "Traceback" not in err


def test_missing_image(capsys):
    _bad(capsys, ["outline", "no/such.png"], "no/such.png")


def test_unreadable_image(capsys, tmp_path):
    p = tmp_path / "junk.png"
    p.write_bytes(b"\x89PNG not really")
    _bad(capsys, ["outline", str(p)], str(p))


def test_empty_image(capsys, tmp_path):
    p = tmp_path / "empty.jpg"
    p.write_bytes(b"")
    _bad(capsys, ["outline", str(p)], str(p))


def test_image_with_no_leaf(capsys, tmp_path):
    import cv2

    p = tmp_path / "blank.png"
    cv2.imwrite(str(p), np.full((200, 300, 3), 255, np.uint8))
    _bad(capsys, ["outline", str(p)], "no leaf")


def test_malformed_json(capsys, tmp_path):
    p = tmp_path / "leaves.json"
    p.write_text('{"species": {"a": ')
    _bad(capsys, ["veins", "--config", str(p), "--species", "a"], "malformed JSON")


def test_unknown_species(capsys):
    _bad(capsys, ["veins", "--species", "baobab"], "unknown species 'baobab'")


def test_unknown_key_in_entry(capsys, tmp_path):
    p = tmp_path / "leaves.json"
    p.write_text(json.dumps({"species": {"a": {"length_m": 0.1, "outline": {"points": [[0, 0], [1, 1], [0, 1]]}, "colour": 1}}}))
    _bad(capsys, ["veins", "--config", str(p), "--species", "a"], "key 'colour'")


def test_value_out_of_range_in_entry(capsys, tmp_path):
    p = tmp_path / "leaves.json"
    p.write_text(json.dumps({"species": {"a": {"length_m": 0.1, "outline": {"points": [[0, 0], [1, 1], [0, 1]]},
                                                "params": {"mesh.spacing": -1}}}}))
    _bad(capsys, ["veins", "--config", str(p), "--species", "a"], "'mesh.spacing'")


def test_set_nonexistent_parameter(capsys):
    _bad(capsys, ["veins", "--set", "veins.wibble=3"], "unknown parameter 'veins.wibble'")


def test_set_out_of_range(capsys):
    _bad(capsys, ["veins", "--set", "veins.main.kappa=-5"], "out of range")


def test_set_not_a_number(capsys):
    _bad(capsys, ["veins", "--set", "veins.main.kappa=abc"], "'veins.main.kappa'")


def test_unknown_command_option(capsys):
    _bad(capsys, ["veins", "--frobnicate"], "unrecognized arguments")


def test_unwritable_output(capsys, tmp_path):
    _bad(capsys, ["veins", "--out", str(tmp_path / "nope" / "v.png")], "nope")


def test_console_script_prints_no_traceback():
    r = subprocess.run([sys.executable, "-m", "leafsim", "veins", "--species", "nope"], capture_output=True, text=True)
    assert r.returncode == 2 and r.stdout == "" and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr


def test_run_writes_stats_npz_and_frames(capsys, tmp_path):
    out = tmp_path / "run"
    stats = tmp_path / "stats.jsonl"
    code, o, err = run(capsys, "run", "--species", "oak", "--frames", "6", "--every", "3", "--out", str(out),
                       "--stats", str(stats), "--set", "mesh.spacing=0.05", "--json")
    assert code == 0, err
    rep = json.loads(o)
    assert rep["frames"] == 6 and rep["nan"] is False and 0 < rep["water_fraction"] < 1
    lines = [json.loads(x) for x in stats.read_text().splitlines()]
    assert len(lines) == 6 and all({"water_T", "water_V", "residual", "kinetic", "nan", "ms"} <= set(x) for x in lines)
    assert lines[-1]["water_T"] + lines[-1]["water_V"] <= lines[0]["water_T"] + lines[0]["water_V"]
    assert sorted(p.name for p in out.glob("frame_*.png")) == ["frame_00000.png", "frame_00003.png", "frame_00006.png"]
    d = np.load(out / "final.npz", allow_pickle=True)
    assert d["particle_q"].shape[1] == 3 and np.isfinite(d["particle_q"]).all()
    # the petiole's particles are marked, so readers can measure the blade alone
    assert d["particle_petiole"].shape == d["particle_layer"].shape and 0 < d["particle_petiole"].sum() < len(d["particle_layer"])
    assert not list(out.glob(".*tmp"))


def test_run_only_requested_effects(capsys):
    code, o, err = run(capsys, "run", "--species", "oak", "--frames", "3", "--effects", "osmosis",
                       "--set", "mesh.spacing=0.05", "--json")
    rep = json.loads(o)
    assert code == 0 and rep["water_fraction"] < 1 and rep["shape_max_displacement"] == 0


def test_run_bad_effect(capsys):
    _bad(capsys, ["run", "--frames", "3", "--effects", "osmosis,teleport"], "unknown effect 'teleport'")


def test_run_every_needs_out(capsys):
    _bad(capsys, ["run", "--frames", "3", "--every", "2"], "--every needs --out")


def test_run_negative_frames(capsys):
    _bad(capsys, ["run", "--frames", "-1"], "--frames -1")


@pytest.mark.parametrize("setting", ["mesh.spacing=-1", "dynamics.tolerance=0", "osmosis.diffusion=nan"])
def test_run_bad_parameter_before_any_work(capsys, setting):
    _bad(capsys, ["run", "--frames", "3", "--set", setting], setting.split("=")[0])


def test_until_stops_at_the_first_frame_past_the_criterion(tmp_path, capsys):
    """``--until water=F`` stops at the first frame whose water left is ≤ F (the statistics
    show the frame before it above F); ``--until dry`` with ``--frames`` stops at whichever
    comes first; bad values are one line."""
    stats = tmp_path / "s.jsonl"
    out = tmp_path / "out"
    assert main(["run", "--species", "oak", "--set", "mesh.spacing=0.08", "--until", "water=0.95", "--stats", str(stats),
                 "--every", "100000", "--out", str(out), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    # the first frame and the one where --until stopped
    assert sorted(p.name for p in out.glob("frame_*.png")) == ["frame_00000.png", f"frame_{rep['frame']:05d}.png"]
    # the blade's water (the petiole dries last and is left out of "water" and "dry")
    w = [(d["water_T"] + d["water_V"]) / rep["fresh_blade_water_kg"] for d in map(json.loads, stats.read_text().splitlines())]
    assert rep["until"] == "water=0.95" and len(w) == rep["frames"] > 10
    assert w[-1] <= 0.95 < w[-2] and rep["water_fraction"] == pytest.approx(w[-1], abs=1e-6)
    assert rep["blade_water_kg"] == pytest.approx(rep["water_fraction"] * rep["fresh_blade_water_kg"], rel=1e-5)
    assert rep["water_kg"] > rep["blade_water_kg"] and rep["petiole_water_fraction"] > rep["water_fraction"]
    assert main(["run", "--species", "oak", "--set", "mesh.spacing=0.08", "--until", "dry", "--frames", "5", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["frame"] == 5
    for bad, needle in ((["--until", "wet"], "expected dry, water=F or season=S"), (["--until", "water=1.5"], "in [0, 1]"),
                        ([], "give --frames N or --until dry")):
        assert main(["run", "--species", "oak", *bad]) == 2
        err = capsys.readouterr().err
        assert needle in err and err.count("\n") == 1


@pytest.mark.parametrize("argv", [["bench", "--nosuch"], ["run", "--species", "oak", "--frames", "x"], ["nosuchcmd"]])
def test_argument_errors_carry_one_prefix(capsys, argv):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("leafsim: ") and not err.startswith("leafsim: leafsim") and err.count("\n") == 1


def test_every_option_has_help():
    import argparse

    from leafsim.cli import build_parser

    ap = build_parser()
    subs = next(a for a in ap._actions if isinstance(a, argparse._SubParsersAction))
    missing = [f"{name} {'/'.join(a.option_strings) or a.dest}" for name, p in subs.choices.items() for a in p._actions
               if not isinstance(a, argparse._HelpAction) and not a.help]
    assert not missing, missing


def test_json_outputs_and_final_npz_say_what_made_them(capsys, tmp_path):
    """A number taken from --json says how to make it again: leafsim's version and commit, the
    libraries, the command, the species, config, seed, quality and every parameter that differs
    from the declared defaults (the species' own, --quality's and --set's); final.npz carries
    the same as ``meta``. No clock in it: the same command gives the same bytes."""
    argv = ["run", "--species", "oak", "--quality", "draft", "--frames", "2", "--set", "colour.age_rate=0.3",
            "--effects", "osmosis,colour", "--out", str(tmp_path / "o"), "--json"]
    code, out, _ = run(capsys, *argv)
    assert code == 0
    p = json.loads(out)["provenance"]
    assert p["species"] == "oak" and p["seed"] == 0 and p["quality"] == "draft" and p["command"] == " ".join(argv)
    assert p["params"]["colour.age_rate"] == 0.3 and p["params"]["effects.pbd"] is False
    assert p["params"]["dynamics.finish"] == "static"  # oak's own default, not leafsim's
    assert "mesh.spacing" in p["params"] and p["leafsim"] and p["numba"]
    import re

    assert p["commit"] is None or re.fullmatch(r"[0-9a-f]{40}(\+changes)?", p["commit"])  # None: an installed copy
    meta = json.loads(str(np.load(tmp_path / "o" / "final.npz")["meta"]))
    assert meta == p
    code, out2, _ = run(capsys, *argv)  # the same command again: the same record
    assert json.loads(out2)["provenance"] == p
    code, out3, _ = run(capsys, "veins", "--species", "maple", "--json")
    assert json.loads(out3)["provenance"]["species"] == "maple" and "quality" in json.loads(out3)["provenance"]


@pytest.mark.parametrize("suffix,addon", [("glb", True), ("obj", True), ("ply", False)])
def test_export_names_the_blender_addon_for_the_formats_it_reads(capsys, tmp_path, suffix, addon):
    """Blender's importers drop a glTF's colour morphs and photo ageing and an OBJ's vertex colours;
    the add-on brings them back, so every glTF and OBJ export says where it is (it was named for
    an animated glTF only, while docs/export.md recommends it for an OBJ)."""
    code, out, _ = run(capsys, "export", "--species", "oak", "--set", "mesh.spacing=0.06", "--out",
                       str(tmp_path / f"leaf.{suffix}"), "--json")
    rep = json.loads(out)
    assert code == 0 and ("blender_addon" in rep) == addon
    if addon:
        from pathlib import Path

        assert Path(rep["blender_addon"]).is_file() and rep["blender_addon"].endswith("blender_import.py")


def test_an_exported_gltf_says_which_leaf_it_is(capsys, tmp_path):
    """Leaves imported side by side all have surfaces called blade, stalk and veins: the glTF's
    root node is named after the leaf and says in its extras what it is (species, seed, frame,
    water)."""
    out = tmp_path / "leaf.glb"
    code, _, _ = run(capsys, "export", "--species", "oak", "--seed", "2", "--set", "mesh.spacing=0.06", "--frames", "4",
                     "--veins", "--out", str(out), "--json")
    data = out.read_bytes()
    doc = json.loads(data[20:20 + int.from_bytes(data[12:16], "little")])
    (root,) = [doc["nodes"][i] for i in doc["scenes"][0]["nodes"]]
    assert code == 0 and root["name"] == "oak-seed2" and [doc["nodes"][i]["name"] for i in root["children"]] == ["blade", "stalk", "veins"]
    about = root["extras"]["leafsim"]
    assert about["species"] == "oak" and about["seed"] == 2 and about["frame"] == 4 and 0 < about["water_fraction"] <= 1


@pytest.mark.parametrize("until", ["water=1", "season=0"])
def test_an_animation_whose_run_stops_at_the_fresh_leaf_is_refused(capsys, tmp_path, until):
    """--every with a --until that holds at the fresh leaf asks, like --frames 0, for an animation
    of no drying: refused in one line, no file (it wrote a glb of 0 targets, without animation)."""
    out = tmp_path / "leaf.glb"
    code, _, err = run(capsys, "export", "--species", "oak", "--set", "mesh.spacing=0.06", "--until", until, "--every", "10",
                       "--out", str(out))
    line = err.strip().splitlines()[-1]
    assert code == 2 and "no drying to animate" in line and f"--until {until}" in line and not out.exists()


def test_an_aged_leaf_as_obj_with_the_photo_says_the_photo_is_not_aged(capsys, tmp_path):
    """An OBJ holds the photo as its texture and nothing to age it by: a dried leaf exported so
    shows the fresh photo's green, which the command says in one warning (silent before)."""
    code, _, err = run(capsys, "export", "--species", "oak", "--set", "mesh.spacing=0.06", "--frames", "3", "--texture", "photo",
                       "--out", str(tmp_path / "leaf.obj"), "--json")
    warnings = [ln for ln in err.splitlines() if ln.startswith("leafsim: warning:")]
    assert code == 0 and len(warnings) == 1 and "--texture baked" in warnings[0] and "frame 3" in warnings[0]
    code, _, err = run(capsys, "export", "--species", "oak", "--set", "mesh.spacing=0.06", "--texture", "photo",
                       "--out", str(tmp_path / "fresh.obj"), "--json")
    assert code == 0 and "warning" not in err  # the fresh leaf is the photo


def test_an_animation_of_very_many_key_frames_says_so(capsys, tmp_path):
    """--every 1 over a long run wrote thousands of morph targets (a 290 MB glb, 2.9 GB of memory)
    without a word: past MANY_TARGETS the command warns once, naming an --every that gives about 100."""
    from leafsim.commands.export import MANY_TARGETS

    n = MANY_TARGETS + 5
    code, _, err = run(capsys, "export", "--species", "oak", "--set", "mesh.spacing=0.08", "--frames", str(n), "--every", "1",
                       "--out", str(tmp_path / "a.glb"), "--json")
    warnings = [ln for ln in err.splitlines() if "morph targets" in ln]
    assert code == 0 and len(warnings) == 1 and f"{n} morph targets" in warnings[0] and "--every 2" in warnings[0]
    code, _, err = run(capsys, "export", "--species", "oak", "--set", "mesh.spacing=0.08", "--frames", "20", "--every", "1",
                       "--out", str(tmp_path / "b.glb"), "--json")
    assert code == 0 and "morph targets" not in err


def test_the_window_says_on_the_terminal_that_it_compiles(capsys, monkeypatch):
    """A first run of the window compiled the kernels for up to a minute with nothing on the
    terminal (the status bar said it, the other commands print a line): it prints the line too,
    once, when the kernels are not compiled yet, and nothing when they are."""
    import leafsim.gui.app as gui_app
    import leafsim.interactive.warmup as warmup

    opened = []
    monkeypatch.setattr(gui_app, "run_app", lambda **kw: opened.append(kw) or 0)
    for warm in (False, True):
        monkeypatch.setattr(warmup, "is_warm", lambda w=warm: w)
        code, out, err = run(capsys, "gui", "--species", "oak")
        assert code == 0 and out == ""
        assert (err.count("leafsim: compiling the simulation kernels") == 1) is (not warm), err
    assert len(opened) == 2


def test_a_photo_missing_from_the_user_s_own_folder_is_named(capsys, tmp_path):
    """A species' photo path that is not in the user's images folder (a typo) but names a shipped
    photo was read from leafsim's own data without a word: one warning names both; a copy of the
    shipped config kept without an images folder of its own still finds the shipped photos
    quietly."""
    import warnings

    from leafsim.base.errors import LeafsimWarning
    from leafsim.config.species import load_library

    cfg = tmp_path / "leaves.json"
    cfg.write_text(json.dumps({"species": {"mine": {"name": "Mine", "image": "images/quercus_01.png", "length_m": 0.1}}}))
    for own_folder in (False, True):
        if own_folder:
            (tmp_path / "images").mkdir()
            (tmp_path / "images" / "other.png").write_bytes(b"")
        with warnings.catch_warnings(record=True) as got:
            warnings.simplefilter("always")
            assert load_library(cfg)["mine"].image.name == "quercus_01.png"
        texts = [str(w.message) for w in got if issubclass(w.category, LeafsimWarning)]
        assert len(texts) == int(own_folder), texts
    assert f"species 'mine', key 'image': images/quercus_01.png is not in {tmp_path / 'images'}" in texts[0]
    code, _, err = run(capsys, "species", "--config", str(cfg))
    assert code == 0 and err.startswith("leafsim: warning: ") and err.count("\n") == 1


def test_veins_say_where_the_main_veins_came_from(capsys):
    """``veins --json``'s targets: "photo" when the main veins are traced from the photo (it said
    "config", which the config did not give), "auto" for a drawn leaf's."""
    for key, want in (("oak", "photo"), ("maple", "auto")):
        code, out, _ = run(capsys, "veins", "--species", key, "--quality", "draft", "--json")
        assert code == 0 and json.loads(out)["targets"] == want
