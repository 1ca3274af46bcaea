"""Property-based tests (hypothesis) of the error contract: random ``--set`` values, random
species configs and outlines, odd images.  Invariants: bad input gives exactly one line on
stderr naming what is wrong, exit status 2 and no traceback; good input is accepted and what is
accepted is sound (a valid outline, a traced leaf inside the image).

Tiny inputs only (the whole module takes seconds); ``HYPOTHESIS_PROFILE=nightly`` runs the
longer profile registered in conftest.py.
"""

from __future__ import annotations

import atexit
import contextlib
import io
import json
import math
import os
import shutil
import tempfile
from pathlib import Path

import cv2
import numpy as np
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from helpers.cli_contract import stdout_of_a_failure
from leafsim.base.errors import LeafsimError
from leafsim.base.geometry import crossing_pairs, distance_to_polygon, points_in_polygon
from leafsim.cli import main
from leafsim.config.params import PARAMS, ParamSet, parse_set_args
from leafsim.config.species import load_library
from leafsim.pipeline import leaf_shape

NAMES = sorted(PARAMS)
TMP = Path(tempfile.mkdtemp(prefix="leafsim-hyp-"))
atexit.register(shutil.rmtree, TMP, True)


def run_cli(argv):
    """``leafsim ARGV`` in-process: (exit status, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return code, out.getvalue(), err.getvalue()


def assert_contract(code, out, err, *needles):
    """Exit 2, nothing on stdout, one line on stderr naming ``needles``, no traceback."""
    assert code == 2, (code, err)
    stdout_of_a_failure(code, out, err)
    assert err.startswith("leafsim: ") and err.endswith("\n") and err.count("\n") == 1, repr(err)
    assert "Traceback" not in err and "internal error" not in err, err
    for n in needles:
        assert n in err, (n, err)


# ------------------------------------------------------------------ --set values

def _valid_value(p):
    if p.kind == "bool":
        return st.sampled_from(["true", "false", "on", "off", "1", "0", "yes", "no"])
    if p.kind == "choice":
        return st.sampled_from(p.choices)
    if p.kind == "int":
        return st.integers(int(p.lo), int(p.hi)).map(str)
    return st.floats(p.lo, p.hi, allow_nan=False).map(repr)


def _invalid_value(p):
    junk = st.text(min_size=0, max_size=12).filter(lambda t: t.strip().lower() not in
                                                   ("true", "false", "1", "0", "on", "off", "yes", "no") + p.choices)
    if p.kind in ("bool", "choice"):
        return junk
    out_of_range = st.one_of(
        st.floats(max_value=p.lo, exclude_max=True, allow_nan=False, allow_infinity=False).filter(lambda v: v < p.lo).map(repr),
        st.floats(min_value=p.hi, exclude_min=True, allow_nan=False, allow_infinity=False).filter(lambda v: v > p.hi).map(repr),
    )
    special = st.sampled_from(["nan", "inf", "-inf", "1e400", "9" * 500, "", "0x10", "1,5", "True"])
    not_number = junk.filter(lambda t: not _is_number(t))
    fraction = st.floats(p.lo, p.hi).filter(lambda v: v != int(v)).map(repr) if p.kind == "int" else st.nothing()
    return st.one_of(out_of_range, special, not_number, fraction)


def _is_number(t):
    try:
        return math.isfinite(float(t))
    except (ValueError, OverflowError):
        return False


@given(st.sampled_from(NAMES).flatmap(lambda k: st.tuples(st.just(k), _valid_value(PARAMS[k]))))
def test_valid_set_values_are_accepted(kv):
    key, value = kv
    parsed = parse_set_args([f"{key}={value}"])
    p = PARAMS[key]
    v = parsed[key]
    if p.kind in ("float", "int"):
        assert p.lo <= v <= p.hi
    try:
        ParamSet(parsed)
    except LeafsimError as e:  # only a joint constraint may refuse a single valid value
        assert "break the rule" in str(e) and key in str(e) and "\n" not in str(e)


@given(st.sampled_from(NAMES).flatmap(lambda k: st.tuples(st.just(k), _invalid_value(PARAMS[k]))))
def test_invalid_set_values_one_line_exit_2(kv):
    key, value = kv
    assume("\x00" not in value)  # argv cannot carry NUL
    assert_contract(*run_cli(["veins", "--species", "oak", "--set", f"{key}={value}"]), key)


@given(st.text(min_size=1, max_size=30).filter(lambda k: k.strip() not in PARAMS and "=" not in k and "\x00" not in k))
def test_unknown_set_keys_one_line_exit_2(key):
    # ("--set -x=1": argparse reads the value as an option and says --set lacks its argument)
    assert_contract(*run_cli(["veins", "--set", f"{key}=1"]), "--set" if key.startswith("-") else "unknown parameter")


# ------------------------------------------------------------------ species configs

json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-10**30, 10**30) | st.floats(allow_nan=False) | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4),
    max_leaves=12,
)
ENTRY_KEYS = ["name", "latin", "description", "length_m", "outline", "targets", "main_origin", "lateral_profile",
              "params", "image", "base_px", "apex_px", "colour"]
GOOD = {"length_m": 0.1, "outline": {"points": [[0, 0], [0.3, 0.5], [0, 1], [-0.3, 0.5]]}}


def _write(data) -> Path:
    fd, name = tempfile.mkstemp(suffix=".json", dir=TMP)
    with open(fd, "w", encoding="utf-8") as f:
        f.write(data if isinstance(data, str) else json.dumps(data))
    return Path(name)


@given(st.dictionaries(st.sampled_from(ENTRY_KEYS + ["outline.points", "outline.teeth", "outline.smooth"]), json_values,
                       min_size=1, max_size=3))
def test_random_config_entries_load_or_fail_in_one_line(changes):
    entry = json.loads(json.dumps(GOOD))
    for k, v in changes.items():
        if k.startswith("outline."):
            if isinstance(entry.get("outline"), dict):
                entry["outline"][k.split(".", 1)[1]] = v
        else:
            entry[k] = v
    path = _write({"species": {"kite": entry}})
    code, out, err = run_cli(["species", "--config", str(path), "--json"])
    if code == 0:
        sp = load_library(path)["kite"]
        try:
            shape = leaf_shape(sp)
        except LeafsimError as e:
            assert "\n" not in str(e) and str(path) in str(e)
        else:  # what loads is a sound leaf
            assert len(crossing_pairs(shape.contour, np.roll(shape.contour, -1, axis=0))) == 0
    else:
        assert_contract(code, out, err, str(path))


@given(st.binary(max_size=200) | st.text(max_size=200).map(lambda t: t.encode("utf-8")))
def test_random_config_files(raw):
    fd, name = tempfile.mkstemp(suffix=".json", dir=TMP)
    with open(fd, "wb") as f:
        f.write(raw)
    code, out, err = run_cli(["species", "--config", name])
    assert_contract(code, out, err, name)  # nothing this short is a valid library


# ------------------------------------------------------------------ outlines

coords = st.floats(-2.0, 2.0, allow_nan=False, width=32)


@given(st.lists(st.tuples(coords, coords), min_size=3, max_size=9))
def test_random_outline_points(pts):
    entry = {"length_m": 0.1, "outline": {"points": [list(p) for p in pts]}}
    path = _write({"species": {"kite": entry}})
    code, out, err = run_cli(["species", "--config", str(path)])
    if code != 0:
        assert_contract(code, out, err, str(path), "outline")
        return
    c = np.array(pts, float)
    assert len(crossing_pairs(c, np.roll(c, -1, axis=0))) == 0  # accepted: simple
    shape = leaf_shape(load_library(path)["kite"])
    base = np.zeros((1, 2))
    assert points_in_polygon(base, shape.contour)[0] or distance_to_polygon(base, shape.contour)[0] <= 0.1 * shape.length


@given(st.integers(3, 12), st.floats(0.1, 1.5), st.floats(0.0, 0.6), st.integers(0, 2**31))
def test_star_shaped_outlines_are_accepted(half, width, wobble, seed):
    """A blade star-shaped about (0, 0.5), with the base (0, 0) and the apex (0, 1) on its
    margin, is always accepted, however irregular its radius."""
    rng = np.random.default_rng(seed)
    n = 2 * half
    theta = -np.pi / 2 + np.pi * np.arange(n) / half  # base first, apex at index `half`
    r = 0.5 * (1 + wobble * rng.uniform(-1, 1, n))
    r[0] = r[half] = 0.5
    pts = np.column_stack([width * r * np.cos(theta), 0.5 + r * np.sin(theta)])
    pts[0], pts[half] = (0.0, 0.0), (0.0, 1.0)
    path = _write({"species": {"kite": {"length_m": 0.1, "outline": {"points": pts.tolist()}}}})
    shape = leaf_shape(load_library(path)["kite"])
    assert shape.area > 0 and len(crossing_pairs(shape.contour, np.roll(shape.contour, -1, axis=0))) == 0


# ------------------------------------------------------------------ odd images

@given(st.integers(1, 48), st.integers(1, 48), st.sampled_from([1, 3, 4]), st.sampled_from(["u8", "u16"]),
       st.sampled_from(["noise", "flat", "blob"]), st.integers(0, 2**31))
def test_odd_images(w, h, ch, depth, content, seed):
    rng = np.random.default_rng(seed)
    hi = 255 if depth == "u8" else 65535
    dtype = np.uint8 if depth == "u8" else np.uint16
    shape = (h, w) if ch == 1 else (h, w, ch)
    if content == "noise":
        img = rng.integers(0, hi + 1, shape).astype(dtype)
    else:
        img = np.full(shape, int(rng.integers(0, hi + 1)), dtype)
        if content == "blob":
            m = np.zeros((h, w), np.uint8)
            cv2.ellipse(m, (w // 2, h // 2), (max(1, w // 3), max(1, h // 3)), 0, 0, 360, 255, -1)
            img[m > 0] = hi - img[m > 0]
    fd, name = tempfile.mkstemp(suffix=".png", dir=TMP)
    ok, buf = cv2.imencode(".png", img)
    assume(ok)
    with open(fd, "wb") as f:
        f.write(buf.tobytes())
    code, out, err = run_cli(["outline", name, "--json"])
    if code == 0:  # accepted: the leafness checks may warn (one line each), nothing else
        rep = json.loads(out)
        assert all(line.startswith("leafsim: warning: ") for line in err.splitlines()), err
        assert len(err.splitlines()) == len(rep["leafness"]["problems"])
        assert rep["size"] == [w, h] and 0 < rep["area_px"] <= w * h
    else:
        assert_contract(code, out, err, name)


@given(st.binary(min_size=0, max_size=300), st.sampled_from([b"", b"\x89PNG\r\n\x1a\n", b"\xff\xd8\xff", b"BM"]))
def test_random_bytes_as_image(body, magic):
    fd, name = tempfile.mkstemp(suffix=".png", dir=TMP)
    with open(fd, "wb") as f:
        f.write(magic + body)
    assert_contract(*run_cli(["outline", name]), name, "cannot read image")


# ------------------------------------------------------------------ special files and duplicate keys

@given(st.sampled_from(["fifo", "folder", "loop", "dangling"]), st.sampled_from(["species", "outline", "scene"]))
def test_special_files_as_inputs(kind, command):
    d = Path(tempfile.mkdtemp(dir=TMP))
    p = d / ("x.json" if command != "outline" else "x.png")
    if kind == "fifo":
        os.mkfifo(p)
    elif kind == "folder":
        p.mkdir()
    elif kind == "loop":
        p.symlink_to(d / "y")
        (d / "y").symlink_to(p)
    else:
        p.symlink_to(d / "nowhere")
    argv = {"species": ["species", "--config", str(p)], "outline": ["outline", str(p)], "scene": ["scene", str(p), "--out", str(d / "o")]}
    assert_contract(*run_cli(argv[command]), str(p))


@given(st.sampled_from(["top", "entry", "outline", "teeth"]), st.integers(0, 2**31))
def test_duplicate_keys_in_a_species_config(where, seed):
    rng = np.random.default_rng(seed)
    text = Path("configs/leaves.json").read_text()
    needle = {"top": '"species": {', "entry": '"length_m": ', "outline": '"points": [', "teeth": '"depth": '}[where]
    hits = [i for i in range(len(text)) if text.startswith(needle, i)]
    assume(hits)
    i = hits[int(rng.integers(len(hits)))]
    key = needle.split(":")[0]
    dup = text[:i] + f"{key}: 0, " + text[i:]  # the same key twice in one object
    p = TMP / f"dup_{seed}.json"
    p.write_text(dup)
    assert_contract(*run_cli(["species", "--config", str(p)]), "duplicate key", key.strip('"'))


# ------------------------------------------------------------------ damaged checkpoints

CK_OAK = ["run", "--species", "oak", "--set", "mesh.spacing=0.08", "--checkpoint-every", "2"]
_CK = {}


def _checkpoint() -> dict:
    if not _CK:
        out = TMP / "ck_source"
        code, _, err = run_cli(CK_OAK + ["--frames", "2", "--out", str(out)])
        assert code == 0, err
        _CK.update(np.load(out / "checkpoint.npz"))
    return _CK


@settings(max_examples=25, deadline=None, derandomize=True)
@given(st.sampled_from(["state_particle_q", "state_particle_qd", "state_particle_water", "state_spring_rest",
                        "state_hinge_rest", "state_vol_rest", "state_scalars", "pig_chlorophyll", "pig_leaf"]),
       st.sampled_from(["rows", "columns", "dtype", "nan", "inf", "negative", "huge", "empty"]), st.integers(0, 2**31))
def test_damaged_checkpoint_arrays_give_one_line(key, damage, seed):
    rng = np.random.default_rng(seed)
    d = {k: v.copy() for k, v in _checkpoint().items()}
    a = d[key]
    if damage == "rows":
        a = a[: max(len(a) - 1 - int(rng.integers(3)), 0)]
    elif damage == "columns":
        a = a.reshape(len(a), -1)[:, :1] if a.ndim == 2 and a.shape[1] > 1 else np.stack([a, a], -1)
    elif damage == "dtype":
        a = a.astype(rng.choice([np.float32, np.float16, np.int64]) if a.dtype != np.float32 else np.float64)
    elif damage == "empty":
        a = a[:0]
    else:
        a = a.astype(a.dtype)
        flat = a.reshape(-1)
        j = int(rng.integers(flat.size))
        flat[j] = {"nan": np.nan, "inf": np.inf, "negative": -abs(flat[j]) - 1.0, "huge": 1e30}[damage]
    d[key] = a
    folder = Path(tempfile.mkdtemp(dir=TMP))
    np.savez(folder / "checkpoint.npz", **d)
    code, out, err = run_cli(CK_OAK + ["--frames", "4", "--out", str(folder), "--resume"])
    if code == 0:  # some values are physical (a negative hinge angle, a huge-but-legal time is not)
        assert damage in ("negative",) and key in ("state_particle_q", "state_particle_qd", "state_hinge_rest", "state_vol_rest"), err
    else:
        assert_contract(code, out, err, "checkpoint")
