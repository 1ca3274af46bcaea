"""Cost of a whole drying, before and after a change: two source trees raced in turn.

Each quality level is dried to the end (as ``leafsim accuracy`` does: until 2 % of the water is
left, then 15 % longer) once per round by each tree, in a fresh process, the trees taking
turns (A B, then B A, ...), so both see the same machine.  Reports the median and p90 ms per
frame (median over rounds), ms per simulated second, and whether the two trees' dried leaves
are bit-identical (a SHA-256 of the final positions).

    git worktree add /tmp/before <commit>
    python scripts/ab_cost.py --before /tmp/before --after . --species maple \\
        --quality fine,balanced,draft --rounds 3 --json docs/accuracy/ab_cost.json
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

CHILD = r"""
import hashlib, json, sys
import numpy as np
from leafsim.accuracy import Setting, run_setting
from leafsim.leaf import leaf_shape
from leafsim.sim.metrics import Probe
from leafsim.sim.presets import QUALITY
from leafsim.species import get_species
species, quality = sys.argv[1], sys.argv[2]
sp = get_species(species)
base = sp.params
probe = Probe(leaf_shape(sp, base))
run = run_setting(sp, base, Setting(quality, "quality", dict(QUALITY[quality])), None, probe)
q = np.ascontiguousarray(run.end["q"], np.float64)
print(json.dumps({"ms_frame": run.ms_frame, "ms_frame_p90": run.ms_frame_p90, "ms_per_sim_s": run.ms_per_sim_s,
                  "frames": run.frames, "particles": run.particles, "sha": hashlib.sha256(q.tobytes()).hexdigest()}))
"""


def run_once(tree: Path, species: str, quality: str) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree.resolve())}
    res = subprocess.run([sys.executable, "-c", CHILD, species, quality], env=env, capture_output=True, text=True,
                         cwd=str(tree.resolve()))
    if res.returncode:
        raise SystemExit(f"ab_cost: {tree} {species} {quality} failed:\n{res.stderr[-2000:]}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--before", type=Path, required=True)
    ap.add_argument("--after", type=Path, default=Path("."))
    ap.add_argument("--species", default="maple")
    ap.add_argument("--quality", default="fine,balanced,draft")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args(argv)
    trees = {"before": a.before, "after": a.after}
    levels = a.quality.split(",")
    for name, tree in trees.items():  # compile (and fill numba's cache) outside the timed rounds
        run_once(tree, a.species, "draft")
    runs = {(lv, t): [] for lv in levels for t in trees}
    for r in range(a.rounds):
        for lv in levels:
            order = list(trees) if r % 2 == 0 else list(reversed(trees))
            for t in order:
                runs[(lv, t)].append(run_once(trees[t], a.species, lv))
                print(f"round {r + 1}/{a.rounds} {lv:9s} {t:6s} {runs[(lv, t)][-1]['ms_frame']:8.2f} ms/frame",
                      file=sys.stderr, flush=True)
    rows = []
    for lv in levels:
        b, f = runs[(lv, "before")], runs[(lv, "after")]
        med = {t: float(np.median([x["ms_frame"] for x in runs[(lv, t)]])) for t in trees}
        p90 = {t: float(np.median([x["ms_frame_p90"] for x in runs[(lv, t)]])) for t in trees}
        sim = {t: float(np.median([x["ms_per_sim_s"] for x in runs[(lv, t)]])) for t in trees}
        rows.append({"quality": lv, "particles": f[0]["particles"], "frames": f[0]["frames"],
                     "before_ms_frame": med["before"], "before_ms_frame_p90": p90["before"],
                     "after_ms_frame": med["after"], "after_ms_frame_p90": p90["after"],
                     "before_ms_per_sim_s": sim["before"], "after_ms_per_sim_s": sim["after"],
                     "speedup": med["before"] / med["after"],
                     "identical": len({x["sha"] for x in b + f}) == 1, "rounds": a.rounds})
    print(f"{'quality':10s} {'particles':>9s} {'before ms/frame (p90)':>22s} {'after ms/frame (p90)':>21s} "
          f"{'speed-up':>8s} {'ms per sim. s before / after':>29s}  identical")
    for x in rows:
        print(f"{x['quality']:10s} {x['particles']:9d} {x['before_ms_frame']:12.2f} ({x['before_ms_frame_p90']:6.2f}) "
              f"{x['after_ms_frame']:11.2f} ({x['after_ms_frame_p90']:6.2f}) {x['speedup']:8.2f} "
              f"{x['before_ms_per_sim_s']:14.0f} / {x['after_ms_per_sim_s']:<12.0f}  {x['identical']}")
    if a.json:
        a.json.parent.mkdir(parents=True, exist_ok=True)
        a.json.write_text(json.dumps({"species": a.species, "rows": rows, "load": os.getloadavg()[0]}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
