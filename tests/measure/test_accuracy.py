"""`leafsim accuracy --quick`: the report's shape, and that its errors mean something."""

import json

import pytest

from leafsim.cli import main
from leafsim.config.params import PARAMS
from leafsim.measure.accuracy import METRICS, pareto_front


@pytest.mark.slow
def test_accuracy_quick_report(tmp_path, capsys):
    out = tmp_path / "acc"
    assert main(["accuracy", "--quick", "--species", "oak", "--out", str(out), "--json", "--floor", "1"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["species"] == "oak" and rep["quick"] is True
    ref = rep["reference"]
    assert ref["time_to_dry"] > 0 and 0 < ref["area_3d"] <= 1 and ref["particles"] > 0
    names = {r["name"] for r in rep["rows"]}
    assert {"default", "osmosis every 5"} <= names
    assert {r["group"] for r in rep["rows"]} >= {"default", "mesh", "iterations", "osmosis"}
    for r in rep["rows"]:
        assert "failed" not in r, r
        for m in METRICS:
            assert r[m] >= 0 and r[f"{m}_rel"] >= 0
        assert r["worst_rel"] == max(r[f"{m}_rel"] for m in METRICS)
        assert r["ms_frame"] > 0 and r["ms_per_sim_s"] > r["ms_frame"]  # Δt < 1 s
    # more substeps are closer to the reference than fewer (the reference has the most)
    rows = {r["name"]: r for r in rep["rows"]}
    most = f"{2 * PARAMS['dynamics.substeps'].default}×{PARAMS['dynamics.iterations'].default}"
    assert rows[most]["position"] < rows["2×1"]["position"]
    # the front is non-dominated and holds the cheapest run
    assert rep["front"] == pareto_front(rep["rows"])
    cheapest = min(rep["rows"], key=lambda r: r["ms_per_sim_s"])
    assert cheapest["name"] in rep["front"]
    # the sensitivity floor: the default dried again from a start perturbed by a micrometre
    (fl,) = rep["floor"]
    assert fl["setting"] == "default" and fl["runs"] == 1 and fl["amplitude_m"] == 1e-6
    for m in METRICS:
        assert 0 <= fl[m]["median"] <= fl[m]["max"] < 10
    assert fl["position"]["max"] > 0  # the perturbation acts: the runs are not the same run
    assert "Sensitivity floor" in (out / "accuracy.md").read_text()
    # the table marks the rows whose mechanics the drying path carried (none at --quick's meshes)
    md = (out / "accuracy.md").read_text()
    for r in (r for r in rep["rows"] if "failed" not in r):
        assert r["path_frames"] >= 0 and (f"| {r['name']} †" in md or f"| {r['name']} ★ †" in md) == (r["path_frames"] > 0)
    for f in ("accuracy.json", "accuracy.md", "accuracy_pareto.png"):
        assert (out / f).stat().st_size > 100
    assert (out / "accuracy_pareto.png").read_bytes()[:4] == b"\x89PNG"


def test_accuracy_bad_out(tmp_path, capsys):
    f = tmp_path / "file"
    f.write_text("x")
    assert main(["accuracy", "--quick", "--out", str(f)]) == 2
    assert "not a folder" in capsys.readouterr().err
    assert main(["accuracy", "--quick", "--groups", "mesh,speed"]) == 2
    assert "--groups mesh,speed: expected a comma list of" in capsys.readouterr().err


def test_study_measures_every_other_quality_level():
    """The full study's "quality" sweep: one row per quality level other than the defaults and
    the reference, with exactly the level's changes from the defaults."""
    from leafsim.config.params import ParamSet
    from leafsim.config.presets import QUALITY, quality_of
    from leafsim.measure.accuracy import default_sweeps

    base = ParamSet()
    rows = [s for s in default_sweeps(base, groups=["quality"]) if s.group == "quality"]
    expect = set(QUALITY) - {quality_of(base), "reference"}
    assert {s.name for s in rows} == {f"quality {k}" for k in expect}
    for s in rows:
        assert quality_of(base.with_overrides(s.overrides)) == s.name.split()[1]


def test_unperturbed_start_repeats_the_run_exactly():
    """A perturbation of amplitude 0 is the same run to the last bit (so any floor measured
    with a real perturbation is the leaf's sensitivity, not noise in the solver)."""
    import numpy as np

    from leafsim.config.species import get_species
    from leafsim.measure.accuracy import Setting, run_setting
    from leafsim.pipeline import leaf_shape
    from leafsim.sim.metrics import Probe

    sp = get_species("oak")
    base = sp.params.with_overrides({"mesh.spacing": 0.08})
    probe = Probe(leaf_shape(sp, base))
    s = Setting("default", "default", {})
    builds = {}
    a = run_setting(sp, base, s, 0.1, probe, (), 0, builds)
    b = run_setting(sp, base, s, 0.1, probe, (), 0, builds, perturb=(3, 0.0))
    c = run_setting(sp, base, s, 0.1, probe, (), 0, builds, perturb=(3, 1e-6))
    assert np.array_equal(a.end["q_own"], b.end["q_own"])
    assert not np.array_equal(a.end["q_own"], c.end["q_own"])
    assert np.isfinite(c.end["q_own"]).all()


def test_sun_integrator_sweep_runs_only_when_named():
    """Sun's explicit integrator costs two orders of magnitude more than the default study, so
    ``--groups integrator`` asks for it and the default study leaves it out."""
    from leafsim.config.params import ParamSet
    from leafsim.measure.accuracy import default_sweeps

    every = default_sweeps(ParamSet())
    assert "integrator" not in {s.group for s in every} and len(every) > 10
    named = default_sweeps(ParamSet(), groups=("integrator",))
    assert [s.group for s in named] == ["default", "integrator", "integrator"]
    assert all(s.overrides["dynamics.integrator"] == "sun" for s in named[1:])


def test_a_setting_counts_the_frames_its_drying_path_carried():
    """oak's default mesh is finer than its draft path's: the path carries the first frames;
    a mesh as coarse as the path's runs its own mesh (the accuracy table's † says which)."""
    from leafsim.config.species import get_species
    from leafsim.measure.accuracy import Setting, run_setting
    from leafsim.pipeline import leaf_shape
    from leafsim.sim.metrics import Probe

    sp = get_species("oak")
    probe = Probe(leaf_shape(sp, sp.params))
    t5 = 5 * sp.params["dynamics.dt"]
    fine = run_setting(sp, sp.params, Setting("default", "default", {}), t5, probe)
    coarse = run_setting(sp, sp.params, Setting("coarse", "mesh", {"mesh.spacing": 0.04}), t5, probe)
    assert fine.frames == 5 and fine.path_frames == 5 and coarse.path_frames == 0
