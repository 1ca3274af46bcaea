"""How many render threads Mesa's software rasteriser (llvmpipe) may use beside the simulation.

On a machine without a GPU the window is drawn by llvmpipe, whose render threads compete for the
cores with the simulation worker.  Leaving the worker a core of its own is the better trade on
small machines, measured on the project's 2-core machine (``python -m leafsim.measure.gui_bench
--scales 1 --ground 1``, default maple, two interleaved pairs): with 2 render threads 41.7 / 34.9
fps and 0.116 / 0.111 simulated seconds per second; with 1, 32.8 / 30.8 fps and 0.171 / 0.152
(the leaf dries about 40 % faster while playing, at 31 fps).  A GPU driver ignores the variable;
a value already in the environment wins.  Imports nothing heavy (the bench's parent process
uses it too).
"""

from __future__ import annotations

import os


def render_threads(cpus: int | None = None) -> str:
    """LP_NUM_THREADS for this machine: every core but one for the simulation worker, at least
    1 and at most 4."""
    n = cpus if cpus is not None else (os.cpu_count() or 1)
    return str(max(1, min(4, n - 1)))
