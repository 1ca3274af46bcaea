"""Scenes: strict scene files, batch runs (local pool, Dask), reproducible bytes, reruns,
failure isolation, level of detail and placement."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from helpers.paths import HANG_S
from helpers.paths import REPO as ROOT
from leafsim.base.errors import LeafsimError
from leafsim.scene.job import run_leaf
from leafsim.scene.run import load_scene, run_scene

TINY = {"mesh.spacing": 0.08}


def _scene(tmp_path: Path, name="tiny", overview=False, stem=None, **over) -> Path:
    """A tiny scene: two oaks on a coarse mesh shown on a finer one (LOD, one checked, frames
    every 20, an animated glb) and one chestnut; floor layout."""
    data = {
        "name": name, "seed": 4, "layout": {"kind": "floor", "size": [0.12, 0.12]}, "overview": overview,
        "groups": [
            {"name": "oak", "species": "oak", "count": 2, "seed": 7, "params": dict(TINY),
             "stop": {"frames": 40}, "lod": {"simulate": 0.08, "show": 0.06, "check": 1},
             "output": {"every": 20, "mesh": "glb", "veins": True, "stats": True}},
            {"name": "chestnut", "species": "chestnut", "count": 1, "seed": 3, "params": dict(TINY),
             "stop": {"water_left": 0.97}},
        ],
    }
    data.update(over)
    p = tmp_path / f"{stem or name}.json"
    p.write_text(json.dumps(data))
    return p


def _files(out: Path) -> dict:
    """Every output file's bytes except the run report (the one file with timings)."""
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file() and p.name != "run.json"}


@pytest.fixture(scope="module")
def one_worker(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("scene1")
    scene = load_scene(_scene(tmp))
    rep = run_scene(scene, tmp / "out", workers=1, progress=False)
    return scene, tmp / "out", rep


def test_scene_runs_and_writes_every_output(one_worker):
    scene, out, rep = one_worker
    assert rep["ran"] == 3 and rep["failed"] == [] and rep["skipped"] == 0
    leaf = out / "leaves" / "oak-000"
    frames = sorted(p.name for p in (leaf / "frames").iterdir())
    assert frames == ["state_000000.npz", "state_000020.npz", "state_000040.npz"]
    assert {"state.npz", "view.npz", "stats.jsonl", "leaf.glb", "lod.json", "done.json"} <= {p.name for p in leaf.iterdir()}
    assert not (out / "leaves" / "oak-001" / "lod.json").exists()  # check: 1 → only the first leaf
    assert len((leaf / "stats.jsonl").read_text().splitlines()) == 40
    lod = json.loads((leaf / "lod.json").read_text())
    assert lod["particles_fine"] > lod["particles_coarse"] and 0 <= lod["position_rms"] < 0.2
    assert all(np.isfinite(v) for v in lod.values())
    done = json.loads((leaf / "done.json").read_text())
    assert done["frames"] == 40 and done["particles_shown"] == lod["particles_fine"]
    ch = json.loads((out / "leaves" / "chestnut-000" / "done.json").read_text())
    assert ch["water_left"] <= 0.97 and not (out / "leaves" / "chestnut-000" / "frames").exists()
    placed = json.loads((out / "placement.json").read_text())
    assert [x["name"] for x in placed["leaves"]] == ["oak-000", "oak-001", "chestnut-000"]
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["leaves"]) == {"oak-000", "oak-001", "chestnut-000"} and set(summary["lod"]) == {"oak-000"}


def test_two_workers_give_the_same_bytes_and_rerun_skips(one_worker, tmp_path):
    scene, out1, _ = one_worker
    out2 = tmp_path / "out"
    run_scene(scene, out2, workers=2, progress=False)
    a, b = _files(out1), _files(out2)
    assert a.keys() == b.keys() and all(a[k] == b[k] for k in a), [k for k in a if a[k] != b.get(k)]
    stamp = {p: p.stat().st_mtime_ns for p in out2.rglob("*") if p.is_file() and p.name != "run.json"}
    again = run_scene(scene, out2, workers=2, progress=False)
    assert again["ran"] == 0 and again["skipped"] == 3
    assert all(p.stat().st_mtime_ns == t for p, t in stamp.items() if p.parent.parent.name == "leaves")


