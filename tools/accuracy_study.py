"""The full accuracy study for the docs: ``leafsim accuracy`` on maple (every sweep) and the
mesh / iteration / inertia convergence of grapevine and oak; writes docs/accuracy/ and prints tables.

    .venv/bin/python tools/accuracy_study.py [--species maple,grapevine,oak] [--out docs/accuracy]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

from leafsim.measure.accuracy import markdown, study, write_report


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--species", default="maple,grapevine,oak")
    ap.add_argument("--out", default=str(ROOT / "docs" / "accuracy"))
    a = ap.parse_args()
    for sp in a.species.split(","):
        t0 = time.time()
        groups = None if sp == "maple" else ("mesh", "iterations", "mass")  # maple gets every sweep
        rep = study(sp, groups=groups, progress=True)
        rep["wall_s"] = round(time.time() - t0, 1)
        write_report(rep, Path(a.out) / sp)
        print(f"## {sp} ({rep['wall_s']} s)\n\n{markdown(rep)}\n", flush=True)


if __name__ == "__main__":
    main()
