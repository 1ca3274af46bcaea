"""The hostile-user cases: special files, damaged checkpoints, runaways, size guards, non-leaf
photos and errors that name their real cause.  Every bad input gives exit status 2 and one
line on stderr; nothing is replaced, nothing hangs."""

from __future__ import annotations

import contextlib
import io
import json
import os
from pathlib import Path

import cv2
import numpy as np
import pytest

from helpers import leafimg
from helpers.cli_contract import stdout_of_a_failure
from helpers.paths import REPO
from leafsim.cli import main

OAK = ["--species", "oak", "--set", "mesh.spacing=0.06"]


def run_cli(*argv):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in argv])
    return code, out.getvalue(), err.getvalue()


def one_line(code, out, err, *needles):
    assert code == 2, (code, out, err)
    stdout_of_a_failure(code, out, err)
    assert err.startswith("leafsim: ") and err.count("\n") == 1 and "Traceback" not in err and "internal error" not in err, err
    for n in needles:
        assert n in err, (n, err)
    return err


@pytest.fixture
def fifo(tmp_path):
    p = tmp_path / "pipe.png"
    os.mkfifo(p)
    return p


def test_outputs_onto_special_files_are_refused_untouched(tmp_path, fifo):
    one_line(*run_cli("outline", "images/quercus_01.png", "--out", fifo), "named pipe")
    one_line(*run_cli("outline", "images/quercus_01.png", "--out", tmp_path / "x.jpg"), "expected a .png file name")
    one_line(*run_cli("export", *OAK, "--out", fifo), "named pipe")
    one_line(*run_cli("export", *OAK, "--out", tmp_path), "it is a folder")
    (tmp_path / "m.bin").mkdir()  # the buffer beside a .gltf: refused before the build
    one_line(*run_cli("export", *OAK, "--out", tmp_path / "m.gltf", "--frames", "3"), "m.bin", "it is a folder")
    assert not (tmp_path / "m.gltf").exists()
    one_line(*run_cli("run", *OAK, "--frames", "2", "--stats", fifo), "named pipe")
    assert fifo.is_fifo() and tmp_path.is_dir()
    if os.path.isdir("/proc"):  # found before the build, not after it
        one_line(*run_cli("run", *OAK, "--frames", "2", "--stats", "/proc/leafsim.jsonl"), "cannot create a file in /proc")


def test_inputs_that_are_not_bounded_files_are_refused(tmp_path, fifo):
    one_line(*run_cli("outline", fifo), "it is a named pipe, expected a regular file")  # it would hang the reader
    if os.path.exists("/dev/zero"):
        one_line(*run_cli("species", "--config", "/dev/zero"), "character device")
    cfg = json.loads(Path("configs/leaves.json").read_text())
    cfg["species"]["maple"]["outline"]["points"] = [[0.5 * np.cos(t), 0.5 + 0.5 * np.sin(t)]
                                                   for t in np.linspace(0, 6.28, 25_000)]
    big = tmp_path / "big.json"
    big.write_text(json.dumps(cfg))
    one_line(*run_cli("species", "--config", big), "25,000 points, expected at most 20,000")
    huge = tmp_path / "huge.json"
    huge.write_text('{"species": {"x": {"length_m": 1' + "0" * 5000 + '}}}')
    one_line(*run_cli("species", "--config", huge), "an integer of more than 4000 digits")
    bomb = tmp_path / "bomb.png"  # a tiny file whose header claims 65 000 × 65 000 pixels
    ok, png = cv2.imencode(".png", np.zeros((8, 8), np.uint8))
    raw = bytearray(png.tobytes())
    raw[16:24] = (65000).to_bytes(4, "big") * 2
    bomb.write_bytes(bytes(raw))
    one_line(*run_cli("outline", bomb), "65000×65000 pixels")
    dup = tmp_path / "dup.json"
    dup.write_text(Path("configs/leaves.json").read_text().replace('"species": {', '"species": {"oak": {}, ', 1))
    one_line(*run_cli("species", "--config", dup), "duplicate key 'oak'")