def test_damaged_files_of_a_finished_leaf_make_a_rerun_simulate_it_again(one_worker, tmp_path):
    """A rerun trusts a finished leaf only when its done.json and view.npz hold what a finished
    leaf writes: junk, NaN, a missing array or a bad index is simulated again (to the same
    bytes), not composed into the scene (it was an internal error or NaN in placement.json)."""
    scene, out1, _ = one_worker
    import shutil

    from leafsim.scene.job import check_done, load_view

    ref = _files(out1)
    far = {k: np.array(x) for k, x in np.load(out1 / "leaves" / "oak-001" / "view.npz").items()}
    far["positions"][:, 2] -= 500.0 * float(far["length"])  # a free leaf that fell far is still a leaf
    with open(tmp_path / "far.npz", "wb") as f:
        np.savez(f, **far)
    load_view(tmp_path / "far.npz")
    assert far["vein_colours"].shape == far["colours"].shape  # the veins' own colour is kept
    old = {k: x for k, x in far.items() if k != "vein_colours"}  # a leaf finished before it was
    with open(tmp_path / "old.npz", "wb") as f:
        np.savez(f, **old)
    load_view(tmp_path / "old.npz")
    with open(tmp_path / "badvein.npz", "wb") as f:
        np.savez(f, **{**far, "vein_colours": far["vein_colours"][:-1]})
    with pytest.raises(LeafsimError, match="array 'vein_colours'"):
        load_view(tmp_path / "badvein.npz")
    for damage in ("junk view", "nan positions", "no triangles", "bad index", "nan water", "string frames"):
        out = tmp_path / damage.replace(" ", "_")
        shutil.copytree(out1, out)
        leaf = out / "leaves" / "oak-001"
        view, done = leaf / "view.npz", leaf / "done.json"
        v = {k: np.array(x) for k, x in np.load(view).items()}
        d = json.loads(done.read_text())
        if damage == "junk view":
            view.write_bytes(b"not a zip file")
        elif damage == "nan positions":
            v["positions"][0, 0] = np.nan
        elif damage == "no triangles":
            del v["triangles"]
        elif damage == "bad index":
            v["triangles"][0, 0] = len(v["positions"])
        elif damage == "nan water":
            d["water_left"] = float("nan")
        else:
            d["frames"] = "abc"
        if damage != "junk view" and damage.split()[-1] not in ("water", "frames"):
            with open(view, "wb") as f:
                np.savez(f, **v)
        done.write_text(json.dumps(d))
        with pytest.raises(LeafsimError, match=str(leaf.name)):
            load_view(view)
            check_done(done)
        if damage not in ("junk view", "nan water"):
            continue  # (one damaged file of each kind is enough to show the rerun)
        rep = run_scene(scene, out, workers=1, progress=False)
        assert rep["ran"] == 1 and rep["skipped"] == 2 and rep["failed"] == [], (damage, rep)
        assert _files(out) == ref, damage


@pytest.mark.parametrize("foreign", ["folder", "pipe", "file", "symlink", "leaf is a file", "frames is a file"])
def test_a_leaf_folder_with_anything_of_the_users_is_refused_untouched(one_worker, tmp_path, foreign):
    """A leaf's folder is replaced only when it holds nothing but leafsim's own files: a folder,
    named pipe, symlink or other file of the user's there (or a file where the leaf's folder or
    its frames folder goes) is one line, exit 2, before any leaf runs, and stays as it was (the
    folder was removed with everything in it)."""
    import os
    import shutil

    scene, out1, _ = one_worker
    out = tmp_path / "out"
    shutil.copytree(out1, out)
    leaf = out / "leaves" / "oak-000"
    (leaf / "done.json").write_text("{}")  # so the leaf is simulated again
    if foreign == "folder":
        (leaf / "mydata").mkdir()
        (leaf / "mydata" / "precious.txt").write_text("precious")
        thing = leaf / "mydata" / "precious.txt"
    elif foreign == "pipe":
        os.mkfifo(leaf / "notes")
        thing = leaf / "notes"
    elif foreign == "file":
        (leaf / "notes.txt").write_text("precious")
        thing = leaf / "notes.txt"
    elif foreign == "symlink":
        (tmp_path / "elsewhere.txt").write_text("precious")
        (leaf / "state.npz").unlink()
        (leaf / "state.npz").symlink_to(tmp_path / "elsewhere.txt")
        thing = tmp_path / "elsewhere.txt"
    elif foreign == "leaf is a file":
        shutil.rmtree(leaf)
        leaf.write_text("precious")
        thing = leaf
    else:
        shutil.rmtree(leaf / "frames")
        (leaf / "frames").write_text("precious")
        thing = leaf / "frames"
    before = {str(p): (p.is_symlink(), p.read_bytes() if p.is_file() and not p.is_fifo() else None)
              for p in out.rglob("*") if p.name != "done.json"}
    r = subprocess.run([sys.executable, "-m", "leafsim", "scene", str(scene.path), "--out", str(out), "--workers", "1"],
                       cwd=ROOT, capture_output=True, text=True, timeout=HANG_S)
    assert r.returncode == 2 and "Traceback" not in r.stderr and r.stderr.count("\n") == 1, r.stderr
    assert "oak-000" in r.stderr and "leafsim" in r.stderr
    after = {str(p): (p.is_symlink(), p.read_bytes() if p.is_file() and not p.is_fifo() else None)
             for p in out.rglob("*") if p.name != "done.json"}
    assert after == before and (thing.exists() or thing.is_symlink())


