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
import time
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from leafsim import __version__
from leafsim.appearance.view import LeafView
from leafsim.base.errors import LeafsimError, LeafsimWarning
from leafsim.base.fileio import atomic_write_bytes, npz_bytes, read_json
from leafsim.config.species import get_species
from leafsim.export.mesh import export_mesh
from leafsim.pipeline import build_leaf
from leafsim.scene.layout import clear_leaf_folder, leaf_dir
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
    """True when ``done.json`` of the leaf names this job's key and it and ``view.npz`` hold
    what a finished leaf writes (:func:`check_done`, :func:`load_view`): a rerun skips such a
    leaf, and simulates one whose files were damaged or edited again."""
    folder = leaf_dir(out, job.name)
    try:
        if check_done(folder / "done.json").get("key") != job.key:
            return False
        load_view(folder / "view.npz")
    except (OSError, LeafsimError):
        return False
    return True


#: done.json's numbers: name → (kind, smallest, largest)
_DONE = {"frames": (int, 0, 10 ** 9), "time_s": (float, 0.0, 1e9), "water_left": (float, 0.0, 1.0),
         "season": (float, 0.0, 1e12), "particles_simulated": (int, 1, 10 ** 9), "particles_shown": (int, 1, 10 ** 9),
         "margin_lift": (float, -1e3, 1e3), "area_3d": (float, 0.0, 1e3), "area_top": (float, 0.0, 1e3)}


def check_done(path: Path) -> dict:
    """``done.json`` of a finished leaf, its numbers checked (finite, in range); LeafsimError
    naming the file and key otherwise."""
    d = read_json(path, "leaf summary", max_bytes=1 << 20)
    if not isinstance(d, dict) or not isinstance(d.get("key"), str):
        raise LeafsimError(f"{path}: expected an object with the job's key")
    for k, (kind, lo, hi) in _DONE.items():
        v = d.get(k)
        ok = isinstance(v, (int, float)) and not isinstance(v, bool) and (kind is float or isinstance(v, int))
        if not ok or not (lo <= v <= hi):  # NaN fails the comparison
            raise LeafsimError(f"{path}: '{k}' is {v!r}, expected a{'n integer' if kind is int else ' number'} in [{lo}, {hi}]")
    return d


def load_view(path: Path) -> dict:
    """The ``view.npz`` arrays of a finished leaf (:func:`view_arrays`), each checked for the
    key, dtype kind, shape and range a scene composition draws; LeafsimError naming the file
    and array otherwise."""
    if not path.is_file():
        raise LeafsimError(f"{path}: not a regular file")
    try:
        with np.load(path, allow_pickle=False) as z:
            v = {k: z[k] for k in z.files}
    except Exception as e:  # zip, zlib, numpy or a pickled member
        raise LeafsimError(f"{path}: cannot read ({type(e).__name__}: {str(e).splitlines()[0][:80] if str(e) else ''})") from None

    def bad(name, why):
        return LeafsimError(f"{path}: array '{name}' {why}")

    kinds = {"positions": "f", "triangles": "i", "colours": "f", "thickness": "f", "length": "f",
             "vein_index": "i", "vein_width": "f", "vein_start": "i", "vein_order": "i"}
    for name, kind in kinds.items():
        if name not in v:
            raise bad(name, "is missing")
        if v[name].dtype.kind != kind:
            raise bad(name, f"is {v[name].dtype}, expected {'floats' if kind == 'f' else 'integers'}")
        if kind == "f" and not np.isfinite(v[name]).all():
            raise bad(name, "holds NaN or infinite values")
    q, tri, col = v["positions"], v["triangles"], v["colours"]
    length, thick = float(np.asarray(v["length"]).reshape(-1)[0]) if v["length"].size == 1 else -1.0, v["thickness"]
    if not (0.0 < length <= 10.0):
        raise bad("length", "is not a leaf length in (0, 10] m")
    if thick.size != 1 or not (0.0 < float(thick.reshape(-1)[0]) <= 0.1 * length):
        raise bad("thickness", "is not a thickness in (0, L/10]")
    if q.ndim != 2 or q.shape[1] != 3 or len(q) == 0 or np.abs(q - q.mean(0)).max() > 100.0 * length:
        raise bad("positions", f"is {q.shape}, expected (m, 3) within 100 leaf lengths of their centre (a free leaf falls far)")
    m = len(q)
    if tri.ndim != 2 or tri.shape[1] != 3 or not len(tri) or tri.min() < 0 or tri.max() >= m:
        raise bad("triangles", f"is {tri.shape}, expected (t, 3) indices into the {m} positions")
    if col.shape != (m, 3) or col.min() < 0.0 or col.max() > 1.0:
        raise bad("colours", f"is {col.shape}, expected ({m}, 3) linear RGB in [0, 1]")
    vc = v.get("vein_colours")  # optional: a leaf finished before 6 December has none
    if vc is not None and (vc.dtype.kind != "f" or vc.shape != (m, 3) or not np.isfinite(vc).all()
                           or vc.min() < 0.0 or vc.max() > 1.0):
        raise bad("vein_colours", f"is {vc.dtype} {vc.shape}, expected ({m}, 3) linear RGB in [0, 1]")
    vi, vs, vw, vo = v["vein_index"], v["vein_start"], v["vein_width"], v["vein_order"]
    if vi.ndim != 1 or (len(vi) and (vi.min() < 0 or vi.max() >= m)):
        raise bad("vein_index", f"is not a list of indices into the {m} positions")
    if vs.ndim != 1 or not len(vs) or vs[0] != 0 or vs[-1] != len(vi) or (np.diff(vs) < 0).any():
        raise bad("vein_start", "is not the vein polylines' offsets into vein_index")
    if vw.shape != vi.shape or (vw < 0).any() or (len(vw) and vw.max() > length):
        raise bad("vein_width", "is not one width in [0, L] per vein point")
    if vo.shape != (len(vs) - 1,):
        raise bad("vein_order", "is not one order per vein polyline")
    return v


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