def test_scene_size_guards_come_before_any_work(tmp_path):
    def scene(layout=None, **group):
        p = tmp_path / "s.json"
        g = {"name": "a", "species": "oak", "count": 1, "stop": {"frames": 1}, **group}
        p.write_text(json.dumps({"layout": layout or {"kind": "row"}, "overview": False, "groups": [g]}))
        return p

    one_line(*run_cli("scene", scene(count=1_000_000), "--out", tmp_path / "o"), "≈ 2.4 GB", "at most 10,000")
    one_line(*run_cli("scene", scene(count=1e9), "--out", tmp_path / "o"), "expected an integer in [1, 10000]")
    one_line(*run_cli("scene", scene(count=10 ** 400), "--out", tmp_path / "o"), "(401 digits)", "at most 10,000")
    one_line(*run_cli("scene", scene(layout={"kind": "floor", "size": [100, 100], "cell": 0.0001}), "--out", tmp_path / "o"),
             "layout.cell", "1e+12 cells")
    one_line(*run_cli("scene", scene(species="maple", output={"mesh": "glb", "texture": "photo"}), "--out", tmp_path / "o"),
             "output.texture", "drawn outline")
    (tmp_path / "o2").mkdir()
    (tmp_path / "o2" / "placement.json").mkdir()
    one_line(*run_cli("scene", scene(), "--out", tmp_path / "o2"), "placement.json", "it is a folder")
    assert not any((tmp_path / "o2" / "leaves").iterdir())
    # a group's finest mesh over limits.max_particles is refused before the scene's files are begun,
    # naming the key that sets it (lod.show overrides mesh.spacing)
    err = one_line(*run_cli("scene", scene(lod={"simulate": 0.07, "show": 0.035, "check": 0},
                                            params={"limits.max_particles": 1000}), "--out", tmp_path / "o3"),
                   "key 'lod.show'", "more than limits.max_particles = 1,000", "use lod.show ≥")
    assert "mesh.spacing" not in err and not (tmp_path / "o3").exists()
    p = tmp_path / "d.json"
    p.write_text('{"groups": [{"name": "a", "species": "oak", "count": 2, "count": 100000, "stop": {"frames": 1}}]}')
    one_line(*run_cli("scene", p, "--out", tmp_path / "o"), "duplicate key 'count'")
    assert not (tmp_path / "o" / "leaves").exists() or not any((tmp_path / "o" / "leaves").iterdir())
    # the output folder: only its last level is made (as run and export), a broken link is named
    one_line(*run_cli("scene", scene(), "--out", tmp_path / "no" / "such" / "out"), "folder", "does not exist")
    assert not (tmp_path / "no").exists()
    (tmp_path / "gone").symlink_to(tmp_path / "nowhere")
    one_line(*run_cli("scene", scene(), "--out", tmp_path / "gone"), "broken symbolic link")


def test_errors_name_their_real_cause(tmp_path):
    one_line(*run_cli("build", "--species", ""), "no species given")
    # operating-system errors on the user's paths are one line too (ENAMETOOLONG was an internal error)
    long = tmp_path / ("c" * 300)
    one_line(*run_cli("run", *OAK, "--frames", "2", "--out", long), "File name too long", " characters)")
    one_line(*run_cli("run", *OAK, "--frames", "2", "--stats", long / "s.jsonl"), " characters)")
    (tmp_path / "a.txt").write_text("x")
    one_line(*run_cli("run", *OAK, "--frames", "2", "--out", tmp_path / "a.txt" / "sub"), "a.txt is a file, not a folder")
    one_line(*run_cli("export", *OAK, "--out", tmp_path / "a.txt" / "x.glb"), "a.txt is a file, not a folder")
    one_line(*run_cli("run", *OAK, "--frames", "2", "--out", tmp_path / "a.txt" / "sub" / "o"), "a.txt is a file, not a folder")
    one_line(*run_cli("run", *OAK, "--frames", "2", "--stats", tmp_path / "a.txt" / "sub" / "s.jsonl"),
             "a.txt is a file, not a folder")
    # a command line that does not parse, with --json, prints its one object too
    code, out, err = run_cli("run", "--frames", "abc", "--json")
    assert code == 2 and json.loads(out) == {"command": "run", "error": err.strip().removeprefix("leafsim: "), "exit": 2}
    # a --config that cannot be read says so, with or without --species
    one_line(*run_cli("build", "--config", tmp_path / "none.json"), "species config not found")
    # --effects sets every effect: a --set of one beside it is refused, not dropped
    one_line(*run_cli("run", *OAK, "--frames", "2", "--effects", "osmosis", "--set", "effects.shrink=true"),
             "--set effects.shrink with --effects osmosis")
    # --json: exactly one JSON object, a failed command's too, with the error line's message
    code, out, err = run_cli("run", "--species", "mapel", "--frames", "5", "--json")
    doc = json.loads(out)
    assert code == 2 and doc["exit"] == 2 and doc["command"] == "run" and "did you mean 'maple'?" in doc["error"]
    assert err.count("\n") == 1 and doc["error"] in err
    # no --species, and a --config without the default one: the message says so
    cfg = json.loads(Path("configs/leaves.json").read_text())
    cfg["species"] = {"oak": cfg["species"]["oak"]}
    cfg["species"]["oak"]["image"] = str(Path("images/quercus_01.png").resolve())
    (tmp_path / "oak_only.json").write_text(json.dumps(cfg))
    one_line(*run_cli("build", "--config", tmp_path / "oak_only.json"), "no --species given", "default 'maple'", "known: oak")
    one_line(*run_cli("build", "--species", "mapel"), "did you mean 'maple'?")
    one_line(*run_cli("outline", "images/quercus_01.png", "--set", "limits.image_pixels=10000"),
             "limits.image_pixels = 10,000", "too coarse")
    one_line(*run_cli("build", *OAK, "--set", "dynamics.dt=nan"), "expected a finite value")
    out = tmp_path / "o"
    assert run_cli("run", *OAK, "--frames", "8", "--out", out, "--checkpoint-every", "4")[0] == 0
    one_line(*run_cli("run", *OAK, "--frames", "5", "--out", out, "--checkpoint-every", "4", "--resume"),
             "at frame 8 already")