def test_changed_group_reruns_only_its_leaves(one_worker, tmp_path):
    scene, out1, _ = one_worker
    import shutil

    out = tmp_path / "out"
    shutil.copytree(out1, out)
    changed = _scene(tmp_path, groups=[json.loads(scene.path.read_text())["groups"][0],
                                       {"name": "chestnut", "species": "chestnut", "count": 1, "seed": 3,
                                        "params": dict(TINY), "stop": {"frames": 5}}])
    rep = run_scene(load_scene(changed), out, workers=1, progress=False)
    assert rep["ran"] == 1 and rep["skipped"] == 2
    assert json.loads((out / "leaves" / "chestnut-000" / "done.json").read_text())["frames"] == 5


@pytest.mark.slow
def test_dask_local_cluster_gives_the_same_bytes(one_worker, tmp_path):
    from distributed import LocalCluster

    scene, out1, _ = one_worker
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        rep = run_scene(scene, tmp_path / "out", scheduler=cluster.scheduler_address, progress=False)
    assert rep["ran"] == 3 and rep["scheduler"] == cluster.scheduler_address
    a, b = _files(out1), _files(tmp_path / "out")
    assert a.keys() == b.keys() and all(a[k] == b[k] for k in a)


def test_failed_leaf_is_reported_by_name_and_the_others_finish(tmp_path):
    path = _scene(tmp_path, groups=[
        {"name": "ok", "species": "chestnut", "count": 2, "seed": 0, "params": dict(TINY), "stop": {"frames": 10}},
        {"name": "stuck", "species": "chestnut", "count": 1, "seed": 0, "params": dict(TINY),
         "stop": {"water_left": 0.001, "max_frames": 15}}])
    r = subprocess.run([sys.executable, "-m", "leafsim", "scene", str(path), "--out", str(tmp_path / "out"),
                        "--workers", "2", "--json"], capture_output=True, text=True, timeout=HANG_S)
    assert r.returncode == 1
    rep = json.loads(r.stdout)
    assert [f["name"] for f in rep["failed"]] == ["stuck-000"] and "not reached within max_frames = 15" in rep["failed"][0]["error"]
    assert rep["ran"] == 2 and rep["leaves_per_s"] == pytest.approx(2 / rep["simulate_s"], rel=2e-3)  # (the failed leaf was counted)
    assert "stuck-000" in r.stderr.strip().splitlines()[-1] and "Traceback" not in r.stderr
    leaves = tmp_path / "out" / "leaves"
    assert sorted(p.name for p in leaves.iterdir()) == ["ok-000", "ok-001"]  # nothing of the failed leaf
    assert not list((tmp_path / "out").rglob("*.tmp"))


def test_a_leaf_that_blows_up_fails_alone_and_leaves_no_files(tmp_path, monkeypatch):
    """NaN in the state (forced: the physics is stable) → a per-leaf failure, its folder removed."""
    from leafsim.sim.simulator import Simulator

    scene = load_scene(_scene(tmp_path))
    job = scene.jobs[2]
    step = Simulator.step

    def exploding(self, state):
        ms = step(self, state)
        if state.frame == 30:
            state.particle_q[0, 0] = np.nan
        return ms

    monkeypatch.setattr(Simulator, "step", exploding)
    job = type(job)(**{**job.__dict__, "stop": {"kind": "frames", "value": 200, "max_frames": 200}})
    res = run_leaf(job, tmp_path / "out")
    assert res["ok"] is False and res["name"] == "chestnut-000"
    # a kernel trips ("blew up at frame 31"), the watchdog's NaN check (every few frames) or the
    # scene's own (every FINITE_CHECK_EVERY frames)
    err = res["error"]
    assert "blew up" in err or "NaN/Inf" in err
    assert int(re.search(r"frame (\d+)", err).group(1)) <= 64
    assert not (tmp_path / "out" / "leaves" / "chestnut-000").exists()


