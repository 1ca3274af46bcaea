"""`leafsim accuracy --limit`: Richardson extrapolation recovers a known limit and order,
flags meshes outside the asymptotic range, and the study's report holds what it says."""

import json
import math

import numpy as np
import pytest

from leafsim.base.errors import LeafsimError
from leafsim.cli import main
from leafsim.measure.limit import P_MAX, P_MIN, RATIO, extrapolate, richardson


@pytest.mark.parametrize("p", [1.2, 2.0, 1.5])
def test_richardson_recovers_the_limit_and_the_order(p):
    h = np.array([1.0, 1.0 / RATIO, 0.5]) * 0.02
    f = [0.3 + 7.0 * x ** p for x in h]
    lim, order, raw, gci = richardson(f)
    assert lim == pytest.approx(0.3, abs=1e-12)
    assert order == pytest.approx(p, abs=1e-9) and raw == pytest.approx(p, abs=1e-9)
    # the GCI bounds the error of the finest mesh against the limit, with its safety factor
    assert abs(f[-1] - 0.3) == pytest.approx(gci / 1.25, rel=1e-9)


def test_richardson_extrapolates_fields_point_by_point_with_one_order():
    rng = np.random.default_rng(0)
    lim0 = rng.normal(size=(50, 3))
    c = rng.normal(size=(50, 3))
    h = np.array([1.0, 1.0 / RATIO, 0.5])
    lim, order, _, _ = richardson([lim0 + c * x ** 2 for x in h])
    np.testing.assert_allclose(lim, lim0, atol=1e-12)
    assert order == pytest.approx(2.0)


def test_richardson_does_not_extrapolate_outside_the_asymptotic_range():
    # differences that grow under refinement: no order, the finest value stands for the limit
    lim, order, raw, gci = richardson([1.0, 1.1, 1.3])
    assert raw < 0 and math.isnan(order) and lim == 1.3
    assert gci == pytest.approx(3 * 0.2 / (RATIO - 1))
    # an order above the range is clamped
    lim, order, raw, gci = richardson([1.0, 1.0 - 1.0 / 32, 1.0 - 1.0 / 32 - 1.0 / 1024])
    assert raw > P_MAX and order == P_MAX
    # differences that vanish on the finest pair: nothing observed, the first difference sets the GCI
    lim, order, raw, gci = richardson([1.0, 1.2, 1.2])
    assert lim == 1.2 and math.isnan(order) and gci == pytest.approx(3 * 0.2 / (RATIO - 1))
    # an oscillating sequence is not extrapolated outside its bracket
    lim, order, raw, gci = richardson([1.0, 1.2, 1.1])
    assert lim == 1.1 and math.isnan(order) and math.isnan(raw)
    f = np.array([[1.0, -1.0], [1.2, -1.2], [1.1, -1.1]])
    lim, order, _, _ = richardson(list(f))
    np.testing.assert_array_equal(lim, f[2])
    assert math.isnan(order)
    with pytest.raises(LeafsimError, match="three meshes"):
        richardson([1.0, 2.0])


def test_extrapolate_takes_every_measure():
    h = [x * x for x in (1.0, 1.0 / RATIO, 0.5)]  # second order
    ends = [{"q_own": np.full((4, 3), 1 + x), "q": np.full((4, 3), 2 + x), "water_field": np.full(4, x),
             "margin_lift": 0.2 + x, "margin_lift_mean": 0.1 + x, "area_3d": 0.8 - x, "area_top": 0.7 - x, "water": x}
            for x in h]
    lim, info = extrapolate(ends, [[np.full(4, 0.5 + x)] for x in h], [4.0 + x for x in h])
    assert lim["end"]["margin_lift"] == pytest.approx(0.2) and lim["time_to_dry"] == pytest.approx(4.0)
    np.testing.assert_allclose(lim["end"]["q_own"], 1.0)
    np.testing.assert_allclose(lim["water"][0], 0.5)
    assert math.isclose(info["area_top"]["order"], 2.0)


def test_cache_needs_limit(tmp_path, capsys):
    assert main(["accuracy", "--quick", "--cache", str(tmp_path / "c")]) == 2
    assert "--cache: only with --limit" in capsys.readouterr().err


@pytest.mark.slow
def test_limit_quick_report_and_its_cache(tmp_path, capsys):
    cache = tmp_path / "cache"
    out = tmp_path / "lim"
    args = ["accuracy", "--limit", "--quick", "--species", "oak", "--cache", str(cache), "--out", str(out), "--json"]
    assert main(args) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["species"] == "oak" and set(rep["limit"]) >= {"margin_lift", "area_3d", "area_top", "time_to_dry"}
    groups = [r["group"] for r in rep["rows"]]
    assert groups.count("limit") == 3 and "default" in groups and "static" in groups
    for r in rep["rows"]:
        assert "failed" not in r, r
        assert r["cpu_s"] > 0 and r["worst_rel"] >= 0
    parts = [n["particles"] for n in rep["newton"]]
    assert parts == sorted(parts) and all(n["solves"] > 0 and n["newton_median"] >= 1 for n in rep["newton"])
    assert (out / "limit.md").read_text().count("| static r=") >= 3
    assert (out / "limit_front.png").read_bytes()[:4] == b"\x89PNG"
    runs = sorted(cache.glob("*.npz"))
    assert len(runs) == len(rep["rows"])
    # a second study takes every run from the cache: the same report
    assert main(args) == 0
    again = json.loads(capsys.readouterr().out)
    assert again["limit"] == rep["limit"] and [r["cpu_s"] for r in again["rows"]] == [r["cpu_s"] for r in rep["rows"]]


def test_a_cached_run_round_trips_and_a_damaged_one_is_run_again(tmp_path):
    from leafsim.measure.accuracy import Setting, SettingResult
    from leafsim.measure.limit import load_run, save_run

    s = Setting("static r=0.02", "limit", {"mesh.spacing": 0.02, "dynamics.integrator": "static"}, "x")
    end = {"q": np.arange(12.0).reshape(4, 3), "q_own": np.ones((4, 3)), "water_field": np.full(4, 0.5),
           "margin_lift": 0.25, "area_3d": 0.8}
    r = SettingResult(s, 100, 50, 1.5, 2.0, 3.0, 1000.0, 4.2, end, [np.full(4, 0.7)], cpu=1.25,
                      solver={"solves": 3, "newton_median": 4.0})
    f = tmp_path / "run.npz"
    save_run(f, r)
    got = load_run(f, s)
    assert got.cpu == 1.25 and got.solver == r.solver and got.time_to_dry == 4.2 and got.end["margin_lift"] == 0.25
    np.testing.assert_array_equal(got.end["q"], end["q"])
    np.testing.assert_array_equal(got.water[0], 0.7)
    assert load_run(f, Setting("other", "limit", {"mesh.spacing": 0.03}, "")) is None  # another setting's
    f.write_bytes(b"not a zip")
    assert load_run(f, s) is None  # damaged: run again


def test_limit_refuses_the_reference_studys_options(capsys):
    assert main(["accuracy", "--limit", "--quick", "--floor", "2"]) == 2
    err = capsys.readouterr().err
    assert "--limit" in err and "--floor" in err and err.count("\n") == 1