@pytest.mark.parametrize("damage,needle", [
    ("short", "particle_q is float64 (" ),
    ("float32", "particle_q is float32"),
    ("negative water", "negative water"),
    ("nan", "NaN or infinite"),
    ("too much water", "more water"),
    ("all the water in one particle", "fresh water (a particle holds at most"),
    ("collapsed positions", "particle_q does not form this leaf"),
    ("scrambled positions", "particle_q does not form this leaf"),
    ("truncated file", "cannot read checkpoint"),
    ("time beyond the frames", "more than frame × the longest Δt"),
    ("negative leaf factor", "pigment array leaf"),
    ("inflating member", "more than 160,000,000 bytes"),
])
def test_a_damaged_checkpoint_is_refused_before_any_kernel(tmp_path, damage, needle):
    out = tmp_path / "o"
    assert run_cli("run", *OAK, "--frames", "4", "--out", out, "--checkpoint-every", "2")[0] == 0
    ck = out / "checkpoint.npz"
    if damage == "truncated file":
        ck.write_bytes(ck.read_bytes()[: len(ck.read_bytes()) // 2])
    else:
        d = dict(np.load(ck))
        if damage == "short":
            d["state_particle_q"] = d["state_particle_q"][:-5]
        elif damage == "float32":
            d["state_particle_q"] = d["state_particle_q"].astype(np.float32)
        elif damage == "negative water":
            d["state_particle_water"] = -d["state_particle_water"]
        elif damage == "nan":
            d["state_particle_qd"][3, 1] = np.nan
        elif damage == "too much water":
            d["state_particle_water"] = d["state_particle_water"] * 3
        elif damage == "all the water in one particle":
            w = d["state_particle_water"]
            d["state_particle_water"] = np.zeros_like(w)
            d["state_particle_water"][0] = w.sum()
        elif damage == "collapsed positions":
            d["state_particle_q"] = np.zeros_like(d["state_particle_q"])
        elif damage == "scrambled positions":
            d["state_particle_q"] = d["state_particle_q"] + np.random.default_rng(0).normal(0.0, 0.05, d["state_particle_q"].shape)
        elif damage == "time beyond the frames":
            d["state_scalars"] = d["state_scalars"].copy()
            d["state_scalars"][0] = 1e9
        elif damage == "negative leaf factor":
            d["pig_leaf"] = -50.0 * np.abs(d["pig_leaf"])
        elif damage == "inflating member":  # compresses to a few hundred kB, would inflate to 200 MB (25 M floats)
            d["state_particle_q"] = np.zeros((25_000_000,), np.float64)
        (np.savez_compressed if damage == "inflating member" else np.savez)(ck, **d)
    one_line(*run_cli("run", *OAK, "--frames", "8", "--out", out, "--checkpoint-every", "2", "--resume"), needle)


def test_non_leaf_photos_are_reported_and_refused(tmp_path):
    sq = np.full((500, 500, 3), 235, np.uint8)
    sq[120:380, 120:380] = (30, 30, 200)
    cv2.imwrite(str(tmp_path / "square.png"), sq)
    cut, _ = leafimg.photo(500, centre=(0.5, 0.75))  # the blade runs off the bottom edge
    cv2.imwrite(str(tmp_path / "cut.png"), cut)
    code, out, err = run_cli("outline", tmp_path / "cut.png", "--json")
    assert code == 0 and json.loads(out)["cut_by_border"] == ["bottom"]
    assert "leafsim: warning:" in err and "cut by the image's bottom border" in err
    code, out, err = run_cli("outline", tmp_path / "square.png", "--json")
    assert code == 0 and "is a rectangle" in err
    one_line(*run_cli("compare", "--species", "oak", "--set", "mesh.spacing=0.06", "--photo", tmp_path / "square.png"),
             "is a rectangle")
    oak = json.loads(Path("configs/leaves.json").read_text())["species"]["oak"]
    oak["image"] = str(tmp_path / "cut.png")
    for k in ("base_px", "apex_px", "senescent_photo"):
        oak.pop(k, None)
    cfg = {"species": {"oak": oak}}
    p = tmp_path / "cfg.json"
    p.write_text(json.dumps(cfg))
    one_line(*run_cli("build", "--species", "oak", "--config", p), "key 'image'", "cut by the image's bottom border")


@pytest.mark.slow
def test_the_runaway_of_the_issue_is_stopped():
    """Two in-range values made the leaf crumple with growing energy (7 m/s) and exit 0; the
    watchdog now stops it (internal RMS speed ≫ what drying tissue does) and blames the two
    values the user set, not the draft level's own settings."""
    code, out, err = run_cli("run", "--species", "maple", "--quality", "draft", "--frames", "1500",
                             "--set", "shrink.sigma_surface_bottom=3", "--set", "shrink.l_min=0.1", "--json")
    one_line(code, out, err, "simulation unstable", "internal motion", "shrink.sigma_surface_bottom = 3 (draft quality 0.15)",
             "shrink.l_min = 0.1")
    assert "dynamics.substeps" not in err


def test_outputs_in_the_out_folder_are_checked_before_the_run(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    os.mkfifo(out / "final.npz")
    one_line(*run_cli("run", *OAK, "--frames", "3", "--out", out, "--checkpoint-every", "0"), "final.npz", "named pipe")
    (out / "final.npz").unlink()
    (out / "checkpoint.npz").mkdir()
    one_line(*run_cli("run", *OAK, "--frames", "3", "--out", out), "checkpoint.npz", "it is a folder")
    one_line(*run_cli("run", *OAK, "--frames", "3", "--out", out, "--resume"), "is not a regular file")
    (out / "checkpoint.npz").rmdir()
    (out / "frame_00000.png").mkdir()
    one_line(*run_cli("run", *OAK, "--frames", "3", "--out", out, "--every", "1"), "frame_00000.png", "it is a folder")
    (tmp_path / "dangling").symlink_to(tmp_path / "missing")
    one_line(*run_cli("run", *OAK, "--frames", "3", "--out", tmp_path / "dangling"), "broken symbolic link")
    assert (out / "frame_00000.png").is_dir() and not (tmp_path / "missing").exists()


def test_a_criterion_the_run_cannot_reach_is_refused_not_run_forever(tmp_path, monkeypatch):
    import leafsim.compare.run as compare_run
    import leafsim.sim.run as sim_run

    # a criterion that already holds runs nothing, effects or not
    code, out, err = run_cli("run", *OAK, "--until", "water=1", "--effects", "shrink,pbd", "--json")
    assert code == 0 and json.loads(out)["frames"] == 0, (code, err)
    # the effect that moves the measure is off: refused at once
    one_line(*run_cli("run", *OAK, "--until", "dry", "--effects", "shrink,pbd"), "effects.osmosis off")
    one_line(*run_cli("run", *OAK, "--until", "season=2", "--effects", "osmosis"), "effects.colour off")
    one_line(*run_cli("export", *OAK, "--until", "dry", "--effects", "shrink", "--out", tmp_path / "x.glb"),
             "effects.osmosis off")
    assert not (tmp_path / "x.glb").exists()
    # the measure stands still (evaporation off): refused after STALL_FRAMES frames without progress
    monkeypatch.setattr(sim_run, "STALL_FRAMES", 40)
    err = one_line(*run_cli("run", *OAK, "--until", "water=0.5", "--set", "osmosis.evaporation_top=0",
                            "--set", "osmosis.evaporation_bottom=0", "--set", "osmosis.edge_evaporation=0"),
                   "has not moved towards it in 40 frames")
    assert "at frame 40" in err
    # compare's dried stage of a leaf that cannot dry is an error, not a "dried" row at full water
    monkeypatch.setattr(compare_run, "MAX_FRAMES", 30)
    one_line(*run_cli("compare", *OAK, "--stage", "dried", "--set", "osmosis.evaporation_top=0",
                      "--set", "osmosis.evaporation_bottom=0"), "did not dry within 30 frames")
    # and one whose effects cannot dry it is refused before its first frame
    one_line(*run_cli("compare", *OAK, "--stage", "dried", "--effects", "colour"), "effects.osmosis off")


def test_incomplete_or_absurd_solver_records_are_refused(tmp_path):
    out = tmp_path / "o"
    static = [*OAK, "--set", "dynamics.integrator=static"]  # its checkpoints carry the solver's records
    assert run_cli("run", *static, "--frames", "4", "--out", out, "--checkpoint-every", "2")[0] == 0
    ck = out / "checkpoint.npz"
    good = dict(np.load(ck))
    assert {"carry_equilibrium_normal", "carry_equilibrium_anchor"} <= set(good)
    for damage, needle in (("drop anchor", "without equilibrium_anchor"), ("huge normal", "outside [0,"),
                           ("0-d history", "equilibrium_history_time is")):
        d = dict(good)
        if damage == "drop anchor":
            del d["carry_equilibrium_anchor"]
        elif damage == "huge normal":
            d["carry_equilibrium_normal"] = d["carry_equilibrium_normal"] + 1e300
        else:
            d["carry_equilibrium_history_time"] = np.array(0.5)
        np.savez(ck, **d)
        one_line(*run_cli("run", *static, "--frames", "8", "--out", out, "--checkpoint-every", "2", "--resume"), needle)


def test_outputs_never_replace_inputs_links_or_read_only_files(tmp_path):
    photo = tmp_path / "leaf.png"
    photo.write_bytes(Path("images/quercus_01.png").read_bytes())
    before = photo.read_bytes()
    one_line(*run_cli("outline", photo, "--out", photo), "that is the input")
    (tmp_path / "link.png").symlink_to(photo)
    one_line(*run_cli("outline", photo, "--out", tmp_path / "link.png"), "that is the input")
    (tmp_path / "other.png").symlink_to(tmp_path / "precious.txt")
    one_line(*run_cli("outline", photo, "--out", tmp_path / "other.png"), "broken symbolic link")
    assert photo.read_bytes() == before and not (tmp_path / "precious.txt").exists()
    ro = tmp_path / "ro.png"
    ro.write_bytes(b"keep")
    ro.chmod(0o444)
    one_line(*run_cli("outline", photo, "--out", ro), "read-only")
    assert ro.read_bytes() == b"keep"
    out = tmp_path / "run"
    out.mkdir()
    one_line(*run_cli("run", *OAK, "--frames", "2", "--out", out, "--stats", out / "final.npz"), "--stats", "writes that file")
    # nor the species' config or photo
    oak = json.loads(Path("configs/leaves.json").read_text())["species"]["oak"]
    oak["image"] = str(photo)
    oak.pop("senescent_photo", None)
    cfg = tmp_path / "c.json"
    cfg.write_text(json.dumps({"species": {"oak": oak}}))
    one_line(*run_cli("run", "--config", cfg, *OAK, "--frames", "2", "--stats", cfg), "--stats", "that is the input")
    one_line(*run_cli("export", "--config", cfg, *OAK, "--format", "glb", "--out", photo), "--out", "that is the input")
    (tmp_path / "q.bin").write_bytes(photo.read_bytes())
    oak["image"] = str(tmp_path / "q.bin")
    cfg.write_text(json.dumps({"species": {"oak": oak}}))
    one_line(*run_cli("export", "--config", cfg, *OAK, "--out", tmp_path / "q.gltf"), "--out", "that is the input", "q.bin")
    assert photo.read_bytes() == before and (tmp_path / "q.bin").read_bytes() == before


def child(*argv):
    """leafsim in a child process, for the cases that hung before: a regression fails, not stalls."""
    import subprocess
    import sys
    r = subprocess.run([sys.executable, "-m", "leafsim", *map(str, argv)], capture_output=True, text=True, timeout=600)
    return r.returncode, r.stdout, r.stderr


def test_bad_counts_seeds_and_config_shapes_are_one_line(tmp_path):
    one_line(*child("run", *OAK, "--frames", "99999999999999999999"), "--frames", "from 0 to")
    one_line(*child("compare", *OAK, "--stage", "99999999999999999999"), "--stage", "frame number from 0 to")
    one_line(*run_cli("compare", *OAK, "--stage", "9" * 5000), "--stage", "…: expected young")  # int() refuses 4300+ digits
    one_line(*run_cli("build", *OAK, "--set", "veins.main.kappa=1_0"), "veins.main.kappa", "expected a number")
    code, out, err = run_cli("build", *OAK, "--seed", "1_0")
    assert code == 2 and "expected a non-negative integer" in err
    code, out, err = run_cli("accuracy", "--quick", "--json", "--seed", "-1", "--groups", "mesh")
    assert code == 2 and "internal error" not in err and "expected a non-negative integer" in err
    cfg = json.loads(Path("configs/leaves.json").read_text())
    cfg["species"]["grapevine"]["params"] = [1, 2]  # grapevine has variants: they merge its params
    p = tmp_path / "c.json"
    p.write_text(json.dumps(cfg))
    one_line(*run_cli("species", "--config", p), "species 'grapevine', key 'params'", "expected an object")
    oak = {"species": {"oak": json.loads(Path("configs/leaves.json").read_text())["species"]["oak"]}}
    oak["species"]["oak"]["image"] = str(Path(oak["species"]["oak"]["image"]).resolve())
    oak["species"]["oak"].pop("senescent_photo", None)
    oak["species"]["oak"]["base_px"] = [1e300, 1e300]
    p.write_text(json.dumps(oak))
    one_line(*run_cli("build", "--config", p, *OAK), "key 'base_px'", "off the photo")
    oak["species"]["oak"]["base_px"] = [1e6, 1e6]  # hung in the petiole search before
    p.write_text(json.dumps(oak))
    one_line(*child("build", "--config", p, *OAK), "key 'base_px'", "off the photo")
    oak["species"]["oak"]["base_px"] = oak["species"]["oak"]["apex_px"]
    p.write_text(json.dumps(oak))
    one_line(*run_cli("build", "--config", p, *OAK), "key 'apex_px'", "from base_px")


def test_options_that_would_be_ignored_or_silently_empty_are_refused(tmp_path):
    one_line(*run_cli("params", "--json", "--markdown"), "--markdown and --json")
    one_line(*run_cli("run", *OAK, "--frames", "2", "--out", ""), "--out ''")
    one_line(*run_cli("export", *OAK, "--out", ""), "--out ''")
    one_line(*run_cli("run", *OAK, "--frames", "1_0"), "--frames", "expected an integer")
    acc = tmp_path / "acc"
    acc.mkdir()
    (acc / "accuracy_pareto.png").write_bytes(b"keep")
    (acc / "accuracy_pareto.png").chmod(0o444)  # found before the study, not after writing the other two
    one_line(*run_cli("accuracy", "--quick", "--groups", "mesh", "--out", acc), "accuracy_pareto.png", "read-only")
    assert sorted(p.name for p in acc.iterdir()) == ["accuracy_pareto.png"]
    (acc / "accuracy_pareto.png").chmod(0o644)
    (acc / "accuracy_pareto.png").unlink()
    acc.rmdir()
    one_line(*run_cli("run", *OAK, "--frames", "2", "--effects", ""), "--effects", "expected a comma-separated list")
    one_line(*run_cli("run", *OAK, "--frames", "2", "--stats", ""), "--stats ''")
    one_line(*run_cli("export", *OAK, "--every", "2", "--out", tmp_path / "x.glb"), "--every 2 needs --frames N or --until dry")
    # (--frames 0 with --every wrote a still without a word: no animation, the texture switched)
    one_line(*run_cli("export", *OAK, "--frames", "0", "--every", "5", "--out", tmp_path / "x.glb"), "--every 5 with --frames 0")
    one_line(*run_cli("outline", "images/quercus_01.png", "--set", "veins.main.kappa=4"), "--set veins.main.kappa",
             "outline.* or limits.image_pixels")
    assert not list(tmp_path.iterdir())


def test_images_are_sized_from_their_header_and_decoders_stay_quiet(tmp_path):
    img = np.full((120, 160, 3), 230, np.uint8)
    cv2.ellipse(img, (80, 60), (50, 30), 0, 0, 360, (40, 120, 50), -1)
    for ext in ("tif", "bmp", "webp", "ppm"):
        cv2.imwrite(str(tmp_path / f"leaf.{ext}"), img)
        code, out, err = run_cli("outline", tmp_path / f"leaf.{ext}", "--json")
        assert code == 0 and json.loads(out)["points"] > 0, (ext, err)
    big = cv2.resize(img, (1200, 1000))  # uncompressed, 3.6 MB: its directory lies past the first 2 MiB
    cv2.imwrite(str(tmp_path / "big.tif"), big, [cv2.IMWRITE_TIFF_COMPRESSION, 1])
    code, out, err = run_cli("outline", tmp_path / "big.tif", "--json")
    assert code == 0 and json.loads(out)["points"] > 0, err
    tif = bytearray((tmp_path / "leaf.tif").read_bytes())  # its header claims 20 000 × 20 000 pixels
    order = "little" if tif[:2] == b"II" else "big"
    off = int.from_bytes(tif[4:8], order)
    for k in range(int.from_bytes(tif[off:off + 2], order)):
        e = off + 2 + 12 * k
        if int.from_bytes(tif[e:e + 2], order) in (256, 257):
            n = 2 if int.from_bytes(tif[e + 2:e + 4], order) == 3 else 4
            tif[e + 8:e + 8 + n] = (20000).to_bytes(n, order)
    (tmp_path / "huge.tif").write_bytes(bytes(tif))
    one_line(*run_cli("outline", tmp_path / "huge.tif"), "20000×20000 pixels, more than 150 million")
    ok, jpg = cv2.imencode(".jpg", img)  # 2.6 MB of metadata segments before the frame header
    jpg = jpg.tobytes()
    (tmp_path / "meta.jpg").write_bytes(jpg[:2] + (b"\xff\xe1\xff\xff" + bytes(65533)) * 40 + jpg[2:])
    code, out, err = run_cli("outline", tmp_path / "meta.jpg", "--json")
    assert code == 0 and json.loads(out)["points"] > 0, err
    (tmp_path / "x.dat").write_bytes(b"neither a picture nor anything else" * 10)
    one_line(*run_cli("outline", tmp_path / "x.dat"), "its size is not in a PNG, JPEG")
    png = Path("images/quercus_01.png").read_bytes()
    (tmp_path / "cut.png").write_bytes(png[: len(png) // 2])
    # run in a child: libpng writes on the process's own stderr, which redirect_stderr does not catch
    import subprocess
    import sys
    r = subprocess.run([sys.executable, "-m", "leafsim", "outline", str(tmp_path / "cut.png")], capture_output=True, text=True)
    assert r.returncode == 2 and r.stdout == "" and r.stderr.count("\n") == 1 and "cannot read image" in r.stderr, r.stderr


def test_a_senescent_photos_given_end_on_its_background_is_refused(tmp_path):
    """``senescent_photo.base_px`` on the background of the senescent image set a wrong leaf axis
    and compared the wrong shape (IoU 0.44) before: it is checked against the leaf traced there,
    as the species photo's own ends are, in one line naming the key."""
    import cv2

    from helpers.leafimg import photo

    img, _ = photo(400, colour=(40, 120, 150))
    # grain: a flat colour is warned about (not a photographed leaf), and the error is alone
    img = np.clip(img + np.random.default_rng(0).normal(0.0, 4.0, (400, 400, 1)), 0, 255).astype(np.uint8)
    cv2.imwrite(str(tmp_path / "leaf.png"), img)
    cv2.imwrite(str(tmp_path / "old.png"), img)
    entry = {"name": "test leaf", "latin": "Folium testis", "description": "synthetic", "image": "leaf.png",
             "length_m": 0.06, "senescent_photo": {"image": "old.png", "base_px": [5, 5]},
             "targets": "auto", "main_origin": "base", "params": {"mesh.spacing": 0.06}}
    cfg = tmp_path / "leaves.json"
    cfg.write_text(json.dumps({"species": {"t": entry}}))
    one_line(*run_cli("compare", "--config", cfg, "--species", "t"), "senescent_photo.base_px", "outside the leaf traced",
             "old.png")


def test_substeps_coarser_than_every_measured_level_are_named_not_run_silently(tmp_path):
    """XPBD substeps coarser (h²/(M r⁴)) than the coarsest quality level's give a shape nothing
    measured (maple at dynamics.substeps 1 dried nearly flat, the window said nothing): one
    warning line naming the parameters; every quality level, species default and shipped scene
    stays quiet, and an integrator or effect set that runs no XPBD substeps too."""
    from leafsim.config.params import ParamSet
    from leafsim.config.presets import QUALITY
    from leafsim.config.species import get_species, load_library
    from leafsim.sim.effects.dynamics import unmeasured_substeps

    assert all(unmeasured_substeps(ParamSet(v)) is None for v in QUALITY.values())
    assert all(unmeasured_substeps(get_species(k).params) is None for k in load_library())
    for over, ratio in (({"dynamics.substeps": 1}, 392), ({"dynamics.dt": 0.02}, 24.5), ({"dynamics.substeps": 10}, 3.92)):
        w = unmeasured_substeps(ParamSet(over))
        assert w and f"{ratio:.3g}x coarser" in w and "dynamics.substeps" in w and "\n" not in w, (over, w)
    assert unmeasured_substeps(ParamSet({"dynamics.substeps": 20})) is None  # as coarse as draft (with its M = 256)
    assert unmeasured_substeps(ParamSet({"dynamics.substeps": 1, "effects.pbd": False, "effects.bending": False})) is None
    assert unmeasured_substeps(ParamSet({"dynamics.substeps": 1, "dynamics.integrator": "sun"})) is None
    code, _, err = run_cli("run", *OAK, "--set", "dynamics.substeps=1", "--frames", "2")
    assert code == 0 and err.count("leafsim: warning: dynamics: substeps of") == 1 and err.count("\n") == 1, err
    code, _, err = run_cli("run", *OAK, "--frames", "2")
    assert code == 0 and "warning" not in err, err
    from leafsim.commands.scene import _warn_unmeasured_substeps
    from leafsim.scene.run import load_scene

    scenes = sorted((REPO / "configs" / "scenes").glob("*.json"))
    assert len(scenes) >= 3, scenes  # the shipped scenes (an empty glob checked nothing)
    for scene in scenes:  # (the canopy's dt 0.05 s: colour only, no XPBD)
        err = io.StringIO()
        with contextlib.redirect_stderr(err):
            _warn_unmeasured_substeps(load_scene(scene))
        assert err.getvalue() == "", (scene, err.getvalue())
    coarse = {"name": "t", "seed": 0, "groups": [
        {"name": "slow", "species": "oak", "count": 2, "params": {"mesh.spacing": 0.06, "dynamics.substeps": 1}, "stop": {"frames": 1}},
        {"name": "fine", "species": "oak", "count": 1, "params": {"mesh.spacing": 0.06}, "stop": {"frames": 1}}]}
    (tmp_path / "t.json").write_text(json.dumps(coarse))
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        _warn_unmeasured_substeps(load_scene(tmp_path / "t.json"))
    assert err.getvalue().count("\n") == 1 and "group 'slow'" in err.getvalue(), err.getvalue()


def test_no_output_folder_replaces_an_input_kept_in_it(tmp_path):
    """The folder outputs (run's --every frames, accuracy's report, a scene's files and leaf
    folders) never replace the command's inputs kept there: each was overwritten before (an audit)
    and is refused in one line now, the input untouched."""
    src = Path("images/quercus_01.png").read_bytes()
    oak = json.loads(Path("configs/leaves.json").read_text())["species"]["oak"]
    oak.pop("senescent_photo", None)
    # run --every: a photo named as its first frame
    rr = tmp_path / "rr"
    rr.mkdir()
    (rr / "frame_00000.png").write_bytes(src)
    cfg = rr / "c.json"
    cfg.write_text(json.dumps({"species": {"oak": {**oak, "image": "frame_00000.png"}}}))
    one_line(*run_cli("run", "--config", cfg, *OAK, "--frames", "2", "--every", "2", "--out", rr), "--out", "frame_00000.png",
             "would be replaced")
    assert (rr / "frame_00000.png").read_bytes() == src
    # accuracy: a config named as the report
    acc = tmp_path / "acc"
    acc.mkdir()
    (acc / "accuracy.json").write_text(Path("configs/leaves.json").read_text())
    before = (acc / "accuracy.json").read_bytes()
    one_line(*run_cli("accuracy", "--config", acc / "accuracy.json", "--species", "oak", "--quick", "--out", acc), "--out",
             "that is the input")
    assert (acc / "accuracy.json").read_bytes() == before
    # a scene: its config as summary.json, a photo in a leaf's folder
    so = tmp_path / "so"
    so.mkdir()
    (so / "summary.json").write_text(json.dumps({"species": {"oak": {**oak, "image": str(Path("images/quercus_01.png").resolve())}}}))
    scene = {"name": "s", "config": str(so / "summary.json"),
             "groups": [{"name": "o", "species": "oak", "count": 1, "params": {"mesh.spacing": 0.06}, "stop": {"frames": 2}}]}
    sf = tmp_path / "scene.json"
    sf.write_text(json.dumps(scene))
    before = (so / "summary.json").read_bytes()
    one_line(*run_cli("scene", sf, "--out", so), "--out", "that is the input")
    assert (so / "summary.json").read_bytes() == before and not (so / "leaves").exists()  # refused before OUT was made
    leaf = tmp_path / "s2" / "leaves" / "o-000"
    leaf.mkdir(parents=True)
    (leaf / "leaf.png").write_bytes(src)  # a name leafsim writes there: the old check let the leaf's run replace it
    (tmp_path / "c2.json").write_text(json.dumps({"species": {"oak": {**oak, "image": str(leaf / "leaf.png")}}}))
    sf.write_text(json.dumps({**scene, "config": str(tmp_path / "c2.json")}))
    one_line(*run_cli("scene", sf, "--out", tmp_path / "s2"), "--out", "lies in", "would be replaced")
    assert (leaf / "leaf.png").read_bytes() == src
    # an input in a folder of leaves/ the scene does not write is read, not refused
    other = tmp_path / "s3" / "leaves" / "not-this-scene"
    other.mkdir(parents=True)
    (other / "leaf.png").write_bytes(src)
    (tmp_path / "c3.json").write_text(json.dumps({"species": {"oak": {**oak, "image": str(other / "leaf.png")}}}))
    sf.write_text(json.dumps({**scene, "config": str(tmp_path / "c3.json")}))
    code, _, err = run_cli("scene", sf, "--out", tmp_path / "s3")
    assert code == 0 and (other / "leaf.png").read_bytes() == src, err


@pytest.mark.parametrize("change,needle", [
    ({"effects": ["colour"], "stop": {"water_left": 0.02}}, "stop.water_left"),
    ({"params": {"mesh.spacing": 0.06, "effects.colour": False}, "stop": {"season": 1.0}}, "stop.season"),
    ({"stop": {"frames": 100, "max_frames": 5}}, "stop.max_frames"),
    ({"description": 5}, "description"),
    ({"output": {"mesh": "obj", "texture": "photo"}}, "output.texture"),
])
def test_a_scene_that_cannot_do_what_it_says_is_refused_before_any_leaf(tmp_path, change, needle):
    """A stop its effects cannot reach (each leaf was built, then failed, a line per leaf), a frame
    budget below the frames asked for (raised to them without a word) and a description that is
    no text are refused in one line naming the key, and nothing is written."""
    group = {"name": "m", "species": "oak", "count": 3, "params": {"mesh.spacing": 0.06}, "stop": {"frames": 2}}
    top = {"name": "s"}
    for k, v in change.items():
        (top if k == "description" else group)[k] = v
    sf = tmp_path / "scene.json"
    sf.write_text(json.dumps({**top, "groups": [group]}))
    one_line(*run_cli("scene", sf, "--out", tmp_path / "out"), needle)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("stop", [{"water_left": 1.0}, {"season": 0.0}])
def test_a_scene_stop_met_at_the_fresh_leaf_needs_no_effect(tmp_path, stop):
    """A stop met at frame 0 (all the water left, the season the clock starts at) is not refused
    for the effect that would move it being off: the leaves stop at once, as a run does."""
    group = {"name": "m", "species": "oak", "count": 1, "params": {"mesh.spacing": 0.06}, "effects": ["shrink"], "stop": stop}
    sf = tmp_path / "scene.json"
    sf.write_text(json.dumps({"name": "s", "groups": [group]}))
    code, out, err = run_cli("scene", sf, "--out", tmp_path / "out")
    assert code == 0, err