BAD = [
    ({"colour": 1}, "key 'colour': unknown key"),
    # every leaf was simulated and written, then printing the name was an internal error
    ({"name": "tiny\ud800"}, "key 'name': expected text that UTF-8 can write"),
    ({"name": "tiny\nsecond"}, "key 'name': expected one line of printable text"),
    ({"groups": [{"name": "a", "species": "birch", "count": 1, "stop": {"frames": 1}}]}, "group 'a', key 'species': unknown species 'birch'"),
    ({"groups": [{"name": "a", "count": 1, "stop": {"frames": 1}}]}, "group 'a', key 'species': missing: every group names a species"),
    ({"config": "nope.json"}, "key 'config': species config "),
    ({"groups": [{"name": "a", "species": "oak", "count": -3, "stop": {"frames": 1}}]}, "group 'a', key 'count': expected an integer in [1, 10000], got -3"),
    ({"groups": [{"name": "a", "species": "oak", "count": 1, "stop": {"frames": 1}, "lod": {"simulate": 0.05, "show": 0.07}}]}, "key 'lod.show'"),
    ({"groups": [{"name": "a", "species": "oak", "count": 1, "stop": {"frames": 1, "season": 1}}]}, "key 'stop': expected exactly one"),
    ({"groups": [{"name": "a", "species": "oak", "count": 1, "stop": {"frames": 1}, "params": {"mesh.spacingg": 1}}]}, "unknown parameter 'mesh.spacingg'"),
    ({"groups": [{"name": "a", "species": "oak", "count": 1, "stop": {"frames": 1}, "effects": ["wind"]}]}, "key 'effects'"),
    ({"groups": [{"name": "a", "species": "oak", "count": 1, "stop": {"frames": 1}, "effects": []}]}, "key 'effects': expected a non-empty list"),
    ({"groups": [{"name": "a", "species": "oak", "count": 1, "stop": {"frames": 1}, "output": {"mesh": "obj", "every": 5}}]}, "key 'output.mesh'"),
    ({"layout": {"kind": "floor", "size": [0.1]}}, "key 'layout.size'"),
    # a glTF texture cannot change with the key frames: refused before any leaf dries
    ({"groups": [{"name": "a", "species": "oak", "count": 1, "stop": {"frames": 1},
                  "output": {"mesh": "glb", "every": 5, "texture": "baked"}}]}, "key 'output.texture': 'baked' holds one state"),
    ({"groups": [{"name": "a", "species": "oak", "count": 1, "stop": {"frames": 1},
                  "output": {"mesh": "ply", "texture": "baked"}}]}, "key 'output.texture': PLY carries vertex colours"),
    # options that were dropped without a word: the mesh's options without a mesh, and a group
    # mesh spacing the level of detail overrode
    ({"groups": [{"name": "a", "species": "oak", "count": 1, "stop": {"frames": 1},
                  "output": {"texture": "photo"}}]}, "key 'output.texture': an option of the exported mesh, but output.mesh is null"),
    ({"groups": [{"name": "a", "species": "oak", "count": 1, "stop": {"frames": 1},
                  "output": {"veins": True}}]}, "key 'output.veins': an option of the exported mesh"),
    ({"groups": [{"name": "a", "species": "oak", "count": 1, "stop": {"frames": 1}, "params": {"mesh.spacing": 0.05},
                  "lod": {"simulate": 0.07, "show": 0.035}}]}, "key 'lod': sets the meshes (simulate 0.07, show 0.035), and params sets mesh.spacing = 0.05"),
]


