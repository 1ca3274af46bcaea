"""Scenes: many leaves, only the effects they call for, run in parallel (core: no OpenGL).

A scene file (JSON, strictly validated: every error names the file and the key) declares leaf
groups — species, count, seeds, effects, the stage at which to stop, level of detail and
outputs — and a layout that places the finished leaves (``docs/scenes.md`` has the format).
:func:`run_scene` turns the groups into one :class:`~leafsim.scene.job.LeafJob` per leaf,
skips the leaves a previous run finished, runs the rest on a local process pool or a Dask
cluster (same code, same bytes), then places the leaves (:mod:`leafsim.scene.placement`) and
renders an overview image offscreen (the only part that imports the renderer).

Example
-------
>>> scene = load_scene("configs/scenes/forest_floor.json")          # doctest: +SKIP
>>> report = run_scene(scene, "out/floor", workers=2)               # doctest: +SKIP
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
import signal
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from leafsim.base.errors import LeafsimError
from leafsim.base.fileio import atomic_write_bytes, no_folder, not_an_input, output_target, read_json, same_file
from leafsim.config.params import SEED_MAX, json_typed
from leafsim.export.mesh import FORMATS, LAYERS, TEXTURES
from leafsim.scene.job import LeafJob, check_done, is_done, run_leaf
from leafsim.scene.layout import leaf_dir, leaf_folder_entries
from leafsim.sim.run import MAX_RUN_FRAMES

_TOP_KEYS = {"name", "description", "seed", "config", "layout", "overview", "groups"}
_GROUP_KEYS = {"name", "species", "count", "seed", "seeds", "params", "effects", "stop", "lod", "output"}
_STOP_KEYS = {"frames", "water_left", "season", "max_frames"}
_LOD_KEYS = {"simulate", "show", "check"}
_OUTPUT_KEYS = {"end_state", "every", "mesh", "layers", "veins", "texture", "stats"}
_OVERVIEW_KEYS = {"width", "height", "pitch", "yaw"}
_LAYOUT_KEYS = {"floor": {"kind", "size", "cell", "clearance"},
                "canopy": {"kind", "radius", "height", "tilt"},
                "row": {"kind", "gap"}}
_NAME = re.compile(r"^[A-Za-z0-9_-]{1,40}$")
DEFAULT_MAX_FRAMES = 100_000
#: the most leaves one scene may hold, and what setting up each one costs before any
#: simulation (measured: a million leaves took 2.4 GB and 94 CPU s just to set up)
MAX_SCENE_LEAVES = 10_000
SETUP_BYTES_PER_LEAF = 2.4e3
SETUP_S_PER_LEAF = 9.4e-5
#: the floor layout's height field: at most this many cells (9 bytes each)
MAX_FLOOR_CELLS = 50_000_000


@dataclass(frozen=True)
class Scene:
    """A validated scene file: ``jobs`` (one per leaf, in placement order), ``layout`` and
    ``overview`` (dicts with every default filled in, or None for no image)."""

    path: Path
    name: str
    seed: int
    layout: dict
    overview: dict | None
    jobs: tuple
    #: the files the scene reads (the scene file, the species config, the groups' photos): no
    #: output may replace one
    inputs: tuple = ()


class _Where:
    """Builds one-line errors: ``FILE: group 'oak', key 'count': expected …``."""

    def __init__(self, path: Path, ctx: str = ""):
        self.path, self.ctx = path, ctx

    def sub(self, ctx: str) -> "_Where":
        return _Where(self.path, ctx)

    def err(self, key: str | None, msg: str) -> LeafsimError:
        where = ", ".join(x for x in (self.ctx, f"key '{key}'" if key else "") if x)
        return LeafsimError(f"{self.path}: {where + ': ' if where else ''}{msg}")

    def keys(self, obj, allowed: set, what: str, prefix: str = "") -> dict:
        if not isinstance(obj, dict):
            raise self.err(prefix.rstrip(".") or None, f"expected an object ({what})")
        bad = sorted(set(obj) - allowed)
        if bad:
            raise self.err(prefix + bad[0], f"unknown key (expected one of {', '.join(sorted(allowed))})")
        return obj

    def int(self, obj: dict, key: str, default, lo: int, hi: int | None = None, prefix: str = "") -> int:
        v = obj.get(key, default)
        if isinstance(v, bool) or not isinstance(v, int) or v < lo or (hi is not None and v > hi):
            rng = f"an integer ≥ {lo}" if hi is None else f"an integer in [{lo}, {hi}]"
            raise self.err(prefix + key, f"expected {rng}, got {v!r}")
        return v

    def num(self, obj: dict, key: str, default, lo: float, hi: float, prefix: str = "") -> float:
        v = obj.get(key, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (lo <= v <= hi):
            raise self.err(prefix + key, f"expected a number in [{lo:g}, {hi:g}], got {v!r}")
        return float(v)

    def range(self, obj: dict, key: str, default, lo: float, hi: float, prefix: str = "") -> tuple:
        """A number or an increasing [low, high] pair within [lo, hi]."""
        v = obj.get(key, default)
        pair = v if isinstance(v, list) else [v, v]
        ok = len(pair) == 2 and all(not isinstance(x, bool) and isinstance(x, (int, float)) and lo <= x <= hi for x in pair)
        if not ok or pair[0] > pair[1]:
            raise self.err(prefix + key, f"expected a number or a [low, high] pair in [{lo:g}, {hi:g}], got {v!r}")
        return float(pair[0]), float(pair[1])

    def choice(self, obj: dict, key: str, default, choices, prefix: str = ""):
        v = obj.get(key, default)
        if v not in choices:
            raise self.err(prefix + key, f"expected one of {', '.join(str(c) for c in choices)}, got {v!r}")
        return v

    def bool(self, obj: dict, key: str, default: bool, prefix: str = "") -> bool:
        v = obj.get(key, default)
        if not isinstance(v, bool):
            raise self.err(prefix + key, f"expected true or false, got {v!r}")
        return v


def _read_json(path: Path) -> dict:
    data = read_json(path, "scene file")
    if not isinstance(data, dict):
        raise LeafsimError(f"{path}: expected a JSON object with 'groups'")
    return data


def load_scene(path) -> Scene:
    """Read and validate a scene file (LeafsimError naming the file and key otherwise)."""
    from leafsim.config.species import load_library

    path = Path(path)
    data = _read_json(path)
    w = _Where(path)
    w.keys(data, _TOP_KEYS, "a scene")
    if not isinstance(data.get("description", ""), str):
        raise w.err("description", f"expected text, got {data['description']!r}")
    seed = w.int(data, "seed", 0, 0, SEED_MAX)
    config = data.get("config")
    if config is not None and not isinstance(config, str):
        raise w.err("config", "expected the path of a species config (relative to the scene file)")
    config_path = None if config is None else str((path.parent / config).resolve())
    if config_path is not None and not Path(config_path).is_file():
        what = "is not a file" if Path(config_path).exists() else "not found"
        raise w.err("config", f"species config {config_path} {what} (a relative path is read from the scene file's folder)")
    lib = load_library(config_path)
    digest = hashlib.sha256(Path(config_path or _default_config()).read_bytes()).hexdigest()[:16]
    groups = data.get("groups")
    if not isinstance(groups, list) or not groups:
        raise w.err("groups", "expected a non-empty list of leaf groups")
    jobs, names = [], set()
    for i, g in enumerate(groups):
        gw = w.sub(f"group {i + 1}" if not isinstance(g, dict) or not isinstance(g.get("name"), str) else f"group '{g['name']}'")
        jobs += _group_jobs(gw, g, lib, config_path, digest, names)
    if len(jobs) > MAX_SCENE_LEAVES:
        raise w.err("groups", f"the groups hold {_too_many(len(jobs))}")
    name = data.get("name", path.stem)
    if not isinstance(name, str):
        raise w.err("name", "expected a string")
    try:
        name.encode("utf-8")
    except UnicodeEncodeError:
        raise w.err("name", "expected text that UTF-8 can write (it holds a lone surrogate code point)") from None
    if not name.isprintable():
        raise w.err("name", f"expected one line of printable text, got {name!r}")
    species = [lib[k] for k in dict.fromkeys(j.species for j in jobs)]
    inputs = (path, Path(config_path or _default_config()),
              *(p for sp in species for p in (sp.image, sp.senescent.image if sp.senescent is not None else None) if p is not None))
    return Scene(path=path, name=name, seed=seed, layout=_layout(w, data.get("layout", {"kind": "row"})),
                 overview=_overview(w, data.get("overview", {})), jobs=tuple(jobs), inputs=inputs)


def _too_many(n: int) -> str:
    if n > 10 ** 15:  # beyond a float's reach (a count of 400 digits): no sizes to quote
        return f"{str(n)[:12]}… ({len(str(n))} digits) leaves: a scene holds at most {MAX_SCENE_LEAVES:,}"
    return (f"{n:,} leaves would need ≈ {n * SETUP_BYTES_PER_LEAF / 1e9:.2g} GB and {n * SETUP_S_PER_LEAF:.2g} CPU s "
            f"just to set up, before any simulation; a scene holds at most {MAX_SCENE_LEAVES:,} (split it into several scenes)")


def _default_config() -> Path:
    from leafsim.base.resources import default_config

    return default_config()


def _group_jobs(w: _Where, g, lib: dict, config: str | None, digest: str, names: set) -> list[LeafJob]:
    from leafsim.sim.effects import EFFECTS

    w.keys(g, _GROUP_KEYS, "a leaf group")
    name = g.get("name")
    if not isinstance(name, str) or not _NAME.match(name) or name in names:
        raise w.err("name", f"expected a unique group name of letters, digits, '_' or '-' (used in file names), got {name!r}")
    names.add(name)
    sp = g.get("species")
    if sp is None:
        raise w.err("species", f"missing: every group names a species of the config (known: {', '.join(sorted(lib))})")
    if sp not in lib:
        raise w.err("species", f"unknown species {sp!r} (known: {', '.join(sorted(lib))})")
    count = g.get("count")
    if isinstance(count, int) and not isinstance(count, bool) and count > MAX_SCENE_LEAVES:
        raise w.err("count", _too_many(count))
    count = w.int(g, "count", None, 1, MAX_SCENE_LEAVES)
    seeds = _seeds(w, g, count)
    params = g.get("params", {})
    if not isinstance(params, dict):
        raise w.err("params", "expected an object of parameter values")
    where = f"{w.path}: {w.ctx}, key 'params'"
    group_params = lib[sp].params.with_overrides(json_typed(params, where), where=where)
    effects = g.get("effects")
    if effects is not None:
        if not isinstance(effects, list) or not effects or any(e not in EFFECTS for e in effects):
            # [] would switch every effect off without a word: the leaves never changed
            raise w.err("effects", f"expected a non-empty list of effect names from {', '.join(EFFECTS)}, got {effects!r}")
        effects = tuple(effects)
    stop = _stop(w, g.get("stop"))
    # a criterion the group's effects cannot move is refused now, in one line (each leaf of the
    # group was built and then failed, a line per leaf, after the scene's files were begun)
    on = {e: (e in effects) if effects is not None else bool(group_params[f"effects.{e}"]) for e in EFFECTS}
    v = stop["value"]
    ahead = {"water_left": stop["kind"] == "water_left" and v < 1.0,  # (1, or the season it starts at: met at frame 0)
             "season": stop["kind"] == "season" and max(v) > float(group_params["colour.season"])}
    for kind, effect, what in (("water_left", "osmosis", "the water left cannot fall"),
                               ("season", "colour", "the season clock stands still")):
        if ahead[kind] and not on[effect]:
            key = "effects" if effects is not None else "params"
            raise w.err(f"stop.{kind}", f"cannot be reached: {what} with the effect '{effect}' off (its {key}); "
                                        f"switch '{effect}' on or stop after a number of frames")
    lod, check = _lod(w, g.get("lod"))
    if lod is not None and "mesh.spacing" in params and group_params["mesh.spacing"] != lod["simulate"]:
        # the level of detail sets both meshes: the group's other mesh.spacing was dropped without a word
        raise w.err("lod", f"sets the meshes (simulate {lod['simulate']:g}, show {lod['show']:g}), and params sets "
                           f"mesh.spacing = {group_params['mesh.spacing']:g}: leave params' mesh.spacing out (or "
                           "make it lod.simulate)")
    _check_budget(w, lib[sp], group_params, lod)
    output = _output(w, g.get("output", {}))
    if output["mesh"] and output["texture"] == "photo" and lib[sp].image is None:
        raise w.err("output.texture", f"'photo' needs a species with a photo; {sp!r} has a drawn outline (use 'colours')")
    jobs = []
    for k, s in enumerate(seeds):
        st = dict(stop)
        if st["kind"] == "season":  # a [low, high] range: each leaf's own season from its seed
            lo, hi = st["value"]
            st["value"] = float(lo + (hi - lo) * np.random.default_rng([s, 7]).random())
        jobs.append(LeafJob(name=f"{name}-{k:03d}", species=sp, config=config, overrides=dict(params), seed=s,
                            effects=effects, stop=st, lod=lod, check_lod=lod is not None and k < check,
                            output=output, config_digest=digest, meta={"group": name}))
    return jobs


def _check_budget(w: _Where, sp, params, lod: dict | None) -> None:
    """The group's finest mesh (``lod.show`` with a level of detail, else ``mesh.spacing``) within
    ``limits.max_particles`` and the machine's memory, checked now (every leaf of the group
    failed as it started, after the scene's files were begun)."""
    from leafsim.blade.budget import check_mesh_budget
    from leafsim.pipeline import leaf_shape

    key = "lod.show" if lod is not None else "params"
    p = params if lod is None else params.with_overrides({"mesh.spacing": lod["show"]})
    shape = leaf_shape(sp, p)  # (an outline that cannot be made says so itself)
    try:
        check_mesh_budget(shape, p)
    except LeafsimError as e:
        msg = str(e) if lod is None else str(e).replace("mesh.spacing", "lod.show")
        raise w.err(key, msg) from None


