"""Checkpoints of a headless run: the complete simulation state of one frame, written atomically.

A :class:`~leafsim.sim.model.State` (with its pigments) is everything that changes from frame
to frame — the effects keep nothing across frames that is not rebuilt from the model and the
parameters — so rebuilding the model from the same species, parameters and seed and loading
the state continues the run bit-identically to one that was never interrupted.

The file is an ``.npz`` (no pickles) holding the state arrays, the pigments and a JSON record
``meta`` of what the run was made with (species, config, seed, every parameter value, effects
and a fingerprint of the model), which :func:`load_checkpoint` compares before resuming.
"""

from __future__ import annotations

import hashlib
import io
import json
from dataclasses import fields
from pathlib import Path

import numpy as np

from leafsim.base.errors import LeafsimError
from leafsim.base.fileio import atomic_write_bytes
from leafsim.sim.model import Model, State
from leafsim.sim.pigments import PigmentState

FORMAT = "leafsim-checkpoint/1"
_PIGMENT_ARRAYS = ("chlorophyll", "carotenoid", "anthocyanin", "browning", "necrosis", "vein", "leaf")


def model_fingerprint(model: Model) -> str:
    """Short hash of the model's geometry and topology (a rebuilt model must match it)."""
    h = hashlib.sha256()
    for a in (model.particle_rest, model.spring_ij, model.spring_rest0, model.hinge_idx, model.vol_idx,
              model.particle_cytosol, model.particle_water0):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:20]


def save_checkpoint(path, model: Model, state: State, meta: dict) -> None:
    """Write ``state`` (and ``meta``, plus format, frame and model fingerprint) atomically."""
    arrays = {f"state_{f.name}": getattr(state, f.name) for f in fields(State) if f.name != "pigments"}
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
        if saved.get(k) != now.get(k):
            raise LeafsimError(f"--resume: {path} was made with parameter '{k}' = {saved.get(k)!r}, "
                               f"this run has {now.get(k)!r} (resume with the same --set values)")
    return meta


def _open(path: Path):
    if not path.is_file():
        raise LeafsimError(f"--resume: no checkpoint at {path} (run first with --out and --checkpoint-every)")
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
        arrays = {f.name: np.array(data[f"state_{f.name}"]) for f in fields(State) if f.name != "pigments"}
        pig = None
        if "pigments" in meta:
            pig = PigmentState(**{k: np.array(data[f"pig_{k}"]) for k in _PIGMENT_ARRAYS},
                               age=float(meta["pigments"]["age"]), seed=int(meta["pigments"]["seed"]))
    except KeyError as e:
        raise LeafsimError(f"{path}: checkpoint is missing {e.args[0]}") from None
    return State(**arrays, pigments=pig)
