"""Re-run the failure cases of the reliability issue (runaway energy, momentum) with today's code
and print what each does now (one line per case).

    .venv/bin/python tools/fuzz_cases.py
"""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LEAFSIM = [str(ROOT / ".venv" / "bin" / "leafsim")]

CASES = [
    ("sigma_link=3", ["--frames", "1500", "--set", "shrink.sigma_link=3"]),
    ("sigma_surface_bottom=3", ["--frames", "1500", "--set", "shrink.sigma_surface_bottom=3"]),
    ("sigma_surface_bottom=3, l_min=0.1", ["--frames", "1500", "--set", "shrink.sigma_surface_bottom=3", "--set", "shrink.l_min=0.1"]),
    ("substeps=25, no gravity", ["--frames", "1500", "--set", "dynamics.substeps=25", "--set", "effects.gravity=false"]),
    ("sigma_surface_top=0.45 (strong curl, ground)", ["--frames", "4000", "--set", "shrink.sigma_surface_top=0.45"]),
    ("relaxation=1.3, damping=0, dt=0.008", ["--frames", "1500", "--set", "dynamics.relaxation=1.3", "--set", "dynamics.damping=0", "--set", "dynamics.dt=0.008"]),
]


def main():
    for name, args in CASES:
        t0 = time.time()
        r = subprocess.run(LEAFSIM + ["run", "--species", "maple", "--json", *args], capture_output=True, text=True)
        secs = time.time() - t0
        if r.returncode == 0:
            import json

            rep = json.loads(r.stdout)
            what = (f"exit 0 in {secs:.0f} s: {rep['frames']} frames, water {rep['water_fraction']:.3f}, margin lift "
                    f"{rep['shape_margin_lift']:.3f} L, area {rep['shape_area_ratio']:.3f}, max displacement "
                    f"{rep['shape_max_displacement']:.2f} L")
        else:
            what = f"exit {r.returncode} in {secs:.0f} s: {r.stderr.strip()}"
        print(f"| {name} | {what} |", flush=True)


if __name__ == "__main__":
    main()
