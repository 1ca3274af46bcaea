"""Accuracy against cost (``leafsim accuracy``): how far each solver setting is from a
converged reference, and what it costs.

One leaf is dried on the ground to the end under many settings.  Every run is compared with
the reference at fixed material points of the rest leaf (:mod:`leafsim.sim.metrics`), so meshes
of any resolution compare: the dried shape as a 3D-position field in the leaf's own frame and
as a height field (RMS / leaf length), margin lift, 3D and top-down area kept, the water field
at fixed times while it dries, and the time to dry.  Cost is wall-clock per frame (median and
p90 over the run's frames) and per simulated second.

Sweeps (each around the defaults, one setting changed): mesh spacing (≈ √2 steps); substeps ×
iterations and the iteration stop tolerance; Δt; the osmosis solve (direct, CG and Jacobi to a
tolerance, solved every k-th frame); the hinges' over-relaxation; the dynamics frame in
float32 (``dynamics.precision``; osmosis, shrink and colour stay float64).

Example
-------
>>> report = study("maple", quick=True)                         # doctest: +SKIP
>>> write_report(report, "out/accuracy")                         # doctest: +SKIP
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from leafsim.base.errors import LeafsimError
from leafsim.base.fileio import atomic_write_bytes
from leafsim.config.params import ParamSet
from leafsim.config.presets import QUALITY
from leafsim.config.species import get_species
from leafsim.pipeline import build_leaf, leaf_shape
from leafsim.sim.metrics import Probe, field_errors
from leafsim.sim.run import Run, Stop

#: the run ends this much after the reference's time to dry (the shape settles)
SETTLE = 1.15
#: the leaf counts as dry below this water fraction
DRY_WATER = 0.02
#: water-field snapshots at these fractions of the reference's time to dry
WATER_TIMES = (0.25, 0.5, 0.75)
#: metrics every point is judged on, with the tolerance of the "within 10 %" rule
METRICS = ("position", "height", "margin_lift", "area_3d", "area_top", "water", "time_to_dry")
METRIC_NAMES = {"position": "position", "height": "height", "margin_lift": "margin lift", "area_3d": "3D area",
                "area_top": "top-down area", "water": "water", "time_to_dry": "time to dry"}


#: the sweeps of the study (``leafsim accuracy --groups``)
GROUPS = ("mesh", "iterations", "mass", "tolerance", "dt", "relaxation", "osmosis", "precision", "quality", "integrator")
#: sweeps run only when asked for by name (--groups): Sun's explicit integrator costs one to two
#: orders of magnitude more CPU than the whole default study (docs/method.md)
ON_REQUEST = ("integrator",)


@dataclass
class Setting:
    """One point of the study: a name, the sweep it belongs to and its parameter overrides."""

    name: str
    group: str
    overrides: dict
    label: str = ""


@dataclass
class SettingResult:
    """What one setting produced (fields at the end, water fields on the way, costs)."""

    setting: Setting
    particles: int
    frames: int
    seconds: float
    ms_frame: float
    ms_frame_p90: float
    ms_per_sim_s: float
    time_to_dry: float
    end: dict
    water: list = field(default_factory=list)
    failed: str | None = None
    cpu: float = float("nan")  # CPU seconds of the run's frames (process time)
    solver: dict | None = None  # dynamics.integrator = static: the equilibrium solves' statistics
    path_frames: int = 0  # frames whose mechanics the drying path's coarser mesh carried


def default_sweeps(base: ParamSet, quick: bool = False, groups=None) -> list[Setting]:
    """The settings of the study around ``base`` (its values are "today's defaults"), one
    parameter changed at a time; ``groups`` keeps only those sweeps.  Substeps are given at the
    default spacing (``dynamics.substep_scaling`` scales them with the mesh)."""
    s0 = base["mesh.spacing"]
    sub, it = base["dynamics.substeps"], base["dynamics.iterations"]
    out = [Setting("default", "default", {}, "defaults")]
    for f in ((1.6, 1.25) if quick else (1.41, 0.71)):
        out.append(Setting(f"spacing×{f:g}", "mesh", {"mesh.spacing": round(s0 * f, 5)}, f"r = {s0 * f:.4g} L"))
    grid = [(2, 1), (max(sub // 2, 1), it), (2 * sub, it)] if quick else \
        [(max(sub // 4, 1), it), (max(sub // 2, 1), it), (sub, 1), (max(sub // 2, 1), 2 * it), (2 * sub, it)]
    out += [Setting(f"{a}×{b}", "iterations", {"dynamics.substeps": a, "dynamics.iterations": b}, f"{a} substeps × {b} iterations")
            for a, b in grid if (a, b) != (sub, it)]
    M = base["dynamics.mass_scaling"]
    out += [Setting(f"mass×{m:g}", "mass", {"dynamics.mass_scaling": m}, f"inertia × {m:g}")
            for m in ((1.0,) if quick else (1.0, 16.0, 256.0)) if m != M]
    if not quick:
        a = max(sub // 4, 1)
        out.append(Setting(f"{a}×{it}, mass×256", "mass", {"dynamics.substeps": a, "dynamics.mass_scaling": 256.0},
                           f"{a} substeps × {it} iterations, inertia × 256"))
    if not quick:
        out.append(Setting("tol 1e-3", "tolerance", {"dynamics.iterations": 6, "dynamics.tolerance": 1e-3},
                           "≤ 6 iterations, stop at 1e-3 L"))
        dt = base["dynamics.dt"]
        out += [Setting(f"dt×{f:g}", "dt", {"dynamics.dt": dt * f}, f"Δt = {dt * f:g} s") for f in (2.0, 0.5)]
        out.append(Setting("relax 1.3", "relaxation", {"dynamics.relaxation": 1.3}, "hinges over-relaxed, ω = 1.3"))
    out += [Setting(f"osmosis every {k}", "osmosis", {"osmosis.every": k}, f"osmosis every {k} frames") for k in ((5,) if quick else (2, 5, 10))]
    if not quick:
        out += [Setting("osmosis cg 1e-4", "osmosis", {"osmosis.solver": "cg", "osmosis.tolerance": 1e-4}, "CG to 1e-4"),
                Setting("osmosis jacobi 1e-3", "osmosis", {"osmosis.solver": "jacobi", "osmosis.tolerance": 1e-3}, "Jacobi to 1e-3")]
    if not quick:
        out.append(Setting("float32", "precision", {"dynamics.precision": "float32"}, "dynamics frame in float32"))
    if not quick:  # every other quality level (leafsim --quality) measured against the same reference
        for level, values in QUALITY.items():
            changes = {k: v for k, v in values.items() if base[k] != v}
            if changes and level != "reference":
                out.append(Setting(f"quality {level}", "quality", changes, f"--quality {level}"))
    if groups is not None and "integrator" in groups:
        for c in ((1.5,) if quick else (1.5, 0.75)):
            out.append(Setting(f"sun, Courant {c:g}", "integrator", {"dynamics.integrator": "sun", "dynamics.sun_courant": c},
                               f"Sun's explicit midpoint, ω h ≤ {c:g}"))
    return [x for x in out if (groups is None and x.group not in ON_REQUEST) or (groups is not None and x.group in groups)
            or x.group == "default"]


def reference_setting(base: ParamSet, quick: bool = False) -> Setting:
    """The converged reference: a √2 finer mesh (with twice the substeps from the scaling) and
    twice the substeps on top (4× in all), iterations to a tight tolerance."""
    s0 = base["mesh.spacing"]
    f = 0.8 if quick else 0.71
    sub = base["dynamics.substeps"] * 2
    return Setting("reference", "reference", {"mesh.spacing": round(s0 * f, 5), "dynamics.substeps": sub,
                                             "dynamics.iterations": 3, "dynamics.tolerance": 1e-6, "dynamics.path": "own"},
                   f"r = {s0 * f:.4g} L, {sub} substeps at r₀ (scaled) × ≤ 3 iterations")


def run_setting(species, base: ParamSet, setting: Setting, t_end: float | None, probe, water_times=(), seed: int = 0,
                builds: dict | None = None, t_max: float = 60.0, perturb: tuple[int, float] | None = None) -> SettingResult:
    """Dry the leaf under ``setting`` for ``t_end`` simulated seconds (None: until it is dry
    and then SETTLE × that long, at most ``t_max``); measure it.  ``perturb = (seed, a)``
    displaces every particle's start position by a random vector of components U(−a, a) m
    (upwards only, so nothing starts below the ground): the same leaf, started a little less
    than perfectly flat."""
    p = base.with_overrides({**setting.overrides, "effects.colour": False})
    key = tuple(sorted((k, v) for k, v in p.items() if k.startswith(("mesh.", "mass.", "veins.", "outline.", "dynamics.path"))))
    builds = builds if builds is not None else {}
    if key not in builds:
        builds[key] = build_leaf(species, p, seed).model
    model = builds[key]
    run = Run(model, p, seed=seed)
    st = run.state
    if perturb is not None:
        kick = np.random.default_rng(perturb[0]).uniform(-perturb[1], perturb[1], st.particle_q.shape)
        kick[:, 2] = np.abs(kick[:, 2])
        st.particle_q[:] += kick
        run.sim.sync_path(st)  # the drying-path mesh starts from the kicked leaf too
    dt = p["dynamics.dt"]
    n = int(math.ceil((t_end if t_end is not None else t_max) / dt - 1e-9))
    wanted = sorted(water_times)
    water, ms = [], []
    t_dry = float("nan")

    def settled(st) -> bool:
        nonlocal t_dry
        if math.isnan(t_dry) and model.water_fraction(st.particle_water) < DRY_WATER:
            t_dry = st.time
        while wanted and st.time >= wanted[0] - 1e-12:
            water.append(probe.fields(model, st)["water_field"])
            wanted.pop(0)
        return t_end is None and not math.isnan(t_dry) and st.time >= SETTLE * t_dry - 1e-12

    t0 = time.perf_counter()
    c0 = time.process_time()
    on_path = 0
    for stages in run.frames(Stop(frames=n), until=settled):
        ms.append(sum(stages.values()))
        on_path += bool(run.sim.on_path)
    cpu = time.process_time() - c0
    secs = time.perf_counter() - t0
    med = float(np.median(ms))
    return SettingResult(setting, model.particle_count, len(ms), secs, med, float(np.percentile(ms, 90)), med / dt, t_dry,
                         probe.fields(model, st), water, cpu=cpu, solver=solver_stats(run.sim), path_frames=on_path)


def solver_stats(sim) -> dict | None:
    """With ``dynamics.integrator = static``: the equilibrium solves of a run (count, Newton
    iterations median / p90 / largest, factorisations, seconds per solve, largest residual
    left); None for the other integrators."""
    dyn = getattr(sim, "_dynamics", None)
    eq = getattr(dyn, "equilibrium", None) if dyn is not None and getattr(dyn, "static", False) else None
    if eq is None or not eq.log:
        return None
    a = np.array(eq.log, float)
    return {"solves": len(a), "newton_median": float(np.median(a[:, 0])), "newton_p90": float(np.percentile(a[:, 0], 90)),
            "newton_max": int(a[:, 0].max()), "newton_total": int(a[:, 0].sum()), "factorisations": int(a[:, 1].sum()),
            "ms_per_solve": float(1e3 * np.median(a[:, 2])), "residual_max": float(a[:, 3].max()),
            "unconverged": int((a[:, 3] > eq.tol).sum())}


def errors(run: SettingResult, ref: SettingResult, probe) -> dict:
    """Every metric of ``run`` against ``ref``: absolute and relative (to the reference's own
    value, for fields to the reference's deformation from rest)."""
    length = probe.length
    e = field_errors(run.end, ref.end, length)
    deform = float(np.sqrt(((ref.end["q_own"] - probe.rest3) ** 2).sum(1).mean())) / length
    height = float(np.sqrt(((ref.end["q"][:, 2] - ref.end["q"][:, 2].min()) ** 2).mean())) / length
    werr = [float(np.sqrt(((a - b) ** 2).mean())) for a, b in zip(run.water, ref.water)]
    wmag = [float(np.sqrt(((1.0 - b) ** 2).mean())) for b in ref.water]
    out = {
        "position": e["position_rms"], "position_rel": e["position_rms"] / max(deform, 1e-12),
        "height": e["height_rms"], "height_rel": e["height_rms"] / max(height, 1e-12),
        "margin_lift": e["d_margin_lift"], "margin_lift_rel": e["r_margin_lift"],
        "area_3d": e["d_area_3d"], "area_3d_rel": e["r_area_3d"],
        "area_top": e["d_area_top"], "area_top_rel": e["r_area_top"],
        "water": max(werr) if werr else 0.0,
        "water_rel": max(a / max(b, 1e-12) for a, b in zip(werr, wmag)) if werr else 0.0,
        "time_to_dry": abs(run.time_to_dry - ref.time_to_dry),
        "time_to_dry_rel": abs(run.time_to_dry - ref.time_to_dry) / max(ref.time_to_dry, 1e-12),
    }
    out["worst_rel"] = max(out[f"{m}_rel"] for m in METRICS)
    return out


#: start-position perturbation of the sensitivity runs [m]: a hundredth of a blade's thickness
PERTURB_M = 1e-6


def sensitivity(runs: list[SettingResult], base: SettingResult, probe, amplitude: float = PERTURB_M) -> dict:
    """How far the same setting lands when only the start is perturbed (``runs`` against the
    unperturbed ``base``): per metric the median and the largest relative difference.  A
    metric's error against the reference cannot be resolved below this floor -- a dried shape
    that a micrometre at the start changes by X % is only defined to X %."""
    errs = [errors(r, base, probe) for r in runs]
    out = {"setting": base.setting.name, "runs": len(errs), "amplitude_m": amplitude}
    for m in METRICS:
        v = sorted(e[f"{m}_rel"] for e in errs)
        out[m] = {"median": float(f"{np.median(v):.4g}"), "max": float(f"{v[-1]:.4g}")}
    return out


def study(species: str = "maple", quick: bool = False, seed: int = 0, config=None, settings=None,
          progress: bool = True, base_overrides: dict | None = None, groups=None, floor: int = 0,
          floor_reference: bool = False) -> dict:
    """SettingResult the reference and every setting; returns the report (plain data, JSON-ready).

    ``floor`` > 0 also dries the default setting (and with ``floor_reference`` the reference)
    that many more times from start positions perturbed by :data:`PERTURB_M`: the report's
    ``floor`` says how much of each metric's error is the leaf's own sensitivity."""

    sp = get_species(species, config)
    base = sp.params.with_overrides(base_overrides or {})
    if quick:  # small and fast: a coarse leaf that dries in a few hundred frames
        base = base.with_overrides({"mesh.spacing": max(base["mesh.spacing"], 0.06),
                                    "osmosis.evaporation_top": 10 * base["osmosis.evaporation_top"],
                                    "osmosis.evaporation_bottom": 10 * base["osmosis.evaporation_bottom"]})
    shape = leaf_shape(sp, base)
    probe = Probe(shape)
    ref_set = reference_setting(base, quick)
    settings = settings if settings is not None else default_sweeps(base, quick, groups)
    builds: dict = {}
    bar = _progress(len(settings) + 1 + floor * (1 + bool(floor_reference)), progress)
    # water snapshots at fractions of the nominal drying time (water per area / evaporation per
    # area); the reference runs until it is dry and settled, every other run as long
    t_nom = _dry_time_estimate(base)
    times = [f * t_nom for f in WATER_TIMES]
    ref = run_setting(sp, base, ref_set, None, probe, times, seed, builds, t_max=4.0 * t_nom)
    if math.isnan(ref.time_to_dry):
        raise LeafsimError(f"accuracy: the reference run of {species} did not dry within {4 * t_nom:.3g} s")
    t_end = ref.frames * base.with_overrides(ref_set.overrides)["dynamics.dt"]
    bar.update(1)
    rows, done = [], {}
    for s in settings:
        try:
            r = run_setting(sp, base, s, t_end, probe, times, seed, builds)
            e = errors(r, ref, probe)
            done[s.name] = r
        except LeafsimError as exc:  # an unstable setting is a result too
            r, e = None, {"failed": str(exc)}
        rows.append(_row(s, r, e))
        bar.update(1)
    floors = []
    for name, s0 in (("default", next((s for s in settings if s.name == "default"), None)), ("reference", ref_set)):
        if floor <= 0 or s0 is None or (name == "reference" and not floor_reference):
            continue
        r0 = ref if name == "reference" else done.get(name) or run_setting(sp, base, s0, t_end, probe, times, seed, builds)
        pert = []
        for k in range(floor):
            pert.append(run_setting(sp, base, s0, t_end, probe, times, seed, builds, perturb=(1 + k, PERTURB_M)))
            bar.update(1)
        floors.append(sensitivity(pert, r0, probe))
    bar.close()
    report = {"species": species, "quick": quick, "seed": seed, "length_m": probe.length,
              "reference": _row(ref_set, ref, {}), "rows": rows,
              "base": {k: base[k] for k in ("mesh.spacing", "dynamics.substeps", "dynamics.iterations", "dynamics.dt",
                                            "dynamics.relaxation", "osmosis.every", "osmosis.solver")}}
    report["front"] = pareto_front(rows)
    if floors:
        report["floor"] = floors
    return report


def floor_study(species: str = "maple", runs: int = 3, overrides: dict | None = None, seed: int = 0, config=None,
                name: str = "default", amplitude: float = PERTURB_M) -> dict:
    """The sensitivity floor alone, without the sweep: the leaf dried under ``overrides``
    until dry and settled, then ``runs`` more times from perturbed starts for as long."""

    sp = get_species(species, config)
    base = sp.params
    probe = Probe(leaf_shape(sp, base))
    s0 = Setting(name, "floor", dict(overrides or {}))
    t_nom = _dry_time_estimate(base)
    times = [f * t_nom for f in WATER_TIMES]
    builds: dict = {}
    r0 = run_setting(sp, base, s0, None, probe, times, seed, builds, t_max=4.0 * t_nom)
    t_end = r0.frames * base.with_overrides(s0.overrides)["dynamics.dt"]
    pert = [run_setting(sp, base, s0, t_end, probe, times, seed, builds, perturb=(1 + k, amplitude)) for k in range(runs)]
    out = sensitivity(pert, r0, probe, amplitude)
    out.update({"species": species, "overrides": s0.overrides, "particles": r0.particles, "frames": r0.frames,
                "each": [{m: float(f"{errors(r, r0, probe)[f'{m}_rel']:.4g}") for m in METRICS} for r in pert]})
    return out


def ladder_study(species: str, key: str, values, overrides: dict | None = None, seed: int = 0, config=None) -> dict:
    """Successive differences along one setting: the leaf dried with ``key`` = each of
    ``values`` (coarse to fine, e.g. substeps 20, 40, 80, 160), the others at the species'
    values plus ``overrides``, all for as long as the first run took to dry and settle.  For
    every step the relative difference of each metric from the next finer value (``step``),
    and from the finest (``to_finest``); a converging setting shows the steps shrinking."""

    sp = get_species(species, config)
    base = sp.params.with_overrides(overrides or {})
    probe = Probe(leaf_shape(sp, base))
    t_nom = _dry_time_estimate(base)
    times = [f * t_nom for f in WATER_TIMES]
    builds: dict = {}
    runs, t_end = [], None
    for v in values:
        s = Setting(f"{key}={v}", "ladder", {key: v})
        r = run_setting(sp, base, s, t_end, probe, times, seed, builds, t_max=4.0 * t_nom)
        if t_end is None:
            t_end = r.frames * base.with_overrides(s.overrides)["dynamics.dt"]
        runs.append(r)
    rows = []
    for i, r in enumerate(runs):
        row = {"value": values[i], "particles": r.particles, "ms_frame": round(r.ms_frame, 3),
               "ms_per_sim_s": round(r.ms_per_sim_s, 1), "margin_lift": round(r.end["margin_lift"], 5),
               "area_3d": round(r.end["area_3d"], 5), "area_top": round(r.end["area_top"], 5)}
        if i + 1 < len(runs):
            e = errors(r, runs[i + 1], probe)
            row["step"] = {m: float(f"{e[f'{m}_rel']:.4g}") for m in METRICS}
        if i + 1 < len(runs):
            e = errors(r, runs[-1], probe)
            row["to_finest"] = {m: float(f"{e[f'{m}_rel']:.4g}") for m in METRICS}
        rows.append(row)
    return {"species": species, "key": key, "values": list(values), "overrides": dict(overrides or {}),
            "frames": runs[0].frames, "rows": rows}


def _row(s: Setting, r: SettingResult | None, e: dict) -> dict:
    row = {"name": s.name, "group": s.group, "label": s.label, "overrides": s.overrides}
    if r is not None:
        row.update({"particles": r.particles, "frames": r.frames, "seconds": round(r.seconds, 2),
                    "ms_frame": round(r.ms_frame, 3), "ms_frame_p90": round(r.ms_frame_p90, 3),
                    "ms_per_sim_s": round(r.ms_per_sim_s, 1), "time_to_dry": round(r.time_to_dry, 4),
                    "margin_lift": round(r.end["margin_lift"], 4), "area_3d": round(r.end["area_3d"], 4),
                    "area_top": round(r.end["area_top"], 4), "path_frames": r.path_frames})
    row.update({k: (round(v, 5) if isinstance(v, float) else v) for k, v in e.items()})
    return row


def pareto_front(rows: list[dict]) -> list[str]:
    """Names of the rows no other row beats in both cost (ms per simulated second) and error
    (worst relative metric)."""
    ok = [r for r in rows if "worst_rel" in r]
    front = []
    for r in ok:
        if not any(o is not r and o["ms_per_sim_s"] <= r["ms_per_sim_s"] and o["worst_rel"] <= r["worst_rel"]
                   and (o["ms_per_sim_s"] < r["ms_per_sim_s"] or o["worst_rel"] < r["worst_rel"]) for o in ok):
            front.append(r["name"])
    return sorted(front, key=lambda n: next(r["ms_per_sim_s"] for r in ok if r["name"] == n))


def _dry_time_estimate(base: ParamSet) -> float:
    """Nominal drying time: the blade's water per area over the summed evaporation per area of
    both surfaces (veins hold more and dry later)."""
    fresh = base["mass.lma"] / (1.0 - base["mass.water_fraction"])
    water = base["mass.water_fraction"] * fresh
    e = base["osmosis.evaporation_top"] + base["osmosis.evaporation_bottom"]
    if e <= 0:
        raise LeafsimError("accuracy: the leaf does not dry (osmosis.evaporation_top + _bottom = 0)")
    return water / e


class _progress:
    """A tqdm bar on a terminal (stderr), nothing otherwise."""

    def __init__(self, total: int, on: bool):
        self.bar = None
        if on:
            import sys

            from tqdm import tqdm

            self.bar = tqdm(total=total, desc="accuracy", unit="run", file=sys.stderr, disable=not sys.stderr.isatty())

    def update(self, n):
        if self.bar is not None:
            self.bar.update(n)

    def close(self):
        if self.bar is not None:
            self.bar.close()


# ----------------------------------------------------------------------------- output
def markdown(report: dict) -> str:
    """The study as a markdown table (one row per setting, the reference first)."""
    L = report["length_m"]
    ref = report["reference"]
    lines = [f"Reference ({ref['label']}): {ref['particles']} particles, dried in {ref['time_to_dry']:.3g} s, "
             f"margin lift {ref['margin_lift']:.3f} L, 3D area {ref['area_3d']:.3f}, top-down area {ref['area_top']:.3f}; "
             f"{ref['ms_frame']:.3g} ms per frame.", "",
             "| setting | particles | ms/frame (p90) | ms per sim. s | position RMS / L | height RMS / L | margin lift | "
             "3D area | top-down area | water | time to dry | worst rel. |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    front = set(report["front"])
    for r in report["rows"]:
        if "failed" in r:
            lines.append(f"| {r['name']} | | | | failed: {r['failed']} | | | | | | | |")
            continue
        mark = (" ★" if r["name"] in front else "") + (" †" if r.get("path_frames") else "")
        lines.append(
            f"| {r['name']}{mark} | {r['particles']} | {r['ms_frame']:.3g} ({r['ms_frame_p90']:.3g}) | {r['ms_per_sim_s']:.4g} | "
            f"{r['position']:.4f} ({100 * r['position_rel']:.0f} %) | {r['height']:.4f} ({100 * r['height_rel']:.0f} %) | "
            f"{r['margin_lift']:.3f} ({100 * r['margin_lift_rel']:.0f} %) | {r['area_3d']:.3f} ({100 * r['area_3d_rel']:.1f} %) | "
            f"{r['area_top']:.3f} ({100 * r['area_top_rel']:.0f} %) | {r['water']:.4f} ({100 * r['water_rel']:.0f} %) | "
            f"{r['time_to_dry']:.3g} s ({100 * r['time_to_dry_rel']:.1f} %) | {100 * r['worst_rel']:.0f} % |")
    lines += ["", "Errors against the reference; relative values in brackets (fields relative to the reference's "
              "own deformation or drying, scalars to the reference's value). ★: on the Pareto front of cost "
              f"(ms per simulated second) and worst relative error. †: the drying path's coarser mesh carried the "
              f"mechanics until the hand-over (`path_frames` in the JSON), so its cost per frame is not its own "
              f"mesh's; a setting without † ran its own mesh throughout (a mesh no finer than the path's, or "
              f"solver settings the path does not stand in for). Leaf length L = {L:.3g} m."]
    if report.get("floor"):
        fl = report["floor"]
        lines += ["", "Sensitivity floor: the same setting dried again from start positions perturbed by "
                  f"{1e6 * fl[0]['amplitude_m']:.3g} µm (relative difference from the unperturbed run, median (largest) "
                  "over the perturbed runs):", "",
                  "| setting | runs | " + " | ".join(METRIC_NAMES[m] for m in METRICS) + " |",
                  "|---|---|" + "---|" * len(METRICS)]
        for f in fl:
            lines.append(f"| {f['setting']} | {f['runs']} | " + " | ".join(
                f"{100 * f[m]['median']:.1f} % ({100 * f[m]['max']:.1f} %)" for m in METRICS) + " |")
    return "\n".join(lines)


def scatter_settings(ax, rows: list[dict], xkey: str) -> None:
    """One point per setting (worst relative error in % over ``xkey``), coloured by sweep and
    named, today's defaults starred."""
    import matplotlib.pyplot as plt

    for g, c in zip(sorted({r["group"] for r in rows}), plt.cm.tab10.colors):
        rs = [r for r in rows if r["group"] == g]
        ax.scatter([r[xkey] for r in rs], [100 * r["worst_rel"] for r in rs], color=c, label=g, s=28, zorder=3)
        for r in rs:
            ax.annotate(r["name"], (r[xkey], 100 * r["worst_rel"]), fontsize=6, xytext=(3, 3), textcoords="offset points")
    d = next((r for r in rows if r["name"] == "default"), None)
    if d:
        ax.scatter([d[xkey]], [100 * d["worst_rel"]], marker="*", s=220, color="crimson", label="today's defaults", zorder=4)


def plot(report: dict, path) -> Path:
    """The Pareto plot (worst relative error against ms per simulated second) as a PNG."""
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt


    rows = [r for r in report["rows"] if "worst_rel" in r]
    front = set(report["front"])
    fig, ax = plt.subplots(figsize=(7.5, 5), dpi=110)
    scatter_settings(ax, rows, "ms_per_sim_s")
    fr = sorted((r for r in rows if r["name"] in front), key=lambda r: r["ms_per_sim_s"])
    ax.plot([r["ms_per_sim_s"] for r in fr], [100 * r["worst_rel"] for r in fr], "k--", lw=1, label="Pareto front", zorder=2)
    ax.axhline(10, color="grey", lw=0.8, ls=":")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("cost: wall-clock ms per simulated second (median)")
    ax.set_ylabel("worst relative error against the reference [%]")
    ax.set_title(f"{report['species']}: accuracy against cost")
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    return atomic_write_bytes(path, buf.getvalue(), "plot")


def write_report(report: dict, out) -> dict:
    """Write accuracy.json, accuracy.md and accuracy_pareto.png into ``out``; returns the paths."""

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"json": atomic_write_bytes(out / "accuracy.json", (json.dumps(report, indent=1) + "\n").encode(), "report"),
             "markdown": atomic_write_bytes(out / "accuracy.md", (markdown(report) + "\n").encode(), "report"),
             "plot": plot(report, out / "accuracy_pareto.png")}
    return {k: str(v) for k, v in paths.items()}
