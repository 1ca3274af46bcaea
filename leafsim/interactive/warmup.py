"""The first run of a leafsim version compiles its numba kernels; this module does it up front
and says so.

Kernels are compiled once per version of their sources and then load from the on-disk cache
(:mod:`leafsim.base.cache`) in well under a second.  The compile itself takes 20 s to more than
a minute on a 2-core machine, and a command or a window that sits silent that long looks hung.
``scripts/setup.sh`` compiles during set-up; whoever skips it, or upgrades leafsim without
running it again, gets the compile here instead, announced: the CLI prints a line before it and
one after it (how many kernels, how long), and the GUI's status bar shows it as the first stage
of the first build with a count of the kernels compiled so far.

A marker file in the cache folder (named after the digest of the kernel sources and their
folder, so a new version, or the same one checked out elsewhere, is cold again) records that
the default drying's kernels have been compiled.  Kernels outside that path (the static and Sun integrators, float32 dynamics) still compile on first use,
in seconds.
"""

from __future__ import annotations

import hashlib
import os
import sys
import threading
import time
from pathlib import Path
from typing import Callable

import numpy as np

from leafsim.base.cache import configure_numba_cache, kernel_sources_digest

#: what the user is told while the kernels compile
MESSAGE = "compiling the simulation kernels: the first run of this leafsim version does it once (20 s to about a minute)"


_lock = threading.Lock()
_done_here = False  # this process has warmed up (or found the cache warm)
_marker_path: list = []  # computed once per process: [Path | None]


def _marker() -> Path | None:
    """The marker file: in the kernel cache folder, named after what numba's cache depends on
    (the kernel sources' digest and folder, numba, Python, the CPU), so any of them changing is
    cold again.  None when there is no writable cache folder."""
    if not _marker_path:
        folder = configure_numba_cache()
        path = None
        if folder:
            import platform

            import numba

            try:
                from llvmlite import binding

                cpu = binding.get_host_cpu_name()
            except Exception:  # an llvmlite without it: the machine's name for the processor
                cpu = platform.machine()
            # numba files its cache under the kernel sources' own folder (a checkout at another
            # path, or a moved one, compiles anew), so the marker is that folder's too
            # (as numba names it: the absolute path, links not resolved)
            where = hashlib.sha256(os.path.dirname(os.path.dirname(os.path.abspath(__file__))).encode()).hexdigest()[:12]
            key = f"{kernel_sources_digest()}-{numba.__version__}-py{sys.version_info[0]}{sys.version_info[1]}-{cpu}-{where}"
            path = Path(folder) / ("leafsim-warm-" + "".join(c if c.isalnum() or c in "-._" else "_" for c in key))
        _marker_path.append(path)
    return _marker_path[0]


def is_warm() -> bool:
    """The default drying's kernels are compiled: cached for this version of the sources,
    numba, Python and CPU, or compiled by this process already."""
    if _done_here:
        return True
    m = _marker()
    return m is not None and m.is_file()


class _Counter:
    """numba compile events → ``report(kernels compiled so far, seconds)``."""

    def __init__(self, report, t0):
        self.n, self.report, self.t0 = 0, report, t0

    def listener(self):
        from numba.core import event

        counter = self

        class L(event.Listener):
            def on_start(self, ev):
                pass

            def on_end(self, ev):
                counter.n += 1
                if counter.report is not None:
                    counter.report(counter.n, time.perf_counter() - counter.t0)

        return L()


