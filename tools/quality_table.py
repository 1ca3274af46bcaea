"""Write configs/quality.json (the measured error and cost of each `--quality` level) from the
limit studies of maple, oak and grapevine (`leafsim accuracy --limit`, docs/accuracy/limit_*/limit.json).

    .venv/bin/python tools/quality_table.py [--check]

Each study dried the leaf at the defaults ("default", the level the declared defaults are) and at
`--quality balanced` and `--quality draft` to the protocol's end, and scored each against the
converged limit of three static meshes.  Per level and species the file keeps the worst relative
error over the study's measures, the CPU seconds per dried leaf and the particles.  A level a
study did not run is left out ("not measured").  ``--check`` compares instead of writing (exit 1
when configs/quality.json is not what the studies give).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

from leafsim.config.params import ParamSet  # noqa: E402
from leafsim.config.presets import QUALITY, QUALITY_FILE, QUALITY_SPECIES, quality_of  # noqa: E402

KEEP = ("worst_rel", "cpu_s", "particles", "position_rel", "height_rel", "margin_lift_rel", "water_rel")


def build() -> dict:
    default = quality_of(ParamSet())
    out = {"_about": "Measured by the limit studies docs/accuracy/limit_{" + ",".join(QUALITY_SPECIES) + "}/limit.json "
                     "(leafsim accuracy --limit): per level and species the worst relative error against the converged "
                     "limit, the CPU seconds per dried leaf (a shared 2-core machine) and the particles; docs/accuracy.md. "
                     "Written by tools/quality_table.py."}
    for species in QUALITY_SPECIES:
        rep = json.loads((ROOT / "docs" / "accuracy" / f"limit_{species}" / "limit.json").read_text())
        rows = {r["name"]: r for r in rep["rows"]}
        for level in QUALITY:
            r = rows.get("default" if level == default else f"quality {level}")
            if r is not None:
                out.setdefault(level, {})[species] = {k: r[k] for k in KEEP} | {"study_row": r["name"]}
    return out


def main():
    out = build()
    text = json.dumps(out, indent=1) + "\n"
    path = ROOT / "configs" / QUALITY_FILE
    if "--check" in sys.argv[1:]:
        same = path.is_file() and path.read_text() == text
        print("configs/quality.json is " + ("what the studies give" if same else "stale: run tools/quality_table.py"))
        sys.exit(0 if same else 1)
    path.write_text(text)
    print(text, end="")


if __name__ == "__main__":
    main()