def test_a_scene_leaf_exported_with_a_baked_texture(tmp_path):
    """``output.texture = baked``: each leaf's mesh carries its colour (with the sub-grid
    mottle) as a texture the glTF-Validator accepts."""
    from helpers.gltf import assert_clean

    path = _scene(tmp_path, name="baked", groups=[
        {"name": "oak", "species": "oak", "count": 1, "seed": 2, "params": {**TINY, "colour.age_rate": 10.0},
         "stop": {"frames": 60}, "output": {"mesh": "glb", "texture": "baked", "veins": True}}])
    rep = run_scene(load_scene(path), tmp_path / "out", workers=1, progress=False)
    assert rep["failed"] == []
    glb = tmp_path / "out" / "leaves" / "oak-000" / "leaf.glb"
    assert_clean(glb)
    data = glb.read_bytes()
    doc = json.loads(data[20:20 + int.from_bytes(data[12:16], "little")])
    names = [im["name"] for im in doc["images"]]
    assert names[0] == "baked" and names[1:] in ([], ["crinkle"])  # the drying lamina's crinkle as a normal map
    if names[1:]:
        blade = next(m for m in doc["meshes"] if m["name"] == "blade")["primitives"][0]
        mat = doc["materials"][blade["material"]]
        assert doc["textures"][mat["normalTexture"]["index"]]["source"] == 1 and "TANGENT" in blade["attributes"]
    import cv2

    img = doc["images"][0]
    bv = doc["bufferViews"][img["bufferView"]]
    start = 28 + int.from_bytes(data[12:16], "little") + bv["byteOffset"]  # the BIN chunk's data
    png = cv2.imdecode(np.frombuffer(data[start:start + bv["byteLength"]], np.uint8), cv2.IMREAD_COLOR).astype(np.float32)
    assert (png - cv2.GaussianBlur(png, (0, 0), 3.0)).std() > 1.0  # the turning leaf's flecks, not a flat colour
    # an OBJ writes leaf_baked.png beside it: a file of the leaf's own, so a leaf run again (its
    # last run stopped before done.json) clears it instead of refusing the folder
    obj = _scene(tmp_path, name="baked_obj", groups=[
        {"name": "oak", "species": "oak", "count": 1, "seed": 2, "params": dict(TINY), "stop": {"frames": 2},
         "output": {"mesh": "obj", "texture": "baked"}}])
    leaf = tmp_path / "out_obj" / "leaves" / "oak-000"
    for _ in range(2):
        rep = run_scene(load_scene(obj), tmp_path / "out_obj", workers=1, progress=False)
        assert rep["failed"] == [] and rep["ran"] == 1, rep
        assert (leaf / "leaf_baked.png").is_file()
        (leaf / "done.json").unlink()


def test_a_scene_leaf_is_exported_in_its_species_colour_and_its_photo_ages(tmp_path):
    """A scene's photo species is exported as ``leafsim export`` writes it: the photo's own
    young colour (not the palette's), and with ``texture: photo`` the factor the ageing
    multiplies the photo by (``_AGEING``) moves with the drying (the shipped close-up's oak kept
    the fresh photo throughout: every factor 1, every delta 0)."""
    from helpers.gltf import assert_clean
    from leafsim.export.blender_import import colour_morphs

    params = {**TINY, "colour.age_rate": 10.0}
    groups = [{"name": "oak", "species": "oak", "count": 1, "seed": 2, "params": params, "stop": {"frames": 60},
               "output": {"mesh": "glb", "every": 20, "texture": tex}} for tex in ("colours", "photo")]
    groups[1]["name"] = "oak_photo"
    path = _scene(tmp_path, name="colour", groups=groups)
    rep = run_scene(load_scene(path), tmp_path / "out", workers=1, progress=False)
    assert rep["failed"] == []
    leaves = tmp_path / "out" / "leaves"
    photo = colour_morphs(leaves / "oak_photo-000" / "leaf.glb")["blade"]
    assert photo["photo_factor"]
    last = np.asarray(photo["colours"])  # the base mesh is the last key frame
    first = last + np.asarray(photo["deltas"][0])
    assert np.allclose(first, 1.0, atol=1e-5)  # the fresh leaf is the photo itself
    assert np.abs(last - 1.0).max() > 0.05  # and the photo ages with the leaf
    assert_clean(leaves / "oak_photo-000" / "leaf.glb")
    # the fresh leaf's colours are the CLI's for the same leaf (its seed from the file's extras)
    glb = leaves / "oak-000" / "leaf.glb"
    data = glb.read_bytes()
    nodes = json.loads(data[20:20 + int.from_bytes(data[12:16], "little")])["nodes"]
    seed = next(n["extras"]["leafsim"]["seed"] for n in nodes if "leafsim" in n.get("extras", {}))
    cli = tmp_path / "cli.glb"
    r = subprocess.run([sys.executable, "-m", "leafsim", "export", "--species", "oak", "--seed", str(seed),
                        "--set", "mesh.spacing=0.08", "--set", "colour.age_rate=10", "--frames", "0", "--texture", "colours", "--out", str(cli)],
                       capture_output=True, text=True, timeout=HANG_S)
    assert r.returncode == 0, r.stderr
    scene = colour_morphs(glb)["blade"]
    fresh = np.asarray(scene["colours"]) + np.asarray(scene["deltas"][0])
    doc, blob = _glb_doc(cli)
    prim = next(m for m in doc["meshes"] if m["name"] == "blade")["primitives"][0]
    acc = doc["accessors"][prim["attributes"]["COLOR_0"]]
    bv = doc["bufferViews"][acc["bufferView"]]
    c = np.frombuffer(blob, np.float32, acc["count"] * 4 if acc["type"] == "VEC4" else acc["count"] * 3,
                      bv.get("byteOffset", 0) + acc.get("byteOffset", 0)).reshape(acc["count"], -1)[:, :3]
    assert np.allclose(fresh, c, atol=1e-5)


