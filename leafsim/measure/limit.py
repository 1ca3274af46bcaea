"""The mesh-converged limit of the drying (``leafsim accuracy --limit``) and every setting's
error against it.

The reference of :mod:`.accuracy` is one XPBD run one √2 refinement finer than the defaults,
so "within 10 % of the reference" says little about the distance to the converged answer.
This study solves the drying as a sequence of static equilibria (``dynamics.integrator =
static``, :mod:`leafsim.sim.equilibrium`: every solve to a stated force residual) on three or
more meshes refined by √2, Richardson-extrapolates every measure to zero mesh spacing and
reports each setting's error against that limit, with CPU seconds per dried leaf.

Richardson extrapolation: with values f₁, f₂, f₃ on spacings r, r/ρ, r/ρ² (ρ = √2) the
observed order is p = ln(|f₁ − f₂| / |f₂ − f₃|) / ln ρ and the limit f₃ + (f₃ − f₂)/(ρ^p − 1).
Fields (the probe points' positions in the leaf's own frame, heights, water) take one order
from their RMS differences and are extrapolated point by point.  An order outside
[``P_MIN``, ``P_MAX``] (the meshes are not in the asymptotic range, or the differences do not
shrink) is clamped and reported; the grid-convergence index GCI = 1.25 |f₃ − f₂| / (ρ^p − 1)
(Roache 1998) states how far the limit itself may be off.

Example
-------
>>> report = limit_study("oak", quick=True)                         # doctest: +SKIP
>>> write_limit_report(report, "out/limit")                         # doctest: +SKIP
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from leafsim.base.errors import LeafsimError
from leafsim.base.fileio import atomic_write_bytes
from leafsim.config.presets import QUALITY
from leafsim.config.species import get_species
from leafsim.measure.accuracy import (
    METRIC_NAMES,
    METRICS,
    WATER_TIMES,
    Setting,
    _dry_time_estimate,
    _progress,
    errors,
    run_setting,
)
from leafsim.pipeline import leaf_shape
from leafsim.sim.metrics import Probe

#: refinement ratio between the limit study's meshes
RATIO = math.sqrt(2.0)
#: the meshes of the limit, × the default spacing (each √2 finer)
LIMIT_MESHES = (1.0, 1.0 / RATIO, 0.5)
#: equilibrium solves every this many frames, and their force tolerance (× a particle's weight)
LIMIT_EVERY = 32
LIMIT_TOLERANCE = 1e-2
#: a measure is extrapolated only with an observed order in this range (clamped above): below
#: first order the meshes are pre-asymptotic for it (the water field the shape rides on diverges
#: there: docs/accuracy.md)
P_MIN, P_MAX = 1.0, 4.0
#: the scalar measures extrapolated (the fields are extrapolated point by point)
SCALARS = ("margin_lift", "margin_lift_mean", "area_3d", "area_top")


def richardson(values: list, ratio: float = RATIO) -> tuple:
    """Extrapolate the last three of ``values`` (scalars or arrays on meshes each ``ratio``
    finer) to zero spacing: (limit, order used (nan: not extrapolated), order observed (nan:
    not observable), GCI).

    Converging monotonically (the two differences of one sign, for arrays a positive inner
    product) with an observed order p = ln(|f₁ − f₂| / |f₂ − f₃|) / ln ρ of at least ``P_MIN``
    (above ``P_MAX`` clamped): the limit is f₃ + (f₃ − f₂)/(ρ^p − 1) and GCI = 1.25 |f₃ − f₂| /
    (ρ^p − 1).  Otherwise (oscillating, or the differences do not shrink fast enough to trust)
    nothing is extrapolated: the finest value stands for the limit and GCI = 3 |f₃ − f₂| /
    (ρ − 1) (Roache's safety factor 3 with a first-order guess; with f₃ = f₂ the first
    difference stands in).  Arrays take one order from their RMS differences; their GCI is an
    RMS."""
    if len(values) < 3:
        raise LeafsimError(f"Richardson extrapolation needs three meshes, got {len(values)}")
    f1, f2, f3 = (np.asarray(v, float) for v in values[-3:])
    e1, e2 = f1 - f2, f2 - f3
    d1 = float(np.sqrt(np.mean(e1 ** 2)))
    d2 = float(np.sqrt(np.mean(e2 ** 2)))
    finest = float(f3) if f3.ndim == 0 else f3
    if d2 == 0.0 or d1 == 0.0:
        return finest, float("nan"), float("nan"), 3.0 * max(d1, d2) / (ratio - 1.0)
    raw = math.log(d1 / d2) / math.log(ratio)
    monotone = float(np.sum(e1 * e2)) > 0.0
    if not monotone or raw < P_MIN - 1e-9:
        return finest, float("nan"), (raw if monotone else float("nan")), 3.0 * d2 / (ratio - 1.0)
    p = min(raw, P_MAX)
    c = 1.0 / (ratio ** p - 1.0)
    limit = f3 + e2 * -c
    return (float(limit) if limit.ndim == 0 else limit), p, raw, 1.25 * d2 * c


def extrapolate(ends: list[dict], water: list[list], times: list[float], ratio: float = RATIO) -> tuple[dict, dict]:
    """The limit of the probe fields ``ends`` (:meth:`Probe.fields`, coarse to fine), of the
    water snapshots ``water`` and of the times to dry ``times``: (the limit's fields, the
    orders and GCIs per measure)."""
    lim, info = {}, {}
    for key in ("q_own", "q", "water_field"):
        lim[key], p, raw, gci = richardson([e[key] for e in ends], ratio)
        info[key] = {"order": p, "observed": raw, "gci": gci}
    for key in SCALARS + ("water",):
        lim[key], p, raw, gci = richardson([e[key] for e in ends], ratio)
        info[key] = {"order": p, "observed": raw, "gci": gci}
    snaps = []
    for k in range(min(len(w) for w in water)):
        v, p, raw, gci = richardson([w[k] for w in water], ratio)
        snaps.append(v)
        info[f"water_{k}"] = {"order": p, "observed": raw, "gci": gci}
    t, p, raw, gci = richardson(times, ratio)
    info["time_to_dry"] = {"order": p, "observed": raw, "gci": gci}
    return {"end": lim, "water": snaps, "time_to_dry": t}, info


class _Limit:
    """The extrapolated limit in the shape :func:`.accuracy.errors` compares against."""

    def __init__(self, data: dict):
        self.end = data["end"]
        self.water = data["water"]
        self.time_to_dry = data["time_to_dry"]


def limit_settings(base, quick: bool = False) -> list[Setting]:
    """The static reference runs, coarse to fine."""
    s0 = base["mesh.spacing"]
    meshes = (1.6, 1.6 / RATIO, 0.8) if quick else LIMIT_MESHES
    every = LIMIT_EVERY // 4 if quick else LIMIT_EVERY  # the quick leaf dries 10 × faster
    out = []
    for f in meshes:
        r = round(s0 * f, 5)
        out.append(Setting(f"static r={r:g}", "limit",
                           {"mesh.spacing": r, "dynamics.integrator": "static", "dynamics.static_every": every,
                            "dynamics.static_tolerance": LIMIT_TOLERANCE, "dynamics.path": "own"},
                           f"static equilibrium every {every} frames to {LIMIT_TOLERANCE:g} × weight, r = {r:.4g} L"))
    return out


def candidate_settings(base, quick: bool = False) -> list[Setting]:
    """The settings measured against the limit: today's defaults and quality levels, and the
    static solver on the default and the draft mesh at a few increments."""
    out = [Setting("default", "default", {}, "defaults")]
    if not quick:
        for level in ("balanced", "draft"):
            changes = {k: v for k, v in QUALITY[level].items() if base[k] != v}
            out.append(Setting(f"quality {level}", "quality", changes, f"--quality {level}"))
    s0 = base["mesh.spacing"]
    draft = QUALITY["draft"]["mesh.spacing"]
    for every in ((64,) if quick else (64, 256)):
        for r in ((s0,) if quick else (s0, draft)):
            out.append(Setting(f"static r={r:g} every {every}", "static",
                               {"mesh.spacing": r, "dynamics.integrator": "static", "dynamics.static_every": every,
                                "dynamics.path": "own"},
                               f"static equilibrium every {every} frames, r = {r:.4g} L"))
    return out


def limit_study(species: str = "oak", quick: bool = False, seed: int = 0, config=None, progress: bool = True,
                cache: Path | None = None, candidates: list[Setting] | None = None, keep: dict | None = None) -> dict:
    """Dry ``species`` on the limit meshes, extrapolate, and measure every candidate against
    the limit (see the module doc).  ``cache``: a folder where every run is kept (plain
    ``.npz``, :func:`save_run`) and from which a run of the same settings, protocol and solver
    source is taken instead of run again (a study of hours resumes).  ``keep``: a dict that
    receives the limit itself (``"limit"``, what :func:`.accuracy.errors` compares against) and
    the probe, to score runs made elsewhere."""
    sp = get_species(species, config)
    base = sp.params
    if quick:
        base = base.with_overrides({"osmosis.evaporation_top": 10 * base["osmosis.evaporation_top"],
                                    "osmosis.evaporation_bottom": 10 * base["osmosis.evaporation_bottom"]})
    probe = Probe(leaf_shape(sp, base))
    refs = limit_settings(base, quick)
    cands = candidates if candidates is not None else candidate_settings(base, quick)
    bar = _progress(len(refs) + len(cands), progress)
    t_nom = _dry_time_estimate(base)
    times = [f * t_nom for f in WATER_TIMES]
    builds: dict = {}

    def run(s: Setting, t_end):
        key = None
        if cache is not None:
            key = Path(cache) / f"{cache_key(species, seed, quick, base, s, t_end, times, 4.0 * t_nom)}.npz"
            got = load_run(key, s)
            if got is not None:
                bar.update(1)
                return got
        r = run_setting(sp, base, s, t_end, probe, times, seed, builds, t_max=4.0 * t_nom)
        if key is not None:
            save_run(key, r)
        bar.update(1)
        return r

    first = run(refs[0], None)
    if math.isnan(first.time_to_dry):
        raise LeafsimError(f"accuracy --limit: {species} did not dry within {4 * t_nom:.3g} s")
    t_end = first.frames * base["dynamics.dt"]  # every other run as long (dry × SETTLE)
    ref_runs = [first] + [run(s, t_end) for s in refs[1:]]
    lim_data, orders = extrapolate([r.end for r in ref_runs], [r.water for r in ref_runs],
                                   [r.time_to_dry for r in ref_runs])
    limit = _Limit(lim_data)
    if keep is not None:
        keep.update(limit=limit, probe=probe)
    rows = [_limit_row(s, r, errors(r, limit, probe)) for s, r in zip(refs, ref_runs)]
    for s in cands:
        try:
            r = run(s, t_end)
            rows.append(_limit_row(s, r, errors(r, limit, probe)))
        except LeafsimError as exc:
            rows.append({"name": s.name, "group": s.group, "label": s.label, "failed": str(exc)})
    bar.close()
    lim_scalars = {k: round(float(lim_data["end"][k]), 5) for k in SCALARS}
    lim_scalars["time_to_dry"] = round(float(lim_data["time_to_dry"]), 5)
    return {"species": species, "quick": quick, "seed": seed, "length_m": probe.length, "t_end": t_end,
            "limit": lim_scalars, "orders": _round(orders), "rows": rows,
            "newton": [dict(name=s.name, particles=r.particles, **(r.solver or {})) for s, r in zip(refs, ref_runs)]}


#: bump when a cached run's meaning changes in a way the source digest below does not see
CACHE_VERSION = 1
#: the modules whose source decides what a run produces (their digest is part of the cache key)
CACHE_SOURCES = ("leafsim/sim/equilibrium.py", "leafsim/sim/kernels/static.py", "leafsim/sim/effects/dynamics.py",
                 "leafsim/sim/kernels/pbd.py", "leafsim/sim/kernels/osmosis.py", "leafsim/sim/kernels/shrink.py",
                 "leafsim/measure/accuracy.py")


def cache_key(species, seed, quick, base, s: Setting, t_end, times, t_max) -> str:
    """The cache name of one run: a digest of everything that decides it (the species'
    parameters, the setting, the protocol's times and the solver's source)."""
    import hashlib

    root = Path(__file__).resolve().parents[2]
    h = hashlib.blake2b(digest_size=12)
    h.update(json.dumps([CACHE_VERSION, species, seed, quick, sorted((k, repr(v)) for k, v in base.items()),
                         sorted((k, repr(v)) for k, v in s.overrides.items()), t_end, list(times), t_max],
                        default=repr).encode())
    for rel in CACHE_SOURCES:
        f = root / rel
        h.update(f.read_bytes() if f.is_file() else rel.encode())
    return h.hexdigest()


def save_run(path: Path, r) -> None:
    """One run as an ``.npz`` of plain arrays (its scalars as JSON text), written atomically."""
    import io

    meta = {"setting": {"name": r.setting.name, "group": r.setting.group, "overrides": r.setting.overrides,
                        "label": r.setting.label},
            **{k: getattr(r, k) for k in ("particles", "frames", "seconds", "ms_frame", "ms_frame_p90", "ms_per_sim_s",
                                          "time_to_dry", "failed", "cpu", "solver")},
            "scalars": {k: float(v) for k, v in r.end.items() if np.ndim(v) == 0}, "water": len(r.water)}
    arrays = {f"end_{k}": np.asarray(v, float) for k, v in r.end.items() if np.ndim(v) > 0}
    arrays.update({f"water_{i}": np.asarray(w, float) for i, w in enumerate(r.water)})
    buf = io.BytesIO()
    np.savez(buf, meta=np.frombuffer(json.dumps(meta).encode(), np.uint8), **arrays)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, buf.getvalue(), "run")


def load_run(path: Path, s: Setting):
    """The run cached at ``path`` for setting ``s``, or None (missing, damaged or another
    setting's).  Plain arrays only (no pickle): a cache folder cannot run code."""
    from leafsim.measure.accuracy import SettingResult

    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(bytes(z["meta"]).decode())
            end = {k[4:]: np.array(z[k]) for k in z.files if k.startswith("end_")}
            water = [np.array(z[f"water_{i}"]) for i in range(int(meta["water"]))]
        end.update(meta["scalars"])
        st = meta["setting"]
        if st["overrides"] != json.loads(json.dumps(s.overrides)):
            return None
        return SettingResult(s, meta["particles"], meta["frames"], meta["seconds"], meta["ms_frame"],
                             meta["ms_frame_p90"], meta["ms_per_sim_s"], meta["time_to_dry"], end, water,
                             failed=meta["failed"], cpu=meta["cpu"], solver=meta["solver"])
    except (OSError, ValueError, KeyError, TypeError):  # damaged: run again (and replace it)
        return None


def _round(d):
    if isinstance(d, dict):
        return {k: _round(v) for k, v in d.items()}
    if isinstance(d, float):
        return float(f"{d:.4g}") if math.isfinite(d) else None
    return d


def _limit_row(s: Setting, r, e: dict) -> dict:
    row = {"name": s.name, "group": s.group, "label": s.label, "particles": r.particles, "frames": r.frames,
           "cpu_s": round(r.cpu, 2), "wall_s": round(r.seconds, 2), "time_to_dry": round(r.time_to_dry, 4),
           "margin_lift": round(r.end["margin_lift"], 4), "area_3d": round(r.end["area_3d"], 4),
           "area_top": round(r.end["area_top"], 4)}
    if r.solver:
        row["solver"] = r.solver
    row.update({k: (round(v, 5) if isinstance(v, float) else v) for k, v in e.items()})
    return row


def markdown_limit(report: dict) -> str:
    """The study as markdown: the limit with its orders, every setting's error and CPU, the
    Newton iterations by mesh."""
    L = report["length_m"]
    lim, o = report["limit"], report["orders"]
    lines = [f"Limit (Richardson over {len([r for r in report['rows'] if r['group'] == 'limit'])} meshes, ratio √2): "
             + "; ".join(f"{name}{' ' + _lim(lim, k) if k in lim else ''} (observed order {_num(o[k]['observed'])}, "
                         f"{'extrapolated' if o[k]['order'] is not None else 'not asymptotic: the finest mesh'}, "
                         f"GCI {_num(o[k]['gci'] / (L if k == 'q_own' else 1.0))}{' L' if k == 'q_own' else ''})"
                         for k, name in (("margin_lift", "margin lift"), ("area_3d", "3D area"), ("area_top", "top-down area"),
                                         ("time_to_dry", "time to dry"), ("q_own", "positions"), ("water_field", "water field")))
             + ".",
             "", "| setting | particles | CPU s per dried leaf | " + " | ".join(METRIC_NAMES[m] for m in METRICS) + " | worst |",
             "|---|---|---|" + "---|" * (len(METRICS) + 1)]
    for r in report["rows"]:
        if "failed" in r:
            lines.append(f"| {r['name']} | | failed: {r['failed']} |" + " |" * (len(METRICS) + 1))
            continue
        lines.append(f"| {r['name']} | {r['particles']} | {r['cpu_s']:.1f} | "
                     + " | ".join(f"{100 * r[m + '_rel']:.1f} %" for m in METRICS) + f" | {100 * r['worst_rel']:.1f} % |")
    lines += ["", f"Errors against the limit, relative (fields to the limit's own deformation, scalars to its value). "
              f"L = {L:.3g} m. CPU: the run's frames, process time.", "",
              "Newton iterations per equilibrium solve, by mesh (each solve to "
              f"{LIMIT_TOLERANCE:g} × a particle's weight, every {LIMIT_EVERY} frames):", "",
              "| mesh | particles | solves | median | p90 | largest | factorisations | ms per solve | unconverged |",
              "|---|---|---|---|---|---|---|---|---|"]
    for n in report["newton"]:
        if "solves" not in n:
            continue
        lines.append(f"| {n['name']} | {n['particles']} | {n['solves']} | {n['newton_median']:.3g} | {n['newton_p90']:.3g} | "
                     f"{n['newton_max']} | {n['factorisations']} | {n['ms_per_solve']:.4g} | {n['unconverged']} |")
    return "\n".join(lines)


def _num(v) -> str:
    return "–" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.2g}"


