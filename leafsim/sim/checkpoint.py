"""Checkpoints of a headless run: the complete simulation state of one frame, written atomically.

A :class:`~leafsim.sim.model.State` (with its pigments and its drying-path mesh's state) is
what changes from frame to frame; the few things a stage hands on besides (the static
solver's friction anchors and predictor, whether the drying path carried the last frame:
:meth:`~leafsim.sim.simulator.Simulator.carry`) are kept beside it.  Rebuilding the model
from the same species, parameters and seed and loading both continues the run
bit-identically to one that was never interrupted.

The file is an ``.npz`` (no pickles) holding the state arrays, the pigments and a JSON record
``meta`` of what the run was made with (species, config, seed, every parameter value, effects
and a fingerprint of the model), which :func:`load_checkpoint` compares before resuming.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
from dataclasses import fields
from pathlib import Path

import numpy as np

from leafsim.base.errors import LeafsimError
from leafsim.base.fileio import atomic_write_bytes
from leafsim.config.params import PARAMS
from leafsim.sim.layout import PIGMENT_ARRAYS as _PIGMENT_ARRAYS
from leafsim.sim.model import NOT_ARRAYS, Model, State
from leafsim.sim.pigments import PigmentState

FORMAT = "leafsim-checkpoint/1"
#: a loaded particle farther than this many leaf lengths from the leaf, or faster than this
#: [m/s], is not a state any run reaches
MAX_REACH = 100.0
MAX_SPEED = 1e3
#: pigment contents and per-leaf factors are of order one; beyond this a file is damaged
MAX_PIGMENT = 100.0


def model_fingerprint(model: Model) -> str:
    """Short hash of the model's geometry and topology (a rebuilt model must match it):
    :attr:`Model.fingerprint`."""
    return model.fingerprint


def save_checkpoint(path, model: Model, state: State, meta: dict, carry: dict | None = None) -> None:
    """Write ``state`` (and ``meta``, plus format, frame and model fingerprint) atomically, with
    ``carry``, what the simulator's stages hand to the next frame beyond the state
    (:meth:`~leafsim.sim.simulator.Simulator.carry`).  A state that does not fit ``model`` (another
    leaf's arrays) or holds NaN is refused before anything is written: it could never be resumed,
    and it would replace the last good checkpoint."""
    where = f"checkpoint {path}: the state to save"
    check_state(state, model, where, physical=False)
    arrays = {f"state_{f.name}": getattr(state, f.name) for f in fields(State) if f.name not in NOT_ARRAYS}
    arrays.update({f"carry_{k}": np.asarray(v) for k, v in (carry or {}).items()})
    # the drying-path mesh's state (leafsim.sim.path), and its own path mesh's (dynamics.path = fine)
    s, m, prefix = state, model, "path_"
    while s is not None:
        if isinstance(s.path, State) != (m.path is not None):
            which = "drying-path mesh" if prefix == "path_" else "drying-path mesh's own path mesh"
            raise _fail(where, f"has no {which} state" if m.path is not None else f"has a {which} state this model has not")
        if s.path is not None:
            check_state(s.path, m.path, f"{where} (drying-path mesh)", physical=False)
            arrays.update({f"{prefix}{f.name}": getattr(s.path, f.name) for f in fields(State) if f.name not in NOT_ARRAYS})
        s, m, prefix = s.path, m.path, "path_" + prefix
    record = dict(meta, format=FORMAT, frame=state.frame, model=model_fingerprint(model))
    pig = state.pigments
    if pig is not None:
        arrays.update({f"pig_{k}": getattr(pig, k) for k in _PIGMENT_ARRAYS})
        record["pigments"] = {"age": float(pig.age), "seed": int(pig.seed)}
    buf = io.BytesIO()
    np.savez(buf, meta=np.array(json.dumps(record, sort_keys=True)), **arrays)
    atomic_write_bytes(path, buf.getvalue(), "checkpoint")


def check_meta(path, expect: dict) -> dict:
    """The ``meta`` record of the checkpoint at ``path`` after checking that it was made with
    ``expect`` (species, config, seed, every parameter value): cheap, before any model is built.
    Raises a one-line LeafsimError naming the first difference."""
    path = Path(path)
    meta = _open(path)[0]
    for key in sorted(expect):
        if key != "params" and meta.get(key) != expect[key]:
            raise LeafsimError(f"--resume: {path} was made with {key} {meta.get(key)!r}, this run has {expect[key]!r}")
    saved, now = meta.get("params", {}), expect.get("params", {})
    for k in sorted(set(saved) | set(now)):
        if k not in saved and k in PARAMS and now.get(k) == PARAMS[k].default:
            continue  # a parameter newer than the checkpoint, at the default that keeps the old behaviour
        if saved.get(k) != now.get(k):
            raise LeafsimError(f"--resume: {path} was made with parameter '{k}' = {saved.get(k)!r}, "
                               f"this run has {now.get(k)!r} (resume with the --quality and --set values of the run that wrote it)")
    return meta


#: no array of a checkpoint holds more bytes than this (a model of millions of particles stays
#: far below; a small damaged or hostile file can inflate: 13 MB of zeros made 3 GB)
MAX_MEMBER_BYTES = 160_000_000


def _bounded(path: Path) -> None:
    """Read each member's .npy header (not its data) and refuse a member that claims more
    than :data:`MAX_MEMBER_BYTES` (its shape × its dtype's item size), before numpy inflates it."""
    import zipfile

    with zipfile.ZipFile(path) as z:
        for info in z.infolist():
            with z.open(info) as f:
                version = np.lib.format.read_magic(f)
                shape, _, dtype = (np.lib.format.read_array_header_1_0(f) if version == (1, 0)
                                   else np.lib.format.read_array_header_2_0(f))
            if math.prod(shape) * dtype.itemsize > MAX_MEMBER_BYTES:
                raise LeafsimError(f"{path}: checkpoint member {info.filename} claims {dtype} {shape}, more than "
                                   f"{MAX_MEMBER_BYTES:,} bytes: not a leafsim checkpoint")


def _open(path: Path):
    if not path.is_file():
        raise LeafsimError(f"--resume: no checkpoint at {path} (run first with --out and --checkpoint-every)")
    try:
        _bounded(path)
    except LeafsimError:
        raise
    except Exception as e:  # not a zip of .npy members
        raise LeafsimError(f"{path}: cannot read checkpoint ({type(e).__name__}: {str(e).splitlines()[0][:80] if str(e) else ''})") from None
    try:
        data = np.load(path, allow_pickle=False)
        meta = json.loads(str(data["meta"]))
    except Exception as e:  # a damaged file raises anything from zipfile, numpy or json
        raise LeafsimError(f"{path}: cannot read checkpoint ({type(e).__name__}: {str(e).splitlines()[0][:80]})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise LeafsimError(f"{path}: not a leafsim checkpoint (expected format {FORMAT})")
    return meta, data


def load_checkpoint(path, model: Model, expect: dict) -> State:
    """The state saved in ``path``, after :func:`check_meta` and a check that it belongs to
    this ``model`` (same geometry and topology)."""
    path = Path(path)
    meta = check_meta(path, expect)
    data = _open(path)[1]
    if meta.get("model") != model_fingerprint(model):
        raise LeafsimError(f"--resume: the model built now differs from the one in {path} (species config or code changed)")
    try:
        arrays = {f.name: np.array(data[f"state_{f.name}"]) for f in fields(State) if f.name not in NOT_ARRAYS}
        if arrays["scalars"].shape == (2,):  # written before the weather clock: no weather time yet
            arrays["scalars"] = np.append(arrays["scalars"], 0.0)
        coarse = _path_state(data, model.path, "path_")
        pig = None
        if "pigments" in meta:
            rec = meta["pigments"]
            age, seed = (rec.get("age"), rec.get("seed")) if isinstance(rec, dict) else (None, None)
            if not (isinstance(age, (int, float)) and 0.0 <= age <= 1e12) or not (isinstance(seed, int) and 0 <= seed < 2 ** 63):
                raise LeafsimError(f"{path}: checkpoint's pigment record is {rec!r}, expected an age in [0, 1e12] "
                                   "and a non-negative integer seed")
            pig = PigmentState(**{k: np.array(data[f"pig_{k}"]) for k in _PIGMENT_ARRAYS}, age=float(age), seed=seed)
        elif any(k.startswith("pig_") for k in data.files):
            raise LeafsimError(f"{path}: checkpoint holds pigment arrays without their record (age, seed) in meta")
    except KeyError as e:  # numpy says "NAME is not a file in the archive"
        raise LeafsimError(f"{path}: checkpoint is missing the array {str(e.args[0]).split()[0]}") from None
    except Exception as e:  # a damaged member: zlib, numpy or a wrong type
        raise LeafsimError(f"{path}: cannot read checkpoint ({type(e).__name__}: {str(e).splitlines()[0][:80]})") from None
    state = State(**arrays, pigments=pig, path=coarse, model_key=model.fingerprint)
    check_state(state, model, f"{path}: checkpoint", frame=meta.get("frame"))
    return state


def _path_state(data, model: Model | None, prefix: str) -> State | None:
    """The saved state of the drying-path mesh ``model`` (None: none), with its own path mesh's."""
    if model is None:
        return None
    return State(**{f.name: np.array(data[f"{prefix}{f.name}"]) for f in fields(State) if f.name not in NOT_ARRAYS},
                 path=_path_state(data, model.path, "path_" + prefix), model_key=model.fingerprint)


def load_carry(path, model: Model) -> dict:
    """What the stages handed to the next frame when the checkpoint at ``path`` was written
    (:meth:`~leafsim.sim.simulator.Simulator.restore` takes it; empty for a checkpoint written
    before it was kept), each array checked for the shape, type and range this model's
    simulator writes.  Call after :func:`load_checkpoint`."""
    path = Path(path)
    data = _open(path)[1]
    where = f"{path}: checkpoint"
    try:
        items = {key.removeprefix("carry_"): np.array(data[key]) for key in data.files if key.startswith("carry_")}
    except Exception as e:  # a damaged member
        raise LeafsimError(f"{path}: cannot read checkpoint ({type(e).__name__}: {str(e).splitlines()[0][:80]})") from None
    return _check_carry(items, model, where)


def _check_carry(items: dict, model: Model, where: str, prefix: str = "") -> dict:
    """``items`` (record name → array) checked against what ``model``'s simulator writes; the
    records of its drying-path mesh's simulator (``pathmesh_``, :meth:`Simulator.carry`) against
    that mesh, in turn."""
    from leafsim.sim.simulator import CARRY_PATH

    inner = {k.removeprefix(CARRY_PATH): v for k, v in items.items() if k.startswith(CARRY_PATH)}
    if inner and model.path is None:
        raise _fail(where, f"holds solver records for a drying-path mesh this model has not ({CARRY_PATH}...)")
    n = model.particle_count
    out = {} if not inner else {CARRY_PATH + k: v for k, v in _check_carry(inner, model.path, where, prefix + CARRY_PATH).items()}
    try:
        for name, a in items.items():
            if name.startswith(CARRY_PATH):
                continue
            shape = {"path_was_active": (1,), "equilibrium_normal": (n,), "equilibrium_anchor": (n, 2)}.get(name)
            if name == "equilibrium_history_time" and a.ndim >= 1:
                shape = (min(len(a), 2),)
            elif name == "equilibrium_history_q" and a.ndim >= 1:
                shape = (min(len(a), 2), n, 3)
            elif name.startswith("equilibrium_history_"):
                shape = (2,) if name.endswith("time") else (2, n, 3)
            if shape is None:
                raise _fail(where, f"holds an unknown solver record {prefix + name!r}")
            kind = "b" if name == "path_was_active" else "f"
            if a.shape != shape or a.dtype.kind != kind:
                raise _fail(where, f"solver record {prefix}{name} is {a.dtype} {a.shape}, expected "
                                   f"{'bool' if kind == 'b' else 'float64'} {shape} for this model")
            if kind == "f" and not np.isfinite(a).all():
                raise _fail(where, f"solver record {prefix}{name} holds NaN or infinite values")
            out[name] = a
    except LeafsimError:
        raise
    except Exception as e:  # a damaged member
        raise _fail(where, f"cannot be read ({type(e).__name__}: {str(e).splitlines()[0][:80]})") from None
    eq = sorted(k for k in out if k.startswith("equilibrium_"))
    every = ["equilibrium_anchor", "equilibrium_history_q", "equilibrium_history_time", "equilibrium_normal"]
    if eq and eq != every:
        raise _fail(where, f"holds the static solver's records {', '.join(prefix + k for k in eq)} without "
                           f"{', '.join(prefix + k for k in every if k not in eq)} (all four or none)")
    # the ground's normal forces carry the leaf's weight: none beyond 10⁴ × its fresh weight
    most = 1e4 * float(model.particle_mass0.sum()) * 9.81
    if "equilibrium_normal" in out and ((out["equilibrium_normal"] < 0).any() or (out["equilibrium_normal"] > most).any()):
        raise _fail(where, f"solver record {prefix}equilibrium_normal holds normal forces outside [0, {most:.3g}] N "
                           "(negative, or beyond 10⁴ × the leaf's weight)")
    ht0 = out.get("equilibrium_history_time")
    if ht0 is not None and ((ht0 < 0).any() or (ht0 > 1e9).any()):
        raise _fail(where, f"solver record {prefix}equilibrium_history_time holds times outside [0, 1e9] s")
    if "equilibrium_anchor" in out:
        far = np.abs(out["equilibrium_anchor"] - model.particle_rest[:, :2].mean(0)).max()
        if far > MAX_REACH * model.length:
            raise _fail(where, f"solver record {prefix}equilibrium_anchor holds an anchor {far:.3g} m from the leaf")
    hq, ht = out.get("equilibrium_history_q"), out.get("equilibrium_history_time")
    if (hq is None) != (ht is None) or (hq is not None and len(hq) != len(ht)):
        raise _fail(where, f"solver records {prefix}equilibrium_history_time and _q do not match")
    if hq is not None and len(hq) and np.abs(hq - model.particle_rest.mean(0)).max() > MAX_REACH * model.length:
        raise _fail(where, f"solver record {prefix}equilibrium_history_q holds a particle far from the leaf")
    return out


def _fail(where: str, msg: str) -> LeafsimError:
    return LeafsimError(f"{where} {msg}")


#: a loaded particle may hold this many times its fresh water (measured: never above 1.0)
WATER_SLACK = 2.0
#: a loaded state's springs: at most CRUSHED_SHARE of them shorter than STRAIN_RANGE[0] × their
#: rest lengths and at most TORN_SHARE longer than STRAIN_RANGE[1] (a collapsed position array
#: has them all crushed, a scrambled one nearly all torn, half a leaf collapsed to a point 47 %
#: crushed, a leaf flattened onto a line 13 %; the thesis preset's crumpled ball, the most
#: deformed leaf the simulator makes, at most 1.1 % crushed and 1.1 % torn on oak and maple)
STRAIN_RANGE = (0.2, 5.0)
CRUSHED_SHARE = 0.1
TORN_SHARE = 0.05
#: |hinge_rest| is clamped at 0.35 rad by the shrink effect (1.35 rad with shrink.plication's
#: pleats, clamped at 1 rad on their own; a loaded state is checked against ±π); hinge_plastic, the largest bilayer
#: angle a hinge has asked for, is not (6.1 rad measured on oak with shrink.sigma_surface_top 0.8)
PLASTIC_MAX = 1e3


def check_state(state: State, model: Model, where: str, frame=None, physical: bool = True) -> None:
    """A loaded state must fit ``model`` before any kernel sees it: every array of the shape
    and dtype a fresh state of the model has, finite, and physical — particles within
    :data:`MAX_REACH` leaf lengths and :data:`MAX_SPEED`, water ≥ 0 and at most the fresh
    leaf's total and no particle more than :data:`WATER_SLACK` × its own fresh water (water flows
    down its potential, so a particle never holds more than when fresh), rest lengths in (0, 2 l⁰], rest volumes within 10 × the fresh ones, springs
    neither mostly crushed nor torn (:data:`STRAIN_RANGE`), hinge rest angles within ±π, time and frame non-negative (the frame the record names).  Raises one LeafsimError line naming the array.

    ``physical=False`` (a state to draw or export, not to step): only the arrays' shapes, dtypes
    and finiteness, the time and the pigments; the drying-path mesh's state is not looked at."""
    if not isinstance(state, State):
        raise _fail(where, f"is a {type(state).__name__}, expected a leafsim.sim.model.State (e.g. run.state)")
    if state.model_key and state.model_key != model.fingerprint:
        raise _fail(where, "is a state of another model (another build: its seed, mesh or species differ), "
                           "expected one of this model (run.state, or Simulator(model, ...).state())")
    fresh = model.state()
    if physical and (state.path is None) != (model.path is None):
        raise _fail(where, "the drying-path mesh's state " + ("is missing" if state.path is None else "belongs to no path mesh"))
    if physical and state.path is not None:
        check_state(state.path, model.path, f"{where} (drying-path mesh)")
    for f in fields(State):
        if f.name in NOT_ARRAYS:
            continue
        a, ref = getattr(state, f.name), getattr(fresh, f.name)
        if not isinstance(a, np.ndarray) or a.shape != ref.shape or a.dtype != ref.dtype:
            got = f"{a.dtype} {a.shape}" if isinstance(a, np.ndarray) else type(a).__name__
            raise _fail(where, f"array {f.name} is {got}, expected {ref.dtype} {ref.shape} for this model")
        if not np.isfinite(a).all():
            raise _fail(where, f"array {f.name} holds NaN or infinite values")
        if physical and not a.flags.writeable:  # a state to step: the kernels write every array in place
            raise _fail(where, f"array {f.name} is read-only (a broadcast or a view of a read-only array), expected a "
                               "writeable array (np.array(...) makes a copy)")
    if physical:
        _check_physical(state, model, where, frame)
    _check_pigments(state, model, where)


def check_edited(state: State, model: Model, where: str) -> None:
    """The cheap part of :func:`check_state` for a state a run stepped to itself and may have been
    edited in place since (``State`` is frozen, its arrays are not): every array finite and
    writeable, water ≥ 0 and at most the fresh leaf's, time and frame non-negative.  Not the
    leaf's reach or speed: a free leaf may fall far and fast."""
    for f in fields(State):
        if f.name in NOT_ARRAYS:
            continue
        a = getattr(state, f.name)
        if not np.isfinite(a).all():
            raise _fail(where, f"array {f.name} holds NaN or infinite values (edited since the last frame?)")
        if not a.flags.writeable:
            raise _fail(where, f"array {f.name} is read-only, expected a writeable array")
    w = state.particle_water
    if (w < 0).any() or w.sum() > model.particle_water0.sum() * (1 + 1e-6):
        what = "negative water" if (w < 0).any() else "more water than the fresh leaf"
        raise _fail(where, f"array particle_water holds {what} (edited since the last frame?)")
    if (state.scalars < 0).any():
        raise _fail(where, "time, frame and weather time must be non-negative (scalars edited since the last frame?)")
    if state.path is not None and model.path is not None:
        check_edited(state.path, model.path, f"{where} (drying-path mesh)")


def _check_physical(state: State, model: Model, where: str, frame) -> None:
    """:func:`check_state`'s physical bounds (the arrays' shapes and finiteness checked)."""
    far = np.linalg.norm(state.particle_q - model.particle_rest.mean(0), axis=1).max()
    if far > MAX_REACH * model.length:
        raise _fail(where, f"array particle_q holds a particle {far:.3g} m from the leaf (more than {MAX_REACH:g} leaf lengths)")
    if np.abs(state.particle_qd).max() > MAX_SPEED:
        raise _fail(where, f"array particle_qd holds a speed above {MAX_SPEED:g} m/s")
    if (np.abs(state.vol_rest) > 10.0 * np.abs(model.vol_rest0) + 1e-30).any():
        raise _fail(where, "array vol_rest holds rest volumes beyond 10 × the fresh leaf's")
    w = state.particle_water
    if (w < 0).any():
        raise _fail(where, f"array particle_water holds negative water ({w.min():.3g} kg)")
    if w.sum() > model.particle_water0.sum() * (1 + 1e-6):
        raise _fail(where, f"array particle_water holds more water ({w.sum():.4g} kg) than the fresh leaf "
                           f"({model.particle_water0.sum():.4g} kg)")
    over = w > WATER_SLACK * model.particle_water0 + 1e-12
    if over.any():
        i = int(np.argmax(w / np.maximum(model.particle_water0, 1e-300)))
        raise _fail(where, f"array particle_water holds {w[i] / max(model.particle_water0[i], 1e-300):.3g} × particle {i}'s "
                           f"fresh water (a particle holds at most its fresh, saturated water)")
    r = state.spring_rest / np.maximum(model.spring_rest0, 1e-300)
    if (r <= 0).any() or (r > 2.0).any():
        raise _fail(where, "array spring_rest holds rest lengths outside (0, 2] × their fresh lengths")
    ij = model.spring_ij
    ratio = np.linalg.norm(state.particle_q[ij[:, 0]] - state.particle_q[ij[:, 1]], axis=1) / np.maximum(state.spring_rest, 1e-300)
    crushed = float(np.mean(ratio < STRAIN_RANGE[0])) if len(ratio) else 0.0
    torn = float(np.mean(ratio > STRAIN_RANGE[1])) if len(ratio) else 0.0
    if crushed > CRUSHED_SHARE:
        raise _fail(where, f"array particle_q does not form this leaf: {100 * crushed:.3g} % of its springs are shorter "
                           f"than {STRAIN_RANGE[0]:g} × their rest lengths (at most {100 * CRUSHED_SHARE:g} %)")
    if torn > TORN_SHARE:
        raise _fail(where, f"array particle_q does not form this leaf: {100 * torn:.3g} % of its springs are longer "
                           f"than {STRAIN_RANGE[1]:g} × their rest lengths (at most {100 * TORN_SHARE:g} %)")
    if (np.abs(state.hinge_rest) > np.pi).any():
        raise _fail(where, f"array hinge_rest holds angles beyond ±π ({np.abs(state.hinge_rest).max():.3g} rad)")
    if (np.abs(state.hinge_plastic) > PLASTIC_MAX).any():
        raise _fail(where, f"array hinge_plastic holds angles beyond ±{PLASTIC_MAX:g} rad "
                           f"({np.abs(state.hinge_plastic).max():.3g} rad)")
    t, k, tw = float(state.scalars[0]), float(state.scalars[1]), float(state.scalars[2])
    if t < 0 or t > 1e9 or k < 0 or k != round(k) or (frame is not None and int(k) != frame):
        raise _fail(where, f"array scalars holds time {t:g} s, frame {k:g} (expected non-negative, frame {frame})")
    if t > (k + 1) * PARAMS["dynamics.dt"].hi * (1 + 1e-9):
        raise _fail(where, f"array scalars holds time {t:g} s at frame {k:g}: more than frame × the longest Δt "
                           f"({PARAMS['dynamics.dt'].hi:g} s)")
    if not (0.0 <= tw <= 1e18):
        raise _fail(where, f"array scalars holds weather time {tw:g} s, expected [0, 1e18] s")


def _check_pigments(state: State, model: Model, where: str) -> None:
    pig = state.pigments
    if pig is not None and not isinstance(pig, PigmentState):
        raise _fail(where, f"pigments are a {type(pig).__name__}, expected a PigmentState or None")
    if pig is not None:
        n = model.particle_count
        for name in _PIGMENT_ARRAYS:
            a = getattr(pig, name)
            shape = (6,) if name == "leaf" else (n,)
            dtype = np.float64 if name == "leaf" else np.float32
            if not isinstance(a, np.ndarray) or a.shape != shape or a.dtype != dtype:
                got = f"{a.dtype} {a.shape}" if isinstance(a, np.ndarray) else type(a).__name__
                raise _fail(where, f"pigment array {name} is {got}, expected {np.dtype(dtype)} {shape}")
            if (not np.isfinite(a).all() or (name != "leaf" and (a < 0).any()) or (name == "leaf" and (a[:5] <= 0).any())
                    or (np.abs(a) > MAX_PIGMENT).any()):
                raise _fail(where, f"pigment array {name} holds NaN, infinite, negative or huge values "
                                   f"(pigment contents are fractions of a summer content, at most {MAX_PIGMENT:g})")
        if not isinstance(pig.age, (int, float, np.floating)) or not np.isfinite(pig.age):
            raise _fail(where, "pigment age is not a finite number")