def _seeds(w: _Where, g: dict, count: int) -> list[int]:
    if "seeds" in g:
        s = g["seeds"]
        if "seed" in g:
            raise w.err("seeds", "give either 'seed' (the first of count consecutive seeds) or 'seeds', not both")
        if not isinstance(s, list) or len(s) != count or any(isinstance(x, bool) or not isinstance(x, int) or not 0 <= x <= SEED_MAX
                                                             for x in s):
            raise w.err("seeds", f"expected a list of {count} integers in [0, 2**63-1] (one per leaf)")
        return list(s)
    first = w.int(g, "seed", 0, 0, SEED_MAX - count + 1)
    return list(range(first, first + count))


def _stop(w: _Where, s) -> dict:
    if s is None:
        raise w.err("stop", "missing: give one of frames, water_left (dried to that water fraction) or season")
    w.keys(s, _STOP_KEYS, "a stopping criterion", "stop.")
    kinds = [k for k in ("frames", "water_left", "season") if k in s]
    if len(kinds) != 1:
        raise w.err("stop", f"expected exactly one of frames, water_left, season (got {', '.join(kinds) or 'none'})")
    k = kinds[0]
    mf = w.int(s, "max_frames", DEFAULT_MAX_FRAMES, 1, None, "stop.")
    if k == "frames":
        v = w.int(s, "frames", None, 0, MAX_RUN_FRAMES, "stop.")
        if "max_frames" in s and mf < v:  # (it was raised to stop.frames without a word)
            raise w.err("stop.max_frames", f"expected at least stop.frames = {v} (the frame budget of a leaf that stops "
                                           f"after {v} frames), got {mf}; or leave it out")
    elif k == "water_left":
        v = w.num(s, "water_left", None, 0.0, 1.0, "stop.")
    else:
        v = w.range(s, "season", None, 0.0, 10.0, "stop.")
    return {"kind": k, "value": v, "max_frames": max(mf, v) if k == "frames" else mf}