def _glb_doc(path):
    data = Path(path).read_bytes()
    n = int.from_bytes(data[12:16], "little")
    doc = json.loads(data[20:20 + n])
    return doc, data[28 + n:]


@pytest.mark.parametrize("over,msg", BAD)
def test_bad_scene_files_give_one_line_errors(tmp_path, over, msg):
    path = _scene(tmp_path, stem="bad", **over)
    with pytest.raises(LeafsimError) as e:
        load_scene(path)
    text = str(e.value)
    assert text.startswith(str(path)) and msg in text and "\n" not in text


def test_cli_bad_input_exit_2_and_no_files(tmp_path):
    cases = []
    bad = tmp_path / "bad.json"
    bad.write_text('{"groups": [ ')
    cases.append(([str(bad), "--out", str(tmp_path / "bad")], "malformed JSON"))
    neg = _scene(tmp_path, name="neg", groups=[{"name": "a", "species": "oak", "count": -1, "stop": {"frames": 1}}])
    cases.append(([str(neg), "--out", str(tmp_path / "neg")], "key 'count'"))
    quoted = _scene(tmp_path, name="quoted", groups=[{"name": "a", "species": "oak", "count": 1, "params": {"mesh.spacing": "0.08"},
                                                       "stop": {"frames": 1}}])
    cases.append(([str(quoted), "--out", str(tmp_path / "neg")], "parameter 'mesh.spacing' = \"0.08\" is a string"))
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    cases.append(([str(_scene(tmp_path)), "--out", str(blocker / "out")], "a_file is a file, not a folder"))
    cases.append(([str(_scene(tmp_path)), "--out", str(blocker)], "exists and is not a folder"))
    cases.append(([str(_scene(tmp_path)), "--workers", "0", "--out", str(tmp_path / "w0")], "--workers 0"))
    cases.append(([str(_scene(tmp_path)), "--scheduler", "", "--out", str(tmp_path / "s0")], "--scheduler ''"))
    # reached before anything is made (it left OUT/leaves/ behind)
    cases.append(([str(_scene(tmp_path)), "--scheduler", "notaurl", "--out", str(tmp_path / "s1")],
                  "cannot connect to the Dask scheduler"))
    for args, msg in cases:
        r = subprocess.run([sys.executable, "-m", "leafsim", "scene", *args], capture_output=True, text=True, timeout=HANG_S,
                           cwd=tmp_path)
        assert r.returncode == 2 and msg in r.stderr and len(r.stderr.strip().splitlines()) == 1, (args, r.stderr)
    assert not (tmp_path / "w0").exists() and not (tmp_path / "neg").exists() and not (tmp_path / "out").exists()
    assert not (tmp_path / "s0").exists() and not (tmp_path / "s1").exists()


