"""leaf_measures is the library's call for what `leafsim run --json` reports of a state."""

from __future__ import annotations

import json

from leafsim.cli import main
from leafsim.config.species import get_species
from leafsim.pipeline import build_leaf
from leafsim.sim import leaf_measures
from leafsim.sim.run import Run, Stop


def test_leaf_measures_are_the_cli_s_numbers(capsys):
    sp = get_species("oak")
    p = sp.params.with_overrides({"mesh.spacing": 0.06, "shrink.patchiness": 0.5})
    model = build_leaf(sp, p, seed=3).model
    run = Run(model, p)
    for _ in run.frames(Stop(frames=60)):
        pass
    m = leaf_measures(model, run.state, p)
    assert main(["run", "--species", "oak", "--seed", "3", "--set", "mesh.spacing=0.06", "--set", "shrink.patchiness=0.5",
                 "--frames", "60", "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert set(m) <= set(rep) and {k: rep[k] for k in m} == m
    assert m["time_s"] > 0 and 0 < m["water_fraction"] < 1 and "shape_margin_lift" in m and "shape_midrib_fold_deg" in m