def _lod(w: _Where, lod) -> tuple[dict | None, int]:
    if lod is None:
        return None, 0
    w.keys(lod, _LOD_KEYS, "a level of detail", "lod.")
    sim = w.num(lod, "simulate", None, 0.002, 0.1, "lod.")
    show = w.num(lod, "show", None, 0.002, 0.1, "lod.")
    if show >= sim:
        raise w.err("lod.show", f"expected a finer mesh spacing than lod.simulate = {sim:g}, got {show:g}")
    return {"simulate": sim, "show": show}, w.int(lod, "check", 1, 0, None, "lod.")


def _output(w: _Where, o) -> dict:
    w.keys(o, _OUTPUT_KEYS, "the outputs", "output.")
    mesh = o.get("mesh")
    if mesh is not None and mesh not in FORMATS:
        raise w.err("output.mesh", f"expected null or one of {', '.join(FORMATS)}, got {mesh!r}")
    every = w.int(o, "every", 0, 0, None, "output.")
    if every and mesh in ("obj", "ply"):
        raise w.err("output.mesh", f"{mesh} holds one static shape; frames every K need glb or gltf")
    for k in ("layers", "veins", "texture"):
        if k in o and mesh is None:  # an option of the exported mesh, without one: it did nothing
            raise w.err(f"output.{k}", f"an option of the exported mesh, but output.mesh is null: set output.mesh "
                                       f"({', '.join(FORMATS)}) or leave output.{k} out")
    out = {"end_state": w.bool(o, "end_state", True, "output."), "every": every, "mesh": mesh,
           "layers": w.choice(o, "layers", "shell", LAYERS, "output."), "veins": w.bool(o, "veins", False, "output."),
           "texture": w.choice(o, "texture", "colours", TEXTURES, "output."), "stats": w.bool(o, "stats", False, "output.")}
    if out["texture"] != "colours" and mesh == "ply":
        raise w.err("output.texture", f"PLY carries vertex colours, not a {out['texture']} texture")
    if out["texture"] == "photo" and mesh == "obj":  # (leafsim export warns; a batch is refused, not a leaf at a time)
        raise w.err("output.texture", "'photo' in an OBJ is the photo as the leaf looked when photographed: an OBJ "
                                      "cannot carry its ageing (use 'baked', or mesh glb / gltf)")
    if out["texture"] == "baked" and every and mesh:
        # a glTF texture cannot change with the key frames: refused here, not after the leaves dried
        raise w.err("output.texture", "'baked' holds one state's colour; frames every K need 'colours'")
    return out


