"""One leaf of a scene: build, simulate until its stopping criterion, write its outputs (core).

:func:`run_leaf` is the unit of work every executor runs (the local process pool and Dask
workers alike): it takes a picklable :class:`LeafJob`, writes into ``OUT/leaves/NAME/`` and
returns a small result dict.  Everything the leaf writes depends only on the job (its own
seed, no clock), so the files are the same bytes whoever runs it; ``done.json`` is written
last and names the job's key, so a rerun skips a finished leaf.  A failure (NaN, a stopping
criterion not reached, any error) leaves no files of that leaf and is returned as a
one-line message.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from leafsim import __version__
from leafsim.appearance.photo import species_photo_rgba
from leafsim.appearance.view import LeafView
from leafsim.base.errors import LeafsimError
from leafsim.base.fileio import atomic_write_bytes, npz_bytes
from leafsim.config.species import get_species
from leafsim.export.mesh import export_mesh
from leafsim.pipeline import build_leaf
from leafsim.scene.layout import leaf_dir
from leafsim.scene.lod import LevelOfDetail, lod_error
from leafsim.sim.metrics import Probe
from leafsim.sim.model import Model, State
from leafsim.sim.run import Run, Stop


@dataclass(frozen=True)
class LeafJob:
    """Everything one leaf needs (picklable, hashable into :attr:`key`).

    name : leaf name (folder under ``leaves/``); species, config : species key and config path
    (None = the default config); overrides : parameter values over the species'; seed;
    effects : enabled effect names or None (the parameters' ``effects.*``); stop : {"kind":
    "frames"|"water_left"|"season", "value", "max_frames"}; lod : {"simulate", "show"} mesh
    spacings or None; check_lod : also simulate the fine mesh and write ``lod.json``;
    output : {"end_state", "every", "mesh", "layers", "veins", "texture", "stats"};
    config_digest : sha256 of the species config (a changed config reruns the leaf).
    """
    name: str
    species: str
    config: str | None
    overrides: dict
    seed: int
    effects: tuple | None
    stop: dict
    lod: dict | None
    check_lod: bool
    output: dict
    config_digest: str = ""
    meta: dict = field(default_factory=dict)

    @property
    def key(self) -> str:
        d = asdict(self)
        d.pop("meta")
        d["version"] = __version__
        return hashlib.sha256(json.dumps(d, sort_keys=True, default=str).encode()).hexdigest()[:20]


class LeafFailure(LeafsimError):
    """A leaf that could not be simulated (reported by name; the other leaves go on)."""


def is_done(job: LeafJob, out: Path) -> bool:
    """True when ``done.json`` of the leaf names this job's key (a rerun skips it)."""
    try:
        return json.loads((leaf_dir(out, job.name) / "done.json").read_text())["key"] == job.key
    except (OSError, ValueError, KeyError, TypeError):
        return False


# ------------------------------------------------------------------ simulation

def _water_left(model: Model, state: State) -> float:
    return model.water_fraction(state.particle_water)


def _season(state: State) -> float:
    return float(state.pigments.age) if state.pigments is not None else 0.0


def stop_of(stop: dict) -> Stop:
    """A scene group's ``stop`` object as a :class:`~leafsim.sim.run.Stop`."""
    k, v = stop["kind"], stop["value"]
    return Stop(frames=v if k == "frames" else None, water_left=v if k == "water_left" else None,
                season=v if k == "season" else None, max_frames=stop["max_frames"])


def simulate(model: Model, params, job: LeafJob, stop: dict, keep_every: int = 0, stats: bool = False):
    """Run one leaf (:class:`~leafsim.sim.run.Run`) until ``stop`` is reached; returns (end
    state, snapshots every ``keep_every`` frames incl. frame 0 and the end, stats lines)."""
    run = Run(model, params, job.effects, seed=job.seed)
    snaps = [run.state.copy()] if keep_every else []
    lines = []
    try:
        for _ in run.frames(stop_of(stop)):
            if stats:
                st = run.stats({})
                st.pop("ms")
                lines.append(st)
            if keep_every and run.state.frame % keep_every == 0:
                snaps.append(run.state.copy())
    except LeafsimError as e:  # not reached, or blew up: this leaf fails alone
        raise LeafFailure(str(e)) from None
    if keep_every and snaps[-1].frame != run.state.frame:
        snaps.append(run.state.copy())
    return run.state, snaps, lines


# ------------------------------------------------------------------ outputs

def state_arrays(model: Model, state: State) -> dict:
    """Topology + state arrays of one leaf (the ``state.npz`` members)."""
    out = {"particle_rest": model.particle_rest, "particle_layer": model.particle_layer, "tri_T": model.tri_T,
           "particle_petiole": ~model.blade_particles,
           "tri_V": model.tri_V, "spring_ij": model.spring_ij, "particle_q": state.particle_q,
           "particle_qd": state.particle_qd, "particle_water": state.particle_water,
           "particle_water0": model.particle_water0, "spring_rest": state.spring_rest, "scalars": state.scalars}
    if state.pigments is not None:
        for name in ("chlorophyll", "carotenoid", "anthocyanin", "browning"):
            out[f"pigment_{name}"] = getattr(state.pigments, name)
    return out


