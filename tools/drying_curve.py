"""The weather-driven drying curve against the measured one (docs/drying/curve.md, curve.png).

    python tools/drying_curve.py [--out docs/drying]

A model leaf with the measured kohlrabi leaves' dry mass and water per area dries in the
weather logged during their weighing (tests/data, pvldcurve, MIT): RWC(t) with the declared
default conductances (a prediction), and with the conductances fitted to the measured median.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from leafsim.base.fileio import atomic_write_bytes
from leafsim.config.params import PARAMS
from leafsim.measure.drying import FIT_KEYS, fit, leaf_overrides, load_curves, mean_weather, measured_window, model_curve

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "docs" / "drying"))
    a = ap.parse_args()
    out = Path(a.out)
    table = DATA / "pvldcurve_kohlrabi_leaf_drying_RWC.csv"
    curves = load_curves(table)
    T, RH = mean_weather(DATA / "pvldcurve_weather.csv", measured_window(table))
    ov = leaf_overrides(curves, T, RH)
    t0 = time.process_time()
    pred = model_curve(ov, curves.hours)
    fitted = fit(curves, ov)
    ok = np.isfinite(curves.median)
    band = lambda c: float(np.mean((c[ok] >= curves.lo[ok] - 1e-9) & (c[ok] <= curves.hi[ok] + 1e-9)))
    rms = lambda c: float(np.sqrt(np.mean((c[ok] - curves.median[ok]) ** 2)))
    report = {"weather": {"temperature_C": round(T, 2), "humidity": round(RH, 4)},
              "leaf": {"lma_kg_m2": round(curves.lma, 5), "water_fraction": round(curves.water_fraction, 4),
                       "water_kg_m2": round(curves.water_per_area, 4)},
              "hours": curves.hours.tolist(), "median": np.round(curves.median, 4).tolist(),
              "lo": np.round(curves.lo, 4).tolist(), "hi": np.round(curves.hi, 4).tolist(),
              "default": {"values": {k: PARAMS[k].default for k in FIT_KEYS}, "curve": np.round(pred, 4).tolist(),
                          "rms": round(rms(pred), 4), "in_band": round(band(pred), 3)},
              "fitted": {"values": {k: round(v, 4) for k, v in fitted["values"].items()},
                         "curve": np.round(fitted["curve"], 4).tolist(), "rms": round(fitted["rms"], 4),
                         "in_band": round(fitted["in_band"], 3)},
              "cpu_s": round(time.process_time() - t0, 1)}
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(out / "curve.json", (json.dumps(report, indent=1) + "\n").encode(), "report")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=120)
    for r in curves.rwc:
        ax.plot(curves.hours, r, color="0.75", lw=0.8)
    ax.plot(curves.hours, curves.median, "k-", lw=2, label="measured, 12 kohlrabi leaves (median; grey: each)")
    ax.plot(curves.hours, pred, "C0--", lw=2, label=f"model, default conductances (RMS {report['default']['rms']:.3f})")
    ax.plot(curves.hours, fitted["curve"], "C3:", lw=2, label=f"model, fitted conductances (RMS {report['fitted']['rms']:.3f})")
    ax.set_xlabel("hours after detaching")
    ax.set_ylabel("relative water content")
    ax.set_title(f"Drying in the logged weather ({T:.1f} °C, {100 * RH:.0f} % RH, still air)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "curve.png")
    print(json.dumps({k: report[k] for k in ("weather", "leaf", "cpu_s")}))
    for k in ("default", "fitted"):
        print(k, report[k]["values"], "RMS", report[k]["rms"], "in band", report[k]["in_band"])


if __name__ == "__main__":
    main()