def _layout(w: _Where, lay) -> dict:
    if not isinstance(lay, dict) or lay.get("kind") not in _LAYOUT_KEYS:
        raise w.err("layout.kind", f"expected one of {', '.join(_LAYOUT_KEYS)}")
    kind = lay["kind"]
    w.keys(lay, _LAYOUT_KEYS[kind], f"a {kind} layout", "layout.")
    if kind == "floor":
        size = lay.get("size", [0.5, 0.5])
        if not isinstance(size, list) or len(size) != 2 or any(isinstance(x, bool) or not isinstance(x, (int, float)) or not 0.01 <= x <= 100 for x in size):
            raise w.err("layout.size", f"expected [x, y] in metres (0.01–100), got {size!r}")
        cell = w.num(lay, "cell", 0.002, 1e-4, 0.05, "layout.")
        cells = (size[0] / cell + 1) * (size[1] / cell + 1)
        if cells > MAX_FLOOR_CELLS:  # refused now, not after every leaf was simulated
            raise w.err("layout.cell", f"a {size[0]:g} × {size[1]:g} m floor in cells of {cell:g} m is {cells:.3g} cells "
                                       f"(≈ {9 * cells / 2**30:.3g} GiB for its height field), more than {MAX_FLOOR_CELLS:,}; "
                                       "use larger cells or a smaller floor")
        return {"kind": kind, "size": [float(x) for x in size], "cell": cell,
                "clearance": w.num(lay, "clearance", 0.0005, 0.0, 0.05, "layout.")}
    if kind == "canopy":
        return {"kind": kind, "radius": w.num(lay, "radius", 1.0, 0.05, 50.0, "layout."),
                "height": w.num(lay, "height", 3.0, 0.0, 100.0, "layout."),
                "tilt": list(w.range(lay, "tilt", [20.0, 70.0], 0.0, 90.0, "layout."))}
    return {"kind": kind, "gap": w.num(lay, "gap", 0.01, 0.0, 10.0, "layout.")}