def test_shipped_scenes_load_and_say_what_they_promise():
    canopy = load_scene(ROOT / "configs" / "scenes" / "autumn_canopy.json")
    assert len(canopy.jobs) >= 200 and all(j.effects == ("colour",) and j.stop["kind"] == "season" for j in canopy.jobs)
    assert len({j.stop["value"] for j in canopy.jobs}) > 100  # each leaf its own season
    floor = load_scene(ROOT / "configs" / "scenes" / "forest_floor.json")
    assert floor.layout["kind"] == "floor" and all(j.lod and j.stop["kind"] == "water_left" and j.output["every"] == 0
                                                    for j in floor.jobs)
    close = load_scene(ROOT / "configs" / "scenes" / "close_up.json")
    assert all(j.lod is None and j.output["every"] > 0 and j.output["mesh"] == "glb" and not j.overrides.get("mesh.spacing")
               for j in close.jobs)


def test_overview_image_shows_every_leaf(tmp_path):
    from leafsim.scene.placement import load_views

    scene = load_scene(_scene(tmp_path, overview={"width": 320, "height": 240, "pitch": 90},
                              groups=[{"name": "c", "species": "chestnut", "count": 3, "seed": 0, "params": dict(TINY),
                                       "stop": {"frames": 2}}],
                              layout={"kind": "row", "gap": 0.05}))
    run_scene(scene, tmp_path / "out", workers=1, progress=False)
    import cv2

    img = cv2.imread(str(tmp_path / "out" / "overview.png"))
    assert img.shape == (240, 320, 3)
    sat = cv2.cvtColor(img, cv2.COLOR_BGR2HSV)[:, :, 1]
    n, _, st, _ = cv2.connectedComponentsWithStats((sat > 80).astype(np.uint8))
    blobs = sorted(st[1:, cv2.CC_STAT_AREA])
    assert len(blobs) == 3 and blobs[0] > 500, blobs  # three green leaves, side by side, none lost
    assert len(load_views(tmp_path / "out", scene.jobs)) == 3


def test_every_file_a_leaf_export_writes_is_one_the_scene_may_replace():
    """A leaf's folder is cleared file by file, only of the files leafsim writes there: every
    name an export of ``leaf.FMT`` writes beside it (a glTF's buffer, an OBJ's material, texture
    and crinkle normal map) is among them (the normal map was not: a re-run refused the folder)."""
    from leafsim.export.mesh import FORMATS, TEXTURES, side_files
    from leafsim.scene.layout import _LEAF_FILES

    for fmt in FORMATS:
        for texture in TEXTURES:
            for path in [Path(f"leaf.{fmt}"), *(p for p, _ in side_files(Path(f"leaf.{fmt}"), fmt, texture))]:
                assert _LEAF_FILES.fullmatch(path.name), (fmt, texture, path.name)


def test_more_worker_processes_than_cpus_warns_in_one_line_and_runs(tmp_path):
    """More worker processes than the CPUs this process may use (here one, by affinity): one
    warning line, the scene still runs; a pool never has more processes than leaves, so a
    one-leaf scene with --workers 999 runs one process and says nothing."""
    import os

    one_cpu = lambda: os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # noqa: E731
    leaf = {"species": "chestnut", "seed": 3, "params": dict(TINY), "stop": {"water_left": 0.99}}
    for count, workers, warned in ((2, 2, True), (1, 999, False)):
        path = _scene(tmp_path, name=f"n{count}", groups=[{"name": "c", "count": count, **leaf}])
        r = subprocess.run([sys.executable, "-m", "leafsim", "scene", str(path), "--out", str(tmp_path / f"out{count}"),
                            "--workers", str(workers), "--json"], capture_output=True, text=True, timeout=HANG_S,
                           cwd=tmp_path, preexec_fn=one_cpu)
        assert r.returncode == 0, r.stderr
        warnings = [line for line in r.stderr.splitlines() if "warning" in line]
        if warned:
            assert len(warnings) == 1 and "--workers 2 is more than the CPUs this process may use (1)" in warnings[0], r.stderr
        else:
            assert warnings == [], r.stderr
        assert json.loads(r.stdout)["ran"] == count