def _lim(lim: dict, key: str) -> str:
    if key not in lim:
        return ""
    return f"{lim[key]:.4g} s" if key == "time_to_dry" else f"{lim[key]:.4f}" + (" L" if key == "margin_lift" else "")


def plot_limit(report: dict, path) -> Path:
    """Worst relative error against the limit over CPU seconds per dried leaf, one point per
    setting (the defaults starred), as a PNG."""
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from leafsim.measure.accuracy import scatter_settings

    rows = [r for r in report["rows"] if "worst_rel" in r]
    fig, ax = plt.subplots(figsize=(7.5, 5), dpi=110)
    scatter_settings(ax, rows, "cpu_s")
    ax.set_xscale("log")
    ax.set_xlabel("CPU seconds per dried leaf")
    ax.set_ylabel("worst relative error against the limit [%]")
    ax.set_title(f"{report['species']}: error against the mesh-converged limit")
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    return atomic_write_bytes(path, buf.getvalue(), "plot")


def write_limit_report(report: dict, out) -> dict:
    """limit.json, limit.md and limit_front.png into ``out``; returns the paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    return {"json": str(atomic_write_bytes(out / "limit.json", (json.dumps(report, indent=1) + "\n").encode(), "report")),
            "markdown": str(atomic_write_bytes(out / "limit.md", (markdown_limit(report) + "\n").encode(), "report")),
            "plot": str(plot_limit(report, out / "limit_front.png"))}