def view_arrays(model: Model, state: State, params, view: LeafView | None = None) -> dict:
    """What a scene composition draws of one leaf (``view.npz``): layer-T positions, triangles,
    linear RGB colours (``view``'s: the species' own, :meth:`LeafView.of_species`, as ``leafsim
    export`` and the window draw it; without one, the pigments' palette colour), the vein
    tissue's own (:meth:`LeafView.vein_colours`), and the veins as flat index/width/order arrays."""
    v = view if view is not None else LeafView(model)
    rgb, _ = v.colours(state, params)
    vein_rgb = v.vein_colours(state, params)
    lines = model.vein_polylines()
    idx = [v.remap[i] for i, _, _ in lines]
    return {"positions": state.particle_q[v.T], "triangles": v.remap[model.tri_T].astype(np.int32),
            "colours": np.asarray(rgb, np.float32),
            "vein_colours": np.asarray(rgb if vein_rgb is None else vein_rgb, np.float32),
            "thickness": np.float64(model.thickness),
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
        with warnings.catch_warnings():  # the scene's planner said them once, for every leaf of the species
            warnings.simplefilter("ignore", LeafsimWarning)
            result = _run(job, folder)
        result.update(name=job.name, ok=True, seconds=time.perf_counter() - t0, cpu_s=time.process_time() - c0)
        return result
    except Exception as e:  # every failure is this leaf's only
        try:
            clear_leaf_folder(folder)  # what it wrote so far; never anything else
        except (OSError, LeafsimError):
            pass
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
    view = LeafView.of_species(sp, shown_model, shown_params, seed=job.seed)
    files = {"view.npz": npz_bytes(view_arrays(shown_model, shown, shown_params, view))}
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
        _export(job, sp, shown_model, shown_params, [show(s) for s in snaps] or [shown], folder, view)
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
    clear_leaf_folder(folder)  # a stale leaf of an older job: start clean (its files only)
    for name, data in files.items():
        p = folder / name
        p.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(p, data, name)


def _export(job: LeafJob, sp, model: Model, params, states: list, folder: Path, view: LeafView) -> None:
    """The leaf through the exporter with the species' view (its photo and young colour), as
    ``leafsim export`` writes it."""
    o = job.output
    last = states[-1] if isinstance(states, list) else states
    about = {"leaf": job.name, "species": sp.key, "seed": int(job.seed), "frame": last.frame,
             "time_s": round(float(last.time), 9), "water_fraction": round(model.water_fraction(last.particle_water), 6)}
    export_mesh(model, states, folder / f"leaf.{o['mesh']}", params=params, view=view,
                layers=o["layers"], veins=o["veins"], texture=o["texture"], name=job.name, extras={"leafsim": about},
                keep=(sp.config, sp.image, sp.senescent.image if sp.senescent is not None else None))
