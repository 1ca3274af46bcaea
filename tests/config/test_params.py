import math

import pytest

from helpers.paths import HANG_S, REPO
from leafsim.base.errors import LeafsimError
from leafsim.config.params import GROUPS, PARAMS, ParamSet, markdown_table, parse_set_args


@pytest.mark.parametrize("name", sorted(PARAMS))
def test_default_in_range_and_described(name):
    p = PARAMS[name]
    assert p.help and p.group in GROUPS
    assert p.coerce(p.default) == p.default
    if p.kind in ("float", "int"):
        assert p.lo <= p.default <= p.hi
        assert math.isfinite(p.lo) and math.isfinite(p.hi) and p.lo < p.hi
    if p.kind == "choice":
        assert p.default in p.choices


def test_names_are_dotted_and_unique():
    assert len(PARAMS) > 60
    for name in PARAMS:
        assert name.count(".") >= 1 and name == name.strip()


def test_unknown_key_rejected_with_suggestion():
    with pytest.raises(LeafsimError, match=r"unknown parameter 'veins.main.kapa'.*veins.main.kappa"):
        ParamSet({"veins.main.kapa": 1})


@pytest.mark.parametrize("key,value", [
    ("mesh.spacing", -0.01), ("mesh.spacing", float("nan")), ("dynamics.tolerance", 0.0),
    ("veins.lateral.spacing", 2.5), ("veins.lateral.alternation", "zigzag"), ("effects.pbd", "maybe"),
    ("veins.main.kappa", "abc"), ("dynamics.dt", float("inf")), ("mass.D", True),
])
def test_bad_values_rejected_naming_the_key(key, value):
    with pytest.raises(LeafsimError) as e:
        ParamSet({key: value})
    msg = str(e.value)
    assert key in msg and "expected" in msg and "\n" not in msg


def test_nested_and_flat_keys_agree_and_overrides_validate():
    a = ParamSet({"veins": {"main": {"kappa": 7}}})
    b = ParamSet({"veins.main.kappa": 7})
    assert a == b and a["veins.main.kappa"] == 7.0
    c = b.with_overrides({"osmosis.diffusion": 5e-4})
    assert c["osmosis.diffusion"] == 5e-4 and c.changed() == {"veins.main.kappa": 7.0, "osmosis.diffusion": 5e-4}
    assert b.rebuild_differs(ParamSet()) and not c.with_overrides({"veins.main.kappa": 7}).rebuild_differs(c)



def test_set_args_parse_types():
    d = parse_set_args(["veins.lateral.spacing=4", "effects.pbd=off", "dynamics.voronoi=replace"])
    assert d == {"veins.lateral.spacing": 4, "effects.pbd": False, "dynamics.voronoi": "replace"}
    with pytest.raises(LeafsimError, match="KEY=VALUE"):
        parse_set_args(["novalue"])


def test_markdown_lists_every_parameter():
    md = markdown_table()
    for name in PARAMS:
        assert f"`{name}`" in md


def test_docs_parameters_md_is_generated_from_the_declarations():
    """docs/parameters.md is `leafsim params --markdown` (regenerate it when a parameter changes)."""
    from helpers.paths import REPO as ROOT

    assert (ROOT / "docs" / "parameters.md").read_text(encoding="utf-8") == markdown_table() + "\n"


def test_integer_ranges_fit_an_int_slider():
    """The GUI's integer slider (imgui) takes ranges within ±(2³¹−1)/2 only (it aborts otherwise)."""
    for p in PARAMS.values():
        if p.kind == "int":
            assert -(2**31 - 1) // 2 <= p.lo < p.hi <= (2**31 - 1) // 2, p.name


def test_quality_levels_set_every_quality_key_and_are_recognised():
    from leafsim.config.presets import QUALITY, QUALITY_KEYS, quality_of, quality_overrides, quality_table

    assert quality_of(ParamSet()) == "fine"  # the declared defaults are the fine level (within 10 %)
    for name in QUALITY:
        o = quality_overrides(name)
        assert set(o) == set(QUALITY_KEYS)
        assert quality_of(ParamSet(o)) == name
    assert quality_of(ParamSet({"dynamics.substeps": 7})) is None
    t = quality_table()
    assert set(t) == set(QUALITY)
    for v in t.values():  # per measured species: the error from the limit and the CPU per dried leaf
        for m in (v["measured"] or {}).values():
            assert m["cpu_s"] > 0 and 0 <= m["worst_rel"] < 10 and m["particles"] > 0
    with pytest.raises(LeafsimError, match="expected one of draft"):
        quality_overrides("best")


def test_quality_file_is_what_the_limit_studies_give():
    """configs/quality.json is tools/quality_table.py's digest of the shipped limit studies (the
    GUI's quality tooltip and `leafsim params` quote it; it had gone stale)."""
    import subprocess
    import sys

    r = subprocess.run([sys.executable, str(REPO / "tools" / "quality_table.py"), "--check"], cwd=REPO,
                       capture_output=True, text=True, timeout=HANG_S)
    assert r.returncode == 0, r.stdout + r.stderr


def test_quality_lines_name_a_level_another_one_beats():
    """A level that costs more CPU for no less error than another, on a species, says so."""
    from leafsim.config.presets import quality_lines

    m = lambda e, c: {"worst_rel": e, "cpu_s": c, "particles": 1}  # noqa: E731
    table = {"draft": {"measured": {"maple": m(0.30, 16), "oak": m(0.12, 4)}},
             "balanced": {"measured": {"maple": m(0.34, 50), "oak": m(0.10, 12)}},
             "fine": {"measured": {"maple": m(0.13, 77), "oak": m(0.09, 10)}},
             "reference": {"measured": None}}
    lines = quality_lines(table, "fine")
    assert lines[0].startswith("draft: 30 / 12 % from the converged limit") and "as accurate" not in lines[0]
    assert lines[1].endswith("; draft is as accurate for less CPU on maple; fine is as accurate for less CPU on oak")
    assert lines[2].startswith("fine (default): 13 / 9 %") and "as accurate" not in lines[2]
    assert lines[3] == "reference: not measured"