def _overview(w: _Where, ov) -> dict | None:
    if ov is False:
        return None
    w.keys(ov, _OVERVIEW_KEYS, "the overview image (or false)", "overview.")
    return {"width": w.int(ov, "width", 1600, 64, 8192, "overview."), "height": w.int(ov, "height", 1000, 64, 8192, "overview."),
            "pitch": w.num(ov, "pitch", 55.0, -89.0, 90.0, "overview."), "yaw": w.num(ov, "yaw", -90.0, -360.0, 360.0, "overview.")}


# ------------------------------------------------------------------ running

def _no_input_in_leaf_folders(scene: Scene, out: Path) -> None:
    """LeafsimError when one of the scene's inputs lies in the folder of one of its leaves
    (``OUT/leaves/NAME/``, which a run of that leaf replaces); folders compared as files (the same
    inode), names without regard to case (a case-blind file system)."""
    leaves = out / "leaves"
    if not leaves.is_dir():
        return
    names = {j.name.lower() for j in scene.jobs}
    for src in scene.inputs:
        real = Path(os.path.realpath(src))
        for folder in real.parents:
            if folder.name.lower() in names and same_file(folder.parent, leaves):
                raise LeafsimError(f"--out {out}: the input {src} lies in {folder}, the folder of the scene's leaf "
                                   f"{folder.name}, which the scene writes (expected it elsewhere; it would be replaced)")


