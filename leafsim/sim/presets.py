"""Parameter presets (dotted names of :mod:`leafsim.params`).

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

DEFAULT_NOTES = (
    "Defaults: σ_surface T 0.15 / V 0.165, σ_vein 0.05, l_min 0.5 → a dried leaf keeps ≈ 80–90 % "
    "of its 3D area; 5 substeps × 2 XPBD iterations (same cost as 10 iterations, far stiffer); "
    "hinges keep the largest bilayer curl they reached (plasticity) so the curl lasts."
)

PRESETS = {"thesis": THESIS_PRESET}
