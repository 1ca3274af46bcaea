"""Interleaved timing: one repetition of every job per round, medians and 90th percentiles of
the same rounds, the 1-minute load beside them (these machines are shared and noisy)."""

from __future__ import annotations

import os
import time

import numpy as np


# ----------------------------------------------------------------------------- timing
def interleaved(jobs: dict, rounds: int, warm: int = 1) -> dict:
    """Time ``jobs`` (name → (reset, run); ``reset`` untimed) round-robin: one run of each per
    round.  Returns name → list of ms."""
    for _ in range(warm):
        for reset, run in jobs.values():
            reset()
            run()
    out = {k: [] for k in jobs}
    for _ in range(rounds):
        for k, (reset, run) in jobs.items():
            reset()
            t0 = time.perf_counter()
            run()
            out[k].append((time.perf_counter() - t0) * 1e3)
    return out


def summary(ms) -> dict:
    return {"median_ms": float(np.median(ms)), "p90_ms": float(np.percentile(ms, 90)), "rounds": len(ms)}


def load_average() -> float:
    return float(os.getloadavg()[0])


def nothing():
    return None
