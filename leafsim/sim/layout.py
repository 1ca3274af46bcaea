"""The layout of a model's states: what every array must be, checked cheaply every frame a
simulator steps (:func:`check_layout`; :func:`leafsim.sim.checkpoint.check_state` checks a
loaded or edited state in full)."""

from __future__ import annotations

from dataclasses import fields

import numpy as np

from leafsim.base.errors import LeafsimError
from leafsim.sim.model import NOT_ARRAYS, Model, State

#: the arrays of a state's pigments (:class:`leafsim.sim.pigments.PigmentState`), as a checkpoint records them
PIGMENT_ARRAYS = ("chlorophyll", "carotenoid", "anthocyanin", "browning", "necrosis", "vein", "leaf")


def _fail(where: str, msg: str) -> LeafsimError:
    return LeafsimError(f"{where} {msg}")


def state_layout(model: Model) -> tuple:
    """What every array of a state of ``model`` must be, as (name, shape, dtype) triples, for
    :func:`check_layout` (made once per simulator: a fresh state is made to read it)."""
    fresh = model.state()
    arrays = tuple((f.name, getattr(fresh, f.name).shape, getattr(fresh, f.name).dtype)
                   for f in fields(State) if f.name not in NOT_ARRAYS)
    return arrays, model.particle_count, model.fingerprint


def check_layout(state: State, layout: tuple, where: str) -> None:
    """The cheap part of :func:`check_state`, for every frame a simulator steps: ``state`` is a
    State whose arrays (and pigments') have the shapes and dtypes of ``layout``
    (:func:`state_layout`).  A state of another model, or an array swapped for one of another
    length, reached the kernels, which wrote past the arrays' ends (segfault, heap corruption)."""
    if not isinstance(state, State):
        raise _fail(where, f"is a {type(state).__name__}, expected a leafsim.sim.model.State (e.g. run.state)")
    arrays, n, key = layout
    if state.model_key and state.model_key != key:
        raise _fail(where, "is a state of another model (another build: its seed, mesh or species differ), "
                           "expected one of this model (run.state, or Simulator(model, ...).state())")
    for name, shape, dtype in arrays:
        a = getattr(state, name)
        if not isinstance(a, np.ndarray) or a.shape != shape or a.dtype != dtype:
            got = f"{a.dtype} {a.shape}" if isinstance(a, np.ndarray) else type(a).__name__
            raise _fail(where, f"array {name} is {got}, expected {dtype} {shape} for this model (a state of another "
                               "model?)")
        if not a.flags.writeable:  # the kernels write every array in place
            raise _fail(where, f"array {name} is read-only (a broadcast or a view of a read-only array), expected a "
                               "writeable array (np.array(...) makes a copy)")
    pig = state.pigments
    if pig is not None:
        for name in PIGMENT_ARRAYS:
            a = getattr(pig, name, None)
            want = (6,) if name == "leaf" else (n,)
            if not isinstance(a, np.ndarray) or a.shape != want:
                got = f"{a.dtype} {a.shape}" if isinstance(a, np.ndarray) else type(a).__name__
                raise _fail(where, f"pigment array {name} is {got}, expected shape {want} for this model")
            if not a.flags.writeable:
                raise _fail(where, f"pigment array {name} is read-only, expected a writeable array")
