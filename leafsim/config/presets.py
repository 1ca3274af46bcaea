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

#: quality levels: points of the accuracy study's Pareto front (docs/accuracy.md).  "fine" is the
#: declared defaults, chosen as the fastest point within 10 % of a reference one √2 refinement
#: finer on every metric for maple, grapevine and oak (mesh 0.0199 L, 40 substeps with the inertia
#: scaled × 64, dynamics.mass_scaling); re-measured on the model with stalks and traced veins it is
#: 9 % (maple), 5 % (oak, with its own shrinkage and static finish) and 21 % (grapevine, a mesh dependence:
#: docs/accuracy.md).  "balanced"
#: is the previous default, a √2 coarser mesh (20 substeps from the scaling), ≈ 3.5× cheaper at
#: ≈ 18 % worst; "draft" takes a quarter of balanced's substeps with the inertia × 256 (the same
#: n √M).  The measured error and cost of each are in configs/quality.json, written by
#: tools/quality_table.py from one study (docs/accuracy/maple_default).  "fine" dries most of the
#: water with its mechanics on the draft mesh (dynamics.path, leafsim.sim.path): as close to the
#: reference as the direct run for 2.5–3.3× less CPU (docs/performance.md).
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
    """Each quality level's settings with its measured error and cost (from configs/quality.json;
    ``measured`` is None for a level the study has not measured)."""
    import json
    from pathlib import Path

    from leafsim.base.resources import data_dir

    path = Path(config_dir or data_dir("configs")) / QUALITY_FILE
    measured = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}
    return {k: {"settings": v, "measured": measured.get(k)} for k, v in QUALITY.items()}