def test_a_leaf_dropped_from_the_scene_is_named_not_removed(tmp_path, capsys):
    """Lowering a group's count leaves the dropped leaf's folder on disk (only leafsim's files of
    the scene's own leaves are ever replaced): the run names it, as ``stray_leaves`` and on
    stderr, since a batch import of leaves/*/ would still pick it up."""
    groups = [{"name": "c", "species": "chestnut", "count": 2, "seed": 3, "params": dict(TINY), "stop": {"frames": 2}}]
    run_scene(load_scene(_scene(tmp_path, name="two", groups=groups)), tmp_path / "out", progress=False, render=False)
    groups[0]["count"] = 1
    rep = run_scene(load_scene(_scene(tmp_path, name="two", groups=groups)), tmp_path / "out", progress=False, render=False)
    assert rep["stray_leaves"] == ["c-001"] and rep["skipped"] == 1
    assert (tmp_path / "out" / "leaves" / "c-001" / "done.json").is_file()  # left as it was
    assert "not a leaf of this scene (c-001)" in capsys.readouterr().err
    assert [p["name"] for p in json.loads((tmp_path / "out" / "placement.json").read_text())["leaves"]] == ["c-000"]


def test_the_blender_addon_reads_a_scene_s_leaves_and_placement(one_worker):
    """The add-on imports a whole scene from its placement.json (File → Import, or
    import_leafsim(folder)): every leaf's mesh file and its placement as a 4 × 4 matrix, read
    with the standard library (Blender itself is not here; checked in Blender 4.2: each leaf's
    root lands at its translation with its rotation, to 4e-7)."""
    from leafsim.export.blender_import import scene_leaves

    scene, out, _ = one_worker
    placed = {p["name"]: p for p in json.loads((out / "placement.json").read_text())["leaves"]}
    leaves = scene_leaves(out)
    assert [n for n, _, _ in leaves] == list(placed) and leaves == scene_leaves(out / "placement.json")
    for name, mesh, m in leaves:
        R, t = np.array(placed[name]["rotation"]), np.array(placed[name]["translation"])
        assert np.allclose(np.array(m)[:3, :3], R) and np.allclose(np.array(m)[:3, 3], t) and m[3] == [0, 0, 0, 1]
        group = next(j for j in scene.jobs if j.name == name).output["mesh"]
        assert (mesh is None) == (group is None) and (mesh is None or mesh == out / "leaves" / name / f"leaf.{group}")


def test_the_default_output_folder_is_made(tmp_path):
    """Without --out a scene writes to out/NAME, making out/ (the check that --out's parent
    exists refused the documented `leafsim scene configs/scenes/close_up.json`)."""
    path = _scene(tmp_path, name="dflt", groups=[{"name": "c", "species": "chestnut", "count": 1, "seed": 3,
                                                   "params": dict(TINY), "stop": {"frames": 2}}])
    r = subprocess.run([sys.executable, "-m", "leafsim", "scene", str(path), "--workers", "1"], cwd=tmp_path,
                       capture_output=True, text=True, timeout=HANG_S)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "out" / "dflt" / "placement.json").is_file()


def test_a_species_warning_is_said_once_by_a_scene_on_two_workers(tmp_path):
    """A photo without a stalk (its base guessed from the shape) warns once, as the scene plans
    its leaves, in leafsim's own line; the worker processes that build the same species again
    printed it once more each in Python's raw form (file, line and source)."""
    import subprocess
    import sys

    from helpers.leafimg import photo
    from helpers.paths import HANG_S, REPO

    import cv2

    img, _ = photo(400, obovate=False, petiole=0.0)
    img = np.clip(img + np.random.default_rng(0).normal(0.0, 4.0, (400, 400, 1)), 0, 255).astype(np.uint8)
    cv2.imwrite(str(tmp_path / "bare.png"), img)
    (tmp_path / "leaves.json").write_text(json.dumps({"species": {"bare": {"name": "Bare", "image": "bare.png",
                                                                           "length_m": 0.06}}}))
    scene = _scene(tmp_path, name="bare", config="leaves.json", groups=[
        {"name": "bare", "species": "bare", "count": 2, "seed": 1, "params": dict(TINY), "stop": {"frames": 3},
         "output": {"mesh": None}}])
    out = subprocess.run([sys.executable, "-m", "leafsim", "scene", str(scene), "--out", str(tmp_path / "out"),
                          "--workers", "2"], capture_output=True, text=True, timeout=HANG_S, cwd=REPO)
    assert out.returncode == 0, out.stderr[-800:]
    lines = [ln for ln in out.stderr.splitlines() if "no stalk was found" in ln]
    assert len(lines) == 1 and lines[0].startswith("leafsim: warning: "), out.stderr[-800:]
    assert "warnings.warn" not in out.stderr and "LeafsimWarning" not in out.stderr
