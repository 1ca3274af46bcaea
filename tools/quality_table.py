"""Write configs/quality.json (the measured error and cost of each `--quality` level) from an
accuracy study's report whose rows include every level's settings.

    .venv/bin/python tools/quality_table.py [docs/accuracy/maple_default/accuracy.json]

A level is matched to the study row whose overrides give the same values of every quality
key (within 1 %: the study's reference mesh is the default spacing × 0.71); a level the study did not run is left out (shown as "not measured").
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

from leafsim.config.params import ParamSet
from leafsim.config.presets import QUALITY, QUALITY_FILE, QUALITY_KEYS

KEEP = ("particles", "ms_frame", "ms_per_sim_s", "worst_rel", "position_rel", "height_rel", "margin_lift_rel",
        "area_3d_rel", "area_top_rel", "water_rel", "time_to_dry_rel")


def _same(a, b) -> bool:
    """Equal settings: numbers within 1 % (the study's 0.01988 is the level's 0.0199), others exactly
    (``dynamics.path``)."""
    if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        return abs(a - b) <= 0.01 * abs(b)
    return a == b


def main():
    src = Path(sys.argv[1] if len(sys.argv) > 1 else ROOT / "docs" / "accuracy" / "maple_default" / "accuracy.json").resolve()
    rep = json.loads(src.read_text())
    rows = [rep["reference"]] + rep["rows"]
    out = {"_about": f"Measured by the accuracy study in {src.relative_to(ROOT)} ({rep['species']}, seed {rep['seed']}) "
                     "against its reference; docs/accuracy.md. Relative errors; cost in ms per frame and per simulated "
                     "second on a shared 2-core machine."}
    for level, settings in QUALITY.items():
        for r in rows:
            p = ParamSet(r["overrides"])
            if all(_same(p[k], settings[k]) for k in QUALITY_KEYS):
                out[level] = {k: r.get(k, 0.0) for k in KEEP}
                out[level]["study_row"] = r["name"]
                break
    path = ROOT / "configs" / QUALITY_FILE
    path.write_text(json.dumps(out, indent=1) + "\n")
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
