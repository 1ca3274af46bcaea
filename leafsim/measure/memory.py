"""Memory of a built and running model: bytes per particle of every array, and the peak
resident set from the kernel's high-water mark (a fresh process per size)."""

from __future__ import annotations

import resource

import numpy as np

from leafsim.config.params import ParamSet
from leafsim.measure.models import bench_params
from leafsim.sim.model import Model


# ----------------------------------------------------------------------------- memory
def memory(model: Model, params: ParamSet | None = None) -> dict:
    """Bytes per particle of the model, one state and the stages' arrays (dynamics, osmosis
    with its factors, shrink), and this process's peak RSS so far."""
    from leafsim.sim.simulator import Simulator

    sim = Simulator(model, params or bench_params(model), watchdog=False)
    st = sim.state()
    sim.step(st)
    n = model.particle_count
    parts = {"model": _nbytes(model), "state": _nbytes(st), "dynamics": _nbytes(sim._dynamics),
             "osmosis": _nbytes(sim._osmosis), "shrink": _nbytes(sim._shrink)}
    return {"bytes_per_particle": {k: v / n for k, v in parts.items()},
            "bytes_per_particle_total": sum(parts.values()) / n,
            "peak_rss_mb": peak_rss_mb()}


def peak_rss_mb() -> float:
    """This process's peak resident memory [MB]: the kernel's high-water mark of its address
    space (VmHWM), which starts afresh at exec.  (``ru_maxrss`` does not on Linux: a process
    started by a 1 GB bench inherits the 1 GB as its 'peak'.)  ``ru_maxrss`` where /proc is
    missing."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return float(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _nbytes(obj, seen=None) -> int:
    """Bytes of the numpy arrays and scipy sparse matrices an object holds (one level of
    tuples/lists, no double counting)."""
    import scipy.sparse as sp

    seen = set() if seen is None else seen
    vals = obj if isinstance(obj, (tuple, list)) else (vars(obj).values() if hasattr(obj, "__dict__") else
                                                       [getattr(obj, f) for f in getattr(obj, "__dataclass_fields__", {})])
    total = 0
    for v in vals:
        if id(v) in seen:
            continue
        seen.add(id(v))
        if isinstance(v, np.ndarray):
            total += v.nbytes
        elif sp.issparse(v):
            total += sum(getattr(v, a).nbytes for a in ("data", "indices", "indptr") if hasattr(v, a))
        elif isinstance(v, (tuple, list)):
            total += _nbytes(v, seen)
    return total


def memory_subprocess(size: str) -> dict:
    """:func:`memory` of a fresh process that builds only ``size`` (a clean peak RSS)."""
    import json
    import subprocess
    import sys

    code = ("import json, resource; from leafsim.measure.models import build_bench_model; "
            "from leafsim.measure.memory import memory, peak_rss_mb; r0 = peak_rss_mb(); "
            f"m = build_bench_model({size!r}); r = memory(m); r['rss_after_imports_mb'] = r0; print(json.dumps(r))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])