def view_arrays(model: Model, state: State, params) -> dict:
    """What a scene composition draws of one leaf (``view.npz``): layer-T positions, triangles,
    linear RGB colours from the pigments, and the veins as flat index/width/order arrays."""
    v = LeafView(model)
    rgb, _ = v.colours(state, params)
    lines = model.vein_polylines()
    idx = [v.remap[i] for i, _, _ in lines]
    return {"positions": state.particle_q[v.T], "triangles": v.remap[model.tri_T].astype(np.int32),
            "colours": np.asarray(rgb, np.float32), "thickness": np.float64(model.thickness),
            "length": np.float64(model.length),
            "vein_index": np.concatenate(idx) if idx else np.zeros(0, np.int64),
            "vein_width": np.concatenate([w for _, w, _ in lines]) if lines else np.zeros(0),
            "vein_start": np.cumsum([0] + [len(i) for i in idx]).astype(np.int64),
            "vein_order": np.array([o for _, _, o in lines], np.int64)}


def _summary(model: Model, state: State, shown_model: Model, shown: State, shape) -> dict:

    f = Probe(shape).fields(shown_model, shown)
    return {"frames": state.frame, "time_s": round(state.time, 9), "water_left": _water_left(model, state),
            "season": _season(state), "particles_simulated": model.particle_count,
            "particles_shown": shown_model.particle_count, "margin_lift": f["margin_lift"],
            "area_3d": f["area_3d"], "area_top": f["area_top"]}


def run_leaf(job: LeafJob, out: str | Path) -> dict:
    """Simulate one leaf and write its files; never raises (failures come back as
    ``{"name", "ok": False, "error"}``)."""
    t0, c0 = time.perf_counter(), time.process_time()
    folder = leaf_dir(Path(out), job.name)
    try:
        _single_thread()
        result = _run(job, folder)
        result.update(name=job.name, ok=True, seconds=time.perf_counter() - t0, cpu_s=time.process_time() - c0)
        return result
    except Exception as e:  # every failure is this leaf's only
        shutil.rmtree(folder, ignore_errors=True)
        msg = str(e) if isinstance(e, LeafsimError) else f"{type(e).__name__}: {e}"
        return {"name": job.name, "ok": False, "error": " ".join(msg.split()), "seconds": time.perf_counter() - t0}


def _single_thread() -> None:
    """One numba thread per leaf: the executors parallelise over leaves."""
    import numba

    numba.set_num_threads(1)


def _build(job: LeafJob):

    sp = get_species(job.species, job.config)
    params = sp.params.with_overrides(job.overrides, where=f"leaf {job.name}")
    if job.lod is None:
        shape, _, model = build_leaf(sp, params, job.seed)
        return sp, params, shape, model, None
    lod = LevelOfDetail.build(sp, params, job.seed, job.lod["simulate"], job.lod["show"])
    return sp, lod.coarse_params, lod.shape, lod.coarse, lod


def _run(job: LeafJob, folder: Path) -> dict:
    t0 = time.perf_counter()
    sp, params, shape, model, lod = _build(job)
    o = job.output
    t1 = time.perf_counter()
    state, snaps, lines = simulate(model, params, job, job.stop, o["every"], o["stats"])
    t2 = time.perf_counter()
    show = (lambda s: s) if lod is None else lod.show
    shown_model = model if lod is None else lod.fine
    shown_params = params if lod is None else lod.fine_params
    shown = show(state)
    files = {"view.npz": npz_bytes(view_arrays(shown_model, shown, shown_params))}
    if o["end_state"]:
        files["state.npz"] = npz_bytes(state_arrays(model, state))
    for s in snaps if o["every"] else ():
        files[f"frames/state_{s.frame:06d}.npz"] = npz_bytes(state_arrays(model, s))
    if o["stats"]:
        files["stats.jsonl"] = "".join(json.dumps(x, sort_keys=True) + "\n" for x in lines).encode()
    summary = _summary(model, state, shown_model, shown, shape)
    timing = {"build_s": t1 - t0, "sim_s": t2 - t1}
    if job.check_lod and lod is not None:
        files["lod.json"], timing["fine_sim_s"] = _lod_check(job, lod, shown)
    _write(folder, files)
    if o["mesh"]:
        _export(job, sp, shown_model, shown_params, [show(s) for s in snaps] or [shown], folder)
    summary["key"] = job.key
    atomic_write_bytes(folder / "done.json", (json.dumps(summary, indent=1, sort_keys=True) + "\n").encode(), "leaf summary")
    return {**summary, **timing}


def _lod_check(job: LeafJob, lod, shown: State) -> tuple[bytes, float]:
    """Simulate the fine mesh with the same stopping criterion; its error report as JSON."""
    t = time.perf_counter()
    ref, _, _ = simulate(lod.fine, lod.fine_params, job, job.stop)
    dt = time.perf_counter() - t
    err = lod_error(lod.shape, lod.fine, shown, lod.fine, ref)
    err.update(frames_coarse=shown.frame, frames_fine=ref.frame, particles_coarse=lod.coarse.particle_count,
               particles_fine=lod.fine.particle_count, spacing_simulated=job.lod["simulate"],
               spacing_shown=job.lod["show"])
    return (json.dumps(err, indent=1, sort_keys=True) + "\n").encode(), dt


def _write(folder: Path, files: dict) -> None:
    if folder.exists():
        shutil.rmtree(folder)  # a stale leaf of an older job: start clean
    for name, data in files.items():
        p = folder / name
        p.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(p, data, name)


def _export(job: LeafJob, sp, model: Model, params, states: list, folder: Path) -> None:

    o = job.output
    photo = species_photo_rgba(sp, params) if o["texture"] == "photo" and sp.image is not None else None
    export_mesh(model, states, folder / f"leaf.{o['mesh']}", params=params, view=LeafView(model, photo),
                layers=o["layers"], veins=o["veins"], texture=o["texture"])
