"""Blade simulation: immutable Model + State, switchable effects, numba kernels, headless runs.

>>> from leafsim.blade.build import build_blade                        # doctest: +SKIP
>>> from leafsim.sim import Simulator, run_headless, shape_metrics
>>> model = build_blade(shape, veins, params, seed=1)              # doctest: +SKIP
>>> state, stats = run_headless(model, params, frames=2000)        # doctest: +SKIP
"""

from leafsim.config.presets import PRESETS, THESIS_PRESET
from leafsim.sim.effects import EFFECTS
from leafsim.sim.measures import leaf_measures
from leafsim.sim.model import Model, State
from leafsim.sim.run import run_headless
from leafsim.sim.shape import leaf_frame, save_npz, shape_metrics
from leafsim.sim.simulator import Simulator
from leafsim.sim.stats import frame_stats

__all__ = ["Model", "State", "Simulator", "EFFECTS", "run_headless", "save_npz", "shape_metrics", "frame_stats",
           "leaf_frame", "leaf_measures", "THESIS_PRESET", "PRESETS"]