def check_out_dir(out) -> Path:
    """The output folder, created if its parent exists; LeafsimError if it cannot be written."""
    import os

    out = Path(out)
    if out.is_symlink() and not out.exists():
        raise LeafsimError(f"--out {out}: it is a broken symbolic link (to {os.readlink(out)}); remove it or choose "
                           "another folder")
    if out.exists() and not out.is_dir():
        raise LeafsimError(f"--out {out}: exists and is not a folder")
    if not out.exists() and not out.parent.is_dir():  # as run and export: only the last folder is made
        raise LeafsimError(f"--out {out}: {no_folder(out.parent)}")
    try:
        (out / "leaves").mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise LeafsimError(f"--out {out}: cannot create the output folder ({e.strerror or e})") from None
    if not os.access(out, os.W_OK) or not os.access(out / "leaves", os.W_OK):
        raise LeafsimError(f"--out {out}: folder is not writable")
    return out


def die_with_parent() -> None:
    """A scene worker's set-up: it dies (SIGKILL) when its parent does (Linux ``prctl``; a no-op
    elsewhere), so it never outlives a killed ``leafsim scene``, and it ignores Ctrl-C, which
    the terminal sends to the whole process group: the command stops its workers itself
    (:func:`_stop_pool`), and a worker interrupted by it printed a traceback."""
    import ctypes
    import os

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        libc = None
    if libc is not None and os.getppid() == 1:  # the parent died before the request took effect
        os._exit(1)


#: the longest a scene's command waits for its workers without running Python (so a signal is handled) [s]
WAIT_POLL_S = 0.2


def _local_results(jobs: list, out: Path, workers: int):
    """Yield results of ``jobs`` from a local process pool (spawned workers: no forked
    numba/OpenGL state; each dies with this process)."""
    import multiprocessing as mp
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    pool = ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"), initializer=die_with_parent)
    try:
        with _signals_deferred_while_workers_start():
            futs = {pool.submit(run_leaf, j, str(out)): j for j in jobs}  # (the workers are started here)
        order = {f: k for k, f in enumerate(futs)}
        pending = set(futs)
        while pending:
            # waits of at most WAIT_POLL_S: a signal the kernel hands to another thread (the pool's
            # own, or the progress bar's) only runs its handler when this thread runs Python again,
            # and a wait with no timeout never returned before the next leaf was done (a SIGTERM
            # under load left the command waiting for a leaf of a million frames)
            done, pending = wait(pending, timeout=WAIT_POLL_S, return_when=FIRST_COMPLETED)
            for f in sorted(done, key=order.get):
                try:
                    yield f.result()
                except Exception as e:  # a worker process died: this leaf failed, the pool may go on
                    yield {"name": futs[f].name, "ok": False, "error": f"worker process failed: {type(e).__name__}: {e}"}
    except BaseException:  # interrupted (a signal, or the caller stopped reading): stop now
        _stop_pool(pool)
        raise
    pool.shutdown(wait=True)