def test_json_values_must_be_json_numbers_and_switches_but_set_values_are_text():
    """A file's quoted "0.3" or "true" is refused in one line naming the key; --set's text is
    parsed (it is text by nature); a choice is a string either way."""
    from leafsim.config.params import json_typed, parse_set_args

    ok = {"mesh": {"spacing": 0.03}, "veins.lateral.enabled": False, "osmosis.solver": "direct"}
    assert json_typed(ok, "f.json") is ok
    for bad, key in [({"mesh.spacing": "0.03"}, "mesh.spacing"), ({"veins": {"lateral": {"enabled": "true"}}}, "veins.lateral.enabled"),
                     ({"outline.points": "2000"}, "outline.points")]:
        with pytest.raises(LeafsimError) as e:
            json_typed(bad, "f.json")
        msg = str(e.value)
        assert msg.startswith("f.json: parameter '" + key) and "is a string" in msg and "\n" not in msg
    assert "true or false" in str(pytest.raises(LeafsimError, json_typed, {"veins.lateral.enabled": "1"}).value)
    assert parse_set_args(["mesh.spacing=0.03"]) == {"mesh.spacing": 0.03}


def test_numpy_scalars_are_taken_as_their_python_values():
    """A sweep in code iterates numpy arrays: np.bool_ is a switch's value (it was refused as not
    true or false while np.float64 and np.int64 were taken), and no switch value is a number."""
    import numpy as np

    from leafsim.config.species import get_species

    p = get_species("oak").params
    assert [p.with_overrides({"effects.colour": f})["effects.colour"] for f in np.array([True, False])] == [True, False]
    assert p.with_overrides({"osmosis.every": np.int64(3)})["osmosis.every"] == 3
    assert p.with_overrides({"mesh.spacing": np.float32(0.03)})["mesh.spacing"] == pytest.approx(0.03)
    with pytest.raises(LeafsimError, match="'mesh.spacing' = np.True_"):
        p.with_overrides({"mesh.spacing": np.True_})


def test_a_parameter_declared_for_one_drive_does_nothing_under_the_other(tiny):
    """``only`` is a promise the window keeps by dimming the widget: each parameter declared for
    one evaporation drive leaves a drying under the other drive bit for bit as it was (30
    frames of the tiny leaf), and does change it under its own."""
    import numpy as np

    from leafsim.sim.simulator import Simulator

    def water(over):
        p = ParamSet({"mesh.spacing": 0.06, **over})
        sim = Simulator(tiny, p, effects=("osmosis", "colour"), seed=0)
        st = sim.state()
        for _ in range(30):
            sim.step(st)
        return st.particle_water.copy()

    doc = markdown_table()
    declared = [p for p in PARAMS.values() if p.only and p.only[0] == "environment.drive"]
    assert {p.name for p in declared} >= {"environment.temperature", "osmosis.evaporation_top", "osmosis.g_min"}
    base = {d: water({"environment.drive": d}) for d in ("rates", "weather")}
    for p in declared:
        key, own = p.only
        other = "weather" if own == "rates" else "rates"
        v = p.lo + 0.37 * (p.hi - p.lo) if p.kind == "float" else p.default
        assert np.array_equal(water({key: other, p.name: v}), base[other]), p.name
        if p.name != "osmosis.stomata_open_rwc":  # (open above 0.97: 30 frames do not reach it)
            assert not np.array_equal(water({key: own, p.name: v}), base[own]), p.name
        assert p.applies(ParamSet({key: own})) and not p.applies(ParamSet({key: other}))
        assert f"Acts only with `{key} = {own}`." in doc


def test_the_parameters_of_one_integrator_path_or_solver_say_when_they_act():
    """Parameters whose help says "With X = Y" declare it, so the window dims them and the
    parameter table says so (a parameter audit found them active-looking where they do nothing):
    Sun's integrator's, the drying path's, the iterative osmosis solvers', the rigid modes' air
    damping; a condition may name several values.  (Turgor pressure is not one of them: the
    static solves use it too.)"""
    want = {"dynamics.sun_substeps": ("dynamics.integrator", "sun", "xpbd"),
            "dynamics.sun_courant": ("dynamics.integrator", "sun", "static"),
            "dynamics.sun_damping": ("dynamics.integrator", "sun", "xpbd"),
            "dynamics.handover": ("dynamics.path", "fine", "own"),
            "dynamics.finish": ("dynamics.path", "draft", "own"),
            "osmosis.tolerance": ("osmosis.solver", "cg", "direct"),
            "dynamics.air_damping": ("dynamics.rigid_inertia", True, False)}
    doc = markdown_table()
    for name, (key, on, off) in want.items():
        p = PARAMS[name]
        assert p.only and p.only[0] == key, name
        assert p.applies(ParamSet({key: on})) and not p.applies(ParamSet({key: off})), name
        assert f"Acts only with `{p.only_text()}`." in doc, name
    assert PARAMS["dynamics.handover"].only_text() == "dynamics.path = draft or fine"
    assert PARAMS["dynamics.air_damping"].only_text() == "dynamics.rigid_inertia = true"
    # turgor pressure also acts in the static solves (a static integrator or finish): no only=
    assert not PARAMS["material.turgor_pressure"].only
