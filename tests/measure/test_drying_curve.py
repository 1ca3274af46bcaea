"""The weather-driven drying curve against 12 measured detached leaves (tests/data, pvldcurve):
the declared conductances predict the measured curve, a fit recovers a g_min in the published
range, and a broken file is one clear error."""

from pathlib import Path

import numpy as np
import pytest

from leafsim.base.errors import LeafsimError
from leafsim.measure.drying import fit, leaf_overrides, load_curves, mean_weather, measured_window, model_curve

DATA = Path(__file__).resolve().parents[1] / "data"
TABLE = DATA / "pvldcurve_kohlrabi_leaf_drying_RWC.csv"


@pytest.fixture(scope="module")
def measured():
    curves = load_curves(TABLE)
    T, RH = mean_weather(DATA / "pvldcurve_weather.csv", measured_window(TABLE))
    return curves, leaf_overrides(curves, T, RH)


def test_measured_data_as_documented(measured):
    curves, ov = measured
    assert curves.rwc.shape == (12, len(curves.hours))
    assert ov["environment.temperature"] == pytest.approx(24.4, abs=0.1)
    assert ov["environment.humidity"] == pytest.approx(0.486, abs=0.005)
    # the two phases: ≈ 0.80–0.88 after 2 h, 0.69–0.82 at 11 h
    i2, i11 = list(curves.hours).index(2.0), list(curves.hours).index(11.0)
    assert 0.77 <= curves.median[i2] <= 0.9 and 0.75 <= curves.median[i11] <= 0.82


def test_default_conductances_predict_the_measured_curve(measured):
    curves, ov = measured
    model = model_curve(ov, curves.hours)
    ok = np.isfinite(curves.median)
    rms = np.sqrt(np.mean((model[ok] - curves.median[ok]) ** 2))
    inside = np.mean((model[ok] >= curves.lo[ok]) & (model[ok] <= curves.hi[ok]))
    assert rms < 0.03 and inside >= 0.9, (rms, inside)
    # and not by accident: a leaf with its stomata never open misses the fast first phase
    closed = model_curve({**ov, "osmosis.g_stomata": 0.0}, curves.hours)
    assert np.sqrt(np.mean((closed[ok] - curves.median[ok]) ** 2)) > 2 * rms


def test_fit_recovers_a_published_range_conductance(measured):
    curves, ov = measured
    f = fit(curves, ov)
    assert f["rms"] < 0.01 and f["in_band"] == 1.0
    # Duursma et al. 2019 compile g_min of 0.95–11.3 mmol m⁻² s⁻¹ for our genera
    assert 0.5 < f["values"]["osmosis.g_min"] < 12.0


def test_broken_table_is_one_clear_error(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("sample,hours\n1,0.0\n", encoding="utf-8")
    with pytest.raises(LeafsimError, match="bad.csv: not a pvldcurve drying table"):
        load_curves(bad)
    with pytest.raises(LeafsimError, match="no logged time inside"):
        mean_weather(DATA / "pvldcurve_weather.csv", ("1990-01-01", "1990-01-02"))