@contextlib.contextmanager
def _signals_deferred_while_workers_start():
    """Ctrl-C and SIGTERM wait while the pool starts its workers.

    * In the workers: SIGINT is blocked in this thread meanwhile, and a process starts with its
      parent thread's signal mask, so a Ctrl-C during a worker's start-up, before its
      initializer ignores it, stays pending there instead of making it print a traceback.
    * Here: the command's handlers are swapped for ones that only note the signal, which is
      sent again when the workers are started.  A SIGTERM that came while a worker was being
      launched (the child made, its start-up data not yet written to it) interrupted the
      launch, and the child printed "EOFError: Ran out of input" after the command's
      "interrupted" (2 of 30 commands sent SIGTERM as their first child appeared, 2 of 60 with
      SIGTERM only blocked in this thread: the signal then reaches another thread, and Python
      runs its handler in this one all the same)."""
    noted = []
    swapped = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            swapped[sig] = signal.signal(sig, lambda signum, frame: noted.append(signum))
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT}) if hasattr(signal, "pthread_sigmask") else None
    try:
        yield
    finally:
        if old is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)
        for sig, handler in swapped.items():
            signal.signal(sig, handler if handler is not None else signal.SIG_DFL)
        if noted:
            signal.raise_signal(noted[0])  # the command's own handler now: "interrupted", its exit status


def _stop_pool(pool) -> None:
    """Stop ``pool`` at once: the leaves not started are dropped and the running ones end with
    their workers (a leaf's files are written atomically, so none is left half-written, and a
    rerun simulates it again).  Leaving the pool the usual way waited for every queued leaf (a
    SIGTERM 10 s into an 8-leaf scene ran all 8), and a second Ctrl-C hung the process in
    multiprocessing's exit handler."""
    procs = list((getattr(pool, "_processes", None) or {}).values())  # (no public handle on the workers)
    pool.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        if p.is_alive():
            p.terminate()
    for p in procs:
        p.join(timeout=10.0)  # (a terminated worker exits at once; the bound only guards a stuck one)
        if p.is_alive():
            p.kill()


def _dask_client(address: str):
    """A client of the Dask scheduler at ``address``; LeafsimError when it cannot connect."""
    from distributed import Client

    try:
        return Client(address, timeout="20s")
    except Exception as e:
        raise LeafsimError(f"--scheduler {address}: cannot connect to the Dask scheduler ({type(e).__name__}: {e})") from None


def _dask_results(jobs: list, out: Path, client):
    """Yield results of ``jobs`` from the Dask cluster of ``client`` (its workers must see ``out``)."""
    from distributed import as_completed

    try:
        futs = client.map(run_leaf, jobs, out=str(out.resolve()), pure=False, key=[f"leaf-{j.name}-{j.key}" for j in jobs])
        names = {f.key: j.name for f, j in zip(futs, jobs)}
        for f in as_completed(futs):
            try:
                yield f.result()
            except Exception as e:
                yield {"name": names[f.key], "ok": False, "error": f"dask worker failed: {type(e).__name__}: {e}"}
    finally:
        client.close()


def run_scene(scene: Scene, out, workers: int = 1, scheduler: str | None = None, progress: bool = True,
              render: bool = True, before: Callable[[], None] | None = None) -> dict:
    """Run every leaf of ``scene`` not already done in ``out``, then place the leaves, write
    ``placement.json``, ``summary.json`` and the overview image; returns the run report
    (also written as ``run.json``: the only file with timings).  ``before()`` runs once the
    arguments are checked, when there are leaves to simulate (the CLI compiles the kernels
    there, so the workers load them)."""
    if workers < 1:
        raise LeafsimError(f"--workers {workers}: expected at least 1")
    # the scheduler is reached before anything is created (an address it cannot reach left OUT/leaves/)
    client = _dask_client(scheduler) if scheduler else None
    try:
        return _run_scene(scene, out, workers, scheduler, client, progress, render, before)
    finally:
        if client is not None:
            client.close()


