"""Blade simulation: immutable Model + State, switchable effects, numba kernels, headless runs.

>>> from leafsim.blade import build_blade                        # doctest: +SKIP
>>> from leafsim.sim import Simulator, run_headless, shape_metrics
>>> model = build_blade(shape, veins, params, seed=1)              # doctest: +SKIP
>>> state, stats = run_headless(model, params, frames=2000)        # doctest: +SKIP
"""

from .model import Model, State
from .presets import PRESETS, THESIS_PRESET
from .run import frame_stats, leaf_frame, run_headless, save_npz, shape_metrics
from .simulator import EFFECTS, Simulator

__all__ = ["Model", "State", "Simulator", "EFFECTS", "run_headless", "save_npz", "shape_metrics", "frame_stats",
           "leaf_frame", "THESIS_PRESET", "PRESETS"]
