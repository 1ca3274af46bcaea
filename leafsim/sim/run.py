"""Headless runs, per-frame statistics, atomic .npz export and shape metrics."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from ..errors import LeafsimError
from ..fileio import atomic_write_bytes
from ..params import ParamSet
from .kernels.pbd import residual
from .model import LAYER_T, LAYER_V, Model, State
from .simulator import Simulator


def frame_stats(model: Model, state: State, ms: dict, sim: Simulator | None = None) -> dict:
    """Total water per layer, max residual |C|/l, kinetic energy [J], NaN flag, ms per stage."""
    w = state.particle_water
    lay = model.particle_layer
    q, qd = state.particle_q, state.particle_qd
    finite = bool(np.isfinite(q).all() and np.isfinite(qd).all() and np.isfinite(w).all())
    m = model.particle_cytosol + w
    out = {
        "frame": state.frame,
        "time": state.time,
        "water_T": float(w[lay == LAYER_T].sum()),
        "water_V": float(w[lay == LAYER_V].sum()),
        "residual": float(residual(q, model.spring_ij, state.spring_rest)) if finite else float("nan"),
        "kinetic": float(0.5 * (m * (qd * qd).sum(1)).sum()) if finite else float("nan"),
        "nan": not finite,
        "ms": {k: round(v, 4) for k, v in ms.items()},
    }
    if sim is not None:
        out["iterations"] = sim.iterations
    return out


class StatsStream:
    """Per-frame statistics as JSON lines, written and flushed frame by frame, so that a run
    killed at any moment (even SIGKILL) keeps every frame it finished.

    ``keep_until``: continue an earlier file (``--resume``): its lines up to that frame are kept
    (the rest, computed after the checkpoint, are dropped; they are computed again), then new
    lines are appended.  Without it the file is started afresh.  Errors name the path.
    """

    def __init__(self, path, keep_until: int | None = None):
        self.path = Path(path)
        try:
            if keep_until is not None:
                self._keep(keep_until)
                self.f = open(self.path, "a", encoding="utf-8")
            else:
                self.f = open(self.path, "w", encoding="utf-8")
        except OSError as e:
            raise LeafsimError(f"--stats {self.path}: cannot write statistics ({e.strerror or e})") from None

    def _keep(self, frame: int) -> None:
        kept = []
        if self.path.exists():
            for line in self.path.read_text(encoding="utf-8", errors="replace").splitlines():
                try:
                    st = json.loads(line)
                except ValueError:
                    break  # a line cut by a kill
                if not isinstance(st, dict) or st.get("frame", frame + 1) > frame:
                    break
                kept.append(line + "\n")
        atomic_write_bytes(self.path, "".join(kept).encode(), "statistics")

    def write(self, st: dict) -> None:
        self.f.write(json.dumps(st, sort_keys=True) + "\n")
        self.f.flush()

    def close(self) -> None:
        if not self.f.closed:
            self.f.flush()
            os.fsync(self.f.fileno())
            self.f.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def run_headless(model: Model, params: ParamSet, frames: int, effects=None, stats_path=None, on_frame=None,
                 seed: int = 0, state: State | None = None, simulator: Simulator | None = None, stats_stream=None):
    """Simulate ``frames`` frames with one :class:`Simulator`; returns (state, stats list).

    ``effects``: iterable of effect names (default: the ``effects.*`` parameters).
    ``stats_path``: stream the stats there as JSON lines (:class:`StatsStream`, flushed every
    frame); or ``stats_stream``: an open :class:`StatsStream` to write to (left open).
    ``on_frame(frame, state, stats)``: called after every frame (after its stats line is
    written); return False to stop.
    ``seed``: colour variation of the fresh leaf; ``state``: continue from this state instead
    of a fresh leaf; ``simulator``: use this one (made for ``model``/``params``) instead of a new one.
    """
    if frames < 0:
        raise LeafsimError(f"run: frames = {frames} must be ≥ 0")
    sim = simulator if simulator is not None else Simulator(model, params, effects, seed=seed)
    state = sim.state() if state is None else state
    own = StatsStream(stats_path) if stats_path and stats_stream is None else None
    stream = stats_stream or own
    stats = []
    try:
        for _ in range(frames):
            ms = sim.step(state)
            st = frame_stats(model, state, ms, sim)
            stats.append(st)
            if stream is not None:
                stream.write(st)
            if on_frame is not None and on_frame(state.frame, state, st) is False:
                break
            if st["nan"]:
                break
    finally:
        if own is not None:
            own.close()
    return state, stats


def save_npz(path, model: Model, state: State) -> None:
    """Write model topology and state arrays to ``path`` (.npz) atomically (temp + os.replace)."""
    import io

    buf = io.BytesIO()
    np.savez_compressed(
        buf, particle_rest=model.particle_rest, particle_layer=model.particle_layer, tri_T=model.tri_T,
        tri_V=model.tri_V, spring_ij=model.spring_ij, vein_particles=model.vein_particles,
        vein_start=model.vein_start, vein_order=model.vein_order, vein_width=model.vein_width,
        particle_texcoord=model.particle_texcoord, particle_q=state.particle_q,
        particle_qd=state.particle_qd, particle_water=state.particle_water,
        particle_water0=model.particle_water0, spring_rest=state.spring_rest,
        scalars=state.scalars)
    atomic_write_bytes(path, buf.getvalue(), "positions")


def _area3(q, tri):
    a, b, c = q[tri[:, 0]], q[tri[:, 1]], q[tri[:, 2]]
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def leaf_frame(model: Model, state: State) -> np.ndarray:
    """Positions in the leaf's own frame: best rigid fit (Kabsch) of layer T onto its rest."""
    T = model.particle_layer == LAYER_T
    P = state.particle_q[T]
    Q = model.particle_rest[T]
    pc, qc = P.mean(0), Q.mean(0)
    H = (P - pc).T @ (Q - qc)
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T))
    R = Vt.T @ np.diag([1, 1, d]) @ U.T
    return (state.particle_q - pc) @ R.T + qc


def shape_metrics(model: Model, state: State, own_frame: bool | None = None) -> dict:
    """Shape of the leaf.

    area_ratio : 3D area of layer T now / at rest.
    margin_lift : (max z of contour particles − min z of layer T) / leaf length.
    max_height : (max z − min z of layer T) / length.
    inverted : number of triangles whose V particle is below the triangle (layer inversion).
    max_displacement : largest |q − rest| / length.
    own_frame : measure z in the leaf's best-fit rigid frame (default: True unless on the ground).
    """
    q = state.particle_q
    if own_frame:
        q = leaf_frame(model, state)
    T = model.particle_layer == LAYER_T
    L = model.length
    tri = model.tri_T
    a, b, c = q[tri[:, 0]], q[tri[:, 1]], q[tri[:, 2]]
    n = np.cross(b - a, c - a)
    hv = ((q[model.tri_V] - a) * n).sum(1)
    zc = q[model.contour_particles, 2]
    zmin = q[T, 2].min()
    return {
        "area_ratio": float(_area3(state.particle_q, tri).sum() / _area3(model.particle_rest, tri).sum()),
        "margin_lift": float((zc.max() - zmin) / L),
        "margin_lift_mean": float((np.median(zc) - zmin) / L),
        "max_height": float((q[T, 2].max() - zmin) / L),
        "inverted": int((hv <= 0).sum()),
        "max_displacement": float(np.linalg.norm(state.particle_q - model.particle_rest, axis=1).max() / L),
        "water_fraction_left": float(state.particle_water.sum() / model.particle_water0.sum()),
    }