def _run_scene(scene: Scene, out, workers: int, scheduler: str | None, client, progress: bool, render: bool,
               before: Callable[[], None] | None) -> dict:
    from tqdm import tqdm

    # what the composition writes, checked before any leaf is simulated and before OUT is made
    for name in ("placement.json", "summary.json", "run.json", "overview.png"):
        not_an_input(Path(out) / name, scene.inputs or (scene.path,), "--out")  # a scene file (or config, photo) kept there
    _no_input_in_leaf_folders(scene, Path(out))
    out = check_out_dir(out)
    for name, what in (("placement.json", "placement"), ("summary.json", "summary"), ("run.json", "run report"),
                       ("overview.png", "overview")):
        output_target(out / name, what)
    t0 = time.perf_counter()
    todo = [j for j in scene.jobs if not is_done(j, out)]
    for j in todo:  # a leaf's folder is replaced only when it holds nothing but leafsim's files
        leaf_folder_entries(leaf_dir(out, j.name))
    results = []
    if todo and before is not None:
        before()
        t0 = time.perf_counter()
    if todo:
        gen = _dask_results(todo, out, client) if client is not None else _local_results(todo, out, min(workers, len(todo)))
        # (closed here, not when its frame is freed: an interrupt in this loop, outside the
        # generator, left a script's pool running every queued leaf)
        with contextlib.closing(gen), tqdm(total=len(todo), desc=scene.name, unit="leaf", disable=None if progress else True) as bar:
            for r in gen:
                results.append(r)
                bar.update(1)
                if not r["ok"]:
                    bar.write(f"leafsim: leaf {r['name']} failed: {r['error']}", file=sys.stderr)
    sim_s = time.perf_counter() - t0
    failed = sorted((r for r in results if not r["ok"]), key=lambda r: r["name"])
    report = {"scene": scene.name, "out": str(out), "leaves": len(scene.jobs), "ran": len(todo) - len(failed),
              "skipped": len(scene.jobs) - len(todo), "failed": [{"name": r["name"], "error": r["error"]} for r in failed],
              "workers": None if scheduler else workers, "scheduler": scheduler, "simulate_s": round(sim_s, 3),
              # the leaves simulated to their end (a failed leaf is no output; it was counted too)
              "leaves_per_s": round((len(todo) - len(failed)) / sim_s, 4) if todo and sim_s > 0 else None,
              "leaf_s": {r["name"]: round(r["seconds"], 3) for r in sorted(results, key=lambda r: r["name"])},
              "leaf_cpu_s": round(sum(r.get("cpu_s", 0.0) for r in results), 3)}
    # leaf folders of an earlier version of the scene (a group's count lowered, a group renamed):
    # left alone, but named, since a batch import of leaves/*/ would pick them up
    ours = {j.name for j in scene.jobs}
    stray = sorted(p.name for p in (out / "leaves").iterdir() if p.is_dir() and p.name not in ours)
    report["stray_leaves"] = stray
    if stray:
        shown = ", ".join(stray[:5]) + (f" and {len(stray) - 5} more" if len(stray) > 5 else "")
        print(f"leafsim: {len(stray)} folder{'s' if len(stray) > 1 else ''} in {out / 'leaves'} "
              f"{'are' if len(stray) > 1 else 'is'} not a leaf of this scene ({shown}): left as "
              f"{'they are' if len(stray) > 1 else 'it is'}, and not in summary.json or placement.json", file=sys.stderr)
    t1 = time.perf_counter()
    compose(scene, out, render=render)
    report["compose_s"] = round(time.perf_counter() - t1, 3)
    report["total_s"] = round(time.perf_counter() - t0, 3)
    atomic_write_bytes(out / "run.json", (json.dumps(report, indent=1, sort_keys=True) + "\n").encode(), "run report")
    return report


def compose(scene: Scene, out: Path, render: bool = True) -> None:
    """Place the finished leaves (in scene order), write ``placement.json`` and ``summary.json``
    and render ``overview.png`` (when the scene asks for one)."""
    from leafsim.scene.placement import load_views, merge_views, place

    done = [j for j in scene.jobs if is_done(j, out)]
    views = load_views(out, done)
    placed = place(scene.layout, scene.seed, done, views)
    summary = {"scene": scene.name, "leaves": {}, "lod": {}}
    for j in done:
        d = check_done(leaf_dir(out, j.name) / "done.json")
        summary["leaves"][j.name] = {k: v for k, v in d.items() if k != "key"}
        lod = leaf_dir(out, j.name) / "lod.json"
        if lod.exists():
            summary["lod"][j.name] = json.loads(lod.read_text())
    atomic_write_bytes(out / "placement.json", (json.dumps(placed, indent=1, sort_keys=True) + "\n").encode(), "placement")
    atomic_write_bytes(out / "summary.json", (json.dumps(summary, indent=1, sort_keys=True) + "\n").encode(), "summary")
    if render and scene.overview is not None and done:
        from leafsim.render.overview import render_overview

        render_overview(merge_views(views, placed), scene.layout, scene.overview, out / "overview.png")
