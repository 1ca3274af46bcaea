"""Per-frame statistics of a run: :func:`frame_stats` (water per layer, constraint residual,
kinetic energy, NaN flag, ms per stage) and :class:`StatsStream`, the JSON-lines file that
survives any kill."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from leafsim.base.errors import LeafsimError
from leafsim.base.fileio import atomic_write_bytes, output_target
from leafsim.sim.kernels.pbd import residual
from leafsim.sim.model import LAYER_T, LAYER_V, Model, State


def frame_stats(model: Model, state: State, ms: dict, sim=None) -> dict:
    """The blade's water per layer [kg] (``water_T``, ``water_V``; the petiole's left out, as in
    Model.water_fraction), max residual |C|/l, kinetic energy [J], simulated time [s], NaN flag,
    CPU ms per stage (the stepping thread's: :meth:`~leafsim.sim.simulator.Simulator.step`)
    (with ``sim``: its iterations and whether the drying-path mesh carried the mechanics).

    The residual is the solver's: over the springs of the mesh that carried the mechanics
    (``sim.mechanics_mesh``).  While a drying path carries them the own mesh only takes their
    positions through the prolongation, whose fine-scale error is no constraint the solver
    left unmet (hornbeam's small margin teeth read 20 % there against 1.5 % on the path mesh)."""
    w = state.particle_water
    lay = model.particle_layer
    q, qd = state.particle_q, state.particle_qd
    finite = bool(np.isfinite(q).all() and np.isfinite(qd).all() and np.isfinite(w).all())
    m = model.particle_cytosol + w
    out = {
        "frame": state.frame,
        "time": state.time,
        "water_T": float(w[(lay == LAYER_T) & model.blade_particles].sum()),
        "water_V": float(w[(lay == LAYER_V) & model.blade_particles].sum()),
        "residual": _solver_residual(model, state, sim) if finite else float("nan"),
        "kinetic": float(0.5 * (m * (qd * qd).sum(1)).sum()) if finite else float("nan"),
        "nan": not finite,
        "ms": {k: round(v, 4) for k, v in ms.items()},
    }
    if sim is not None:
        out["iterations"] = sim.iterations
        out["on_path"] = bool(getattr(sim, "on_path", False))  # the mechanics ran on the drying-path mesh
        out["mesh"] = int(getattr(sim, "mechanics_mesh", 0))  # which: 1 the path mesh, 2 its own path mesh
    return out


def _solver_residual(model: Model, state: State, sim) -> float:
    """max |C| / l over the springs of the mesh that carried the last step's mechanics."""
    for _ in range(int(getattr(sim, "mechanics_mesh", 0)) if sim is not None else 0):
        if model.path is None or state.path is None:
            break
        model, state = model.path, state.path
    return float(residual(state.particle_q, model.spring_ij, state.spring_rest))


class StatsStream:
    """Per-frame statistics as JSON lines, written and flushed frame by frame, so that a run
    killed at any moment (even SIGKILL) keeps every frame it finished.

    ``keep_until``: continue an earlier file (``--resume``): its lines up to that frame are kept
    (the rest, computed after the checkpoint, are dropped; they are computed again), then new
    lines are appended.  Without it the file is started afresh.  Errors name the path.
    """

    def __init__(self, path, keep_until: int | None = None):
        self.path = Path(path)
        self.append = keep_until is not None
        self.f = None
        try:
            if self.append:
                self._keep(keep_until)
                self._open()
            else:  # a fresh file replaces the old one at the first line: a run stopped before any
                output_target(self.path, "statistics")  # frame leaves the old one as it was
        except OSError as e:
            raise LeafsimError(f"--stats {self.path}: cannot write statistics ({e.strerror or e})") from None

    def _open(self) -> None:
        # checked again now (the build ran since the command checked it): a regular file or
        # nothing, never through a link (O_NOFOLLOW closes the gap to the open)
        output_target(self.path, "statistics")
        flags = os.O_WRONLY | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | (os.O_APPEND if self.append else os.O_TRUNC)
        self.f = os.fdopen(os.open(self.path, flags, 0o666), "a" if self.append else "w", encoding="utf-8")

    def _keep(self, frame: int) -> None:
        kept, last = [], 0
        if self.path.exists():
            for line in self.path.read_text(encoding="utf-8", errors="replace").splitlines():
                try:
                    st = json.loads(line)
                except ValueError:
                    break  # a line cut by a kill
                k = st.get("frame") if isinstance(st, dict) else None
                if isinstance(k, bool) or not isinstance(k, int) or k > frame:
                    break  # not a line of ours (a frame that is no integer): kept no further
                kept.append(line + "\n")
                last = k
            if kept and last < frame:  # the run that went on from there wrote no statistics
                raise LeafsimError(f"--stats {self.path}: its frames end at {last}, but the run resumes from frame {frame}: "
                                   f"frames {last + 1}–{frame} are missing (that run had no --stats); give another "
                                   f"--stats file to start one at frame {frame + 1}")
        atomic_write_bytes(self.path, "".join(kept).encode(), "statistics")

    def write(self, st: dict) -> None:
        if self.f is None:
            try:
                self._open()
            except OSError as e:
                raise LeafsimError(f"--stats {self.path}: cannot write statistics ({e.strerror or e})") from None
        self.f.write(json.dumps(st, sort_keys=True) + "\n")
        self.f.flush()

    def finish(self) -> None:
        """The run ended normally: its file exists even when it wrote no line (no frame ran)."""
        if self.f is None:
            try:
                self._open()
            except OSError as e:
                raise LeafsimError(f"--stats {self.path}: cannot write statistics ({e.strerror or e})") from None

    def close(self) -> None:
        if self.f is not None and not self.f.closed:
            self.f.flush()
            os.fsync(self.f.fileno())
            self.f.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
