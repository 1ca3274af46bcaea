"""Every parallel kernel against its serial twin, quiet and with one CPU-bound process per core
(the bench's own reproducible load): whether parallel code pays on this machine."""

from __future__ import annotations

import os
import time
import types

import numpy as np

from leafsim.measure.models import bench_params
from leafsim.measure.springs import SpringProblem, spring_contenders
from leafsim.measure.timing import interleaved, load_average, nothing, summary
from leafsim.sim.model import Model


# ----------------------------------------------------------------------------- parallel vs serial
def parallel_twin(fn):
    """``fn`` (a kernel body written with ``prange``) compiled in parallel, from a renamed copy:
    numba keys its on-disk cache by the function's name, source line and argument types, not
    by ``parallel``, so a second decoration of the same function shared the serial one's entry
    and whichever had been compiled first served both (the shrink step's "parallel" twin ran the
    serial code whenever the serial one was cached first, as after every warm-up)."""
    from numba import njit

    from leafsim.sim.kernels import FASTMATH

    copy = types.FunctionType(fn.__code__, fn.__globals__, fn.__name__ + "_par", fn.__defaults__, fn.__closure__)
    copy.__qualname__, copy.__module__, copy.__doc__ = fn.__qualname__ + "_par", fn.__module__, fn.__doc__
    return njit(cache=True, nogil=True, parallel=True, fastmath=FASTMATH)(copy)


class _Busy:
    """``n`` processes spinning on the CPU while the block runs: the bench's own, reproducible
    "machine under load" (the project's machines are shared; a parallel path must not lose
    when another job holds a core)."""

    def __init__(self, n: int):
        self.n, self.procs = n, []

    def __enter__(self):
        import subprocess
        import sys

        try:
            for _ in range(self.n):
                self.procs.append(subprocess.Popen([sys.executable, "-c", "while True: pass"]))
            time.sleep(0.3)
        except BaseException:  # a failed start or Ctrl-C: no burner outlives the bench
            self.__exit__()
            raise
        return self

    def __exit__(self, *exc):
        for p in self.procs:
            p.kill()
        for p in self.procs:
            p.wait()
        self.procs = []
        return False


def parallel_vs_serial(model: Model, rounds: int = 30, busy: int | None = None) -> list[dict]:
    """Every parallel kernel against its serial twin, interleaved, on a quiet machine and with
    ``busy`` CPU-bound processes running (default: one per core): 10 spring passes (the
    coloured fork/join per colour and the 2-block domain split against the serial sweep) and
    the shrink step (``prange`` over springs against the serial loop).  Rows: job, load,
    median / p90 ms, and p90 ÷ the serial twin's p90 (load: the 1-minute load average at the
    end of the block, which lags the burners)."""
    from leafsim.sim.effects.shrink import Shrink
    from leafsim.sim.kernels import shrink as ks

    prob = SpringProblem(model)
    cons = spring_contenders(prob, peers=False, numpy=False, parallel=True)
    cons.pop("ceiling (f32, serial)")
    st = model.state()
    st.particle_water[:] *= np.linspace(0.6, 1.0, model.particle_count)
    sh = Shrink(model)
    sh.configure(bench_params(model))
    m = model

    def shrink(fn):
        return lambda: fn(m.spring_ij, m.spring_rest0, sh.sigma, sh.alpha, sh.l_min, m.particle_cytosol,
                          st.particle_water, m.particle_mass0, st.spring_rest)

    jobs = {f"springs ×10: {k}": (c.reset, c.run) for k, c in cons.items()}
    jobs["shrink: serial"] = (nothing, shrink(ks.shrink_springs))
    jobs["shrink: parallel (prange)"] = (nothing, shrink(parallel_twin(ks._shrink_springs)))
    twin = {k: ("springs ×10: ours (f64, serial)" if k.startswith("springs") else "shrink: serial") for k in jobs}
    busy = (os.cpu_count() or 2) if busy is None else busy
    rows = []
    for n_busy in (0, busy):
        if n_busy:
            with _Busy(n_busy):
                ms = interleaved(jobs, rounds)
                load = load_average()
        else:
            ms = interleaved(jobs, rounds)
            load = load_average()
        st_ = {k: summary(v) for k, v in ms.items()}
        for k, v in st_.items():
            rows.append({"job": k, "busy": n_busy, "load": load, **v,
                         "p90_vs_serial": v["p90_ms"] / st_[twin[k]]["p90_ms"]})
    return rows
