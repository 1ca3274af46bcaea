"""Parameter presets (dotted names of :mod:`leafsim.config.params`).

``THESIS_PRESET`` reproduces the thesis's Table 5.1 values for comparison: they collapse a
fully dried leaf into a crumpled ball (≈ 1 % of its area, SPEC §7) and λ = 70–700 equalises
water within one step.  ``DEFAULT_NOTES`` explains how the defaults were calibrated.
"""

THESIS_PRESET = {
    "shrink.sigma_vein": 0.5,
    "shrink.sigma_surface_top": 1.5,
    "shrink.sigma_surface_bottom": 1.5,
    "shrink.l_min": 0.1,
    "mass.profile_min": 0.1,     # thesis m_min / m_max = 0.1 mg / 1 mg (per particle there; per area here)
    "osmosis.diffusion": 70.0,   # thesis λ 70–700 (dimensionless in the thesis; see docs/method.md)
    "osmosis.evaporation_top": 0.014,     # thesis w_loss 0.2 / 0.1 of a layer's mean water per second
    "osmosis.evaporation_bottom": 0.007,  # (0.07 kg/m² of water per layer at the default mass)
    "osmosis.through_thickness": False,   # Jeong / thesis: water flows within each layer only
    "dynamics.iterations": 1,
    "dynamics.substeps": 1,
    "dynamics.dt": 0.002,
    "dynamics.gravity": 9.8,
    "dynamics.voronoi": "replace",
    "dynamics.plasticity": 0.0,
    "mass.D": 1,
    "shrink.alpha": 1.0,
}

PRESETS = {"thesis": THESIS_PRESET}

#: quality levels.  "fine" is the declared defaults: mesh 0.0199 L, 40 substeps with the inertia
#: scaled × 64 (dynamics.mass_scaling), most of the water dried with its mechanics on the draft
#: mesh (dynamics.path, leafsim.sim.path).  "balanced", the default before it, is a √2 coarser
#: mesh on its own (20 substeps from the scaling); "draft" takes a quarter of its substeps with the
#: inertia × 256 (the same n √M).  Their error against the converged limit and their CPU per dried
#: leaf, measured on maple, oak and grapevine, are in configs/quality.json (tools/quality_table.py,
#: from docs/accuracy/limit_*): fine is 9–13 % from the limit at worst; balanced costs more than
#: draft for no less error on maple and oak (docs/accuracy.md).
_QUALITY_CHANGES = {
    "draft": {"mesh.spacing": 0.028, "dynamics.substeps": 10, "dynamics.mass_scaling": 256.0, "dynamics.path": "own"},
    "balanced": {"mesh.spacing": 0.028, "dynamics.path": "own"},
    "fine": {},
    "reference": {"mesh.spacing": 0.01413, "dynamics.substeps": 80, "dynamics.iterations": 3, "dynamics.tolerance": 1e-6,
                  "dynamics.path": "own"},
}
#: the parameters a quality level sets (every level sets all of them)
QUALITY_KEYS = ("mesh.spacing", "dynamics.path", "dynamics.substeps", "dynamics.iterations", "dynamics.tolerance", "dynamics.dt",
                "dynamics.mass_scaling", "osmosis.every")
QUALITY_FILE = "quality.json"
#: the species whose limit studies measured the levels (configs/quality.json)
QUALITY_SPECIES = ("maple", "oak", "grapevine")


def _levels() -> dict:
    from leafsim.config.params import PARAMS

    return {k: {key: v.get(key, PARAMS[key].default) for key in QUALITY_KEYS} for k, v in _QUALITY_CHANGES.items()}


QUALITY = _levels()


def quality_overrides(name: str) -> dict:
    """The parameter values of quality level ``name`` (LeafsimError naming the choices)."""
    from leafsim.base.errors import LeafsimError

    if name not in QUALITY:
        raise LeafsimError(f"--quality {name!r}: expected one of {', '.join(QUALITY)}")
    return dict(QUALITY[name])


def quality_of(params) -> str | None:
    """The quality level whose settings ``params`` has, or None (custom)."""
    for k, v in QUALITY.items():
        if all(params[key] == val for key, val in v.items()):
            return k
    return None


def quality_table(config_dir=None) -> dict:
    """Each quality level's settings with its measured error and cost (from configs/quality.json:
    ``measured`` maps a species to its worst relative error against the converged limit
    ``worst_rel``, CPU seconds per dried leaf ``cpu_s`` and ``particles``; None for a level no
    study has measured)."""
    import json
    from pathlib import Path

    from leafsim.base.resources import data_dir

    path = Path(config_dir or data_dir("configs")) / QUALITY_FILE
    measured = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}
    return {k: {"settings": v, "measured": measured.get(k)} for k, v in QUALITY.items()}


def quality_lines(table: dict, default: str | None) -> list[str]:
    """One line per level of :func:`quality_table` for a tooltip or a terminal: its error from the
    converged limit and CPU per dried leaf on each measured species, and where another level is
    as accurate for no more CPU (on maple and oak, draft is for balanced)."""
    lines = []
    for level, v in table.items():
        m = v["measured"]
        name = f"{level} (default)" if level == default else level
        if not m:
            lines.append(f"{name}: not measured")
            continue
        sp = [s for s in QUALITY_SPECIES if s in m]
        err = " / ".join(f"{100 * m[s]['worst_rel']:.0f}" for s in sp)
        cpu = " / ".join(f"{m[s]['cpu_s']:.0f}" for s in sp)
        line = f"{name}: {err} % from the converged limit at worst, {cpu} CPU s per dried leaf ({' / '.join(sp)})"
        beaten = {}
        for s in sp:
            a = m[s]
            for other, w in table.items():
                b = (w["measured"] or {}).get(s)
                if other != level and b and b["cpu_s"] <= a["cpu_s"] and b["worst_rel"] <= a["worst_rel"] and (
                        b["cpu_s"] < a["cpu_s"] or b["worst_rel"] < a["worst_rel"]):
                    beaten.setdefault(other, []).append(s)
        for other, where in beaten.items():
            line += f"; {other} is as accurate for less CPU on {' and '.join(where)}"
        lines.append(line)
    return lines