def _exercise() -> None:
    """Compile what a default drying and the window's first frames use: a draft maple built and
    stepped (dynamics, osmosis, shrink, contacts, colour), the watchdog's momenta and the drying
    path's prolongation, one static equilibrium solve, every
    pigment kernel, the leaf's colours and the renderer's geometry (no OpenGL needed)."""
    from leafsim.appearance.view import LeafView
    from leafsim.config.presets import quality_overrides
    from leafsim.config.species import DEFAULT_SPECIES, get_species
    from leafsim.pipeline import build_leaf
    from leafsim.render.geom import bounds, orient_up, vertex_normals
    from leafsim.sim.pigments import precompile
    from leafsim.sim.run import Run

    sp = get_species(DEFAULT_SPECIES, None)
    params = sp.params.with_overrides(quality_overrides("draft"), where="warm-up")
    model = build_leaf(sp, params, 0).model
    run = Run(model, params, seed=0)
    for _ in range(2):
        run.step()
    run.stats()  # the constraint residual and momenta the stats panel shows
    # the watchdog's momenta (its first check comes at frame 5) and the drying path's
    # prolongation (draft runs without a path), with the types the default run passes
    from leafsim.sim.kernels.transfer import prolong_pair
    from leafsim.sim.watchdog import momenta

    q = np.ascontiguousarray(run.state.particle_q)
    momenta(model.particle_cytosol + run.state.particle_water, q, np.ascontiguousarray(run.state.particle_qd))
    prolong_pair(np.array([0, 1], np.int64), np.array([0], np.int64), np.ones(1), q[:1].copy(), q[:1].copy(),
                 np.empty((1, 3)), np.empty((1, 3)))
    # the static equilibrium's kernels: a species whose drying finishes with it (dynamics.finish,
    # oak) would otherwise compile them at its hand-over, silently
    static = params.with_overrides({"dynamics.scene": "ground", "dynamics.integrator": "static",
                                    "dynamics.static_iterations": 2}, where="warm-up")
    run.sim._dynamics.configure(static, run.sim.effects)
    run.sim._dynamics.apply(run.state)
    precompile()
    mesh = LeafView(model, None, run.sim.state().pigments).mesh(run.state, params)
    pos = np.ascontiguousarray(mesh.positions, dtype=np.float32)  # as the renderer holds them
    tri = orient_up(pos, np.asarray(mesh.triangles))
    vertex_normals(pos, tri)
    bounds(pos)


def warm_up(report: Callable[[int, float], None] | None = None,
            exercise: Callable[[], None] | None = None) -> tuple[int, float, bool] | None:
    """Compile the kernels now unless they are compiled already (then None, at once).
    ``report(n, seconds)`` is called as each kernel finishes compiling; ``exercise`` is what
    compiles them (default: :func:`_exercise`).  One warm-up at a time: a second caller waits
    for the first and then finds the kernels compiled.  Returns (kernels compiled, seconds,
    whether the cache keeps them) and marks the cache warm.  An exercise that fails raises
    (nothing is marked)."""
    global _done_here
    if is_warm():
        return None
    from numba.core import event

    with _lock:
        if is_warm():  # another thread warmed up while this one waited
            return None
        t0 = time.perf_counter()
        counter = _Counter(report, t0)
        with event.install_listener("numba:compile", counter.listener()):
            (exercise or _exercise)()
        _done_here = True
        m, kept = _marker(), False
        if m is not None:
            try:
                m.touch()
                kept = True
            except OSError:  # a read-only cache folder
                pass
        return counter.n, time.perf_counter() - t0, kept


def warm_up_cli(stream=None) -> None:
    """:func:`warm_up` for a command line: one line before (on a terminal, a live count) and
    one after, on stderr (stdout stays the command's own: ``--json`` prints one object).  A
    warm-up that fails is said in one line and the command goes on (its own run compiles what
    it needs, or fails with its own message)."""
    stream = sys.stderr if stream is None else stream
    if is_warm():
        return
    live = getattr(stream, "isatty", lambda: False)()
    print(f"leafsim: {MESSAGE} …", file=stream, flush=True)

    def report(n, s):
        if live:
            print(f"\r  {n} kernels compiled, {s:.0f} s", end="", file=stream, flush=True)

    try:
        done = warm_up(report)
    except Exception as e:  # never stop the user's command for the warm-up's sake
        print(("\n" if live else "") + f"leafsim: the kernel warm-up failed ({type(e).__name__}: {' '.join(str(e).split())[:200]}); "
              "going on, the run compiles what it needs", file=stream, flush=True)
        return
    if done is not None:
        where = "cached for the next runs" if done[2] else "no writable cache folder: the next run compiles them again"
        print(("\n" if live else "") + f"leafsim: compiled {done[0]} kernels in {done[1]:.0f} s ({where})", file=stream, flush=True)
