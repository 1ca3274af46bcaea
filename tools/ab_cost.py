"""Cost of a whole drying, before and after a change: two source trees raced in turn.

Each quality level is dried to the end (as ``leafsim accuracy`` does: until 2 % of the water is
left, then 15 % longer) once per round by each tree, in a fresh process, the trees taking
turns (A B, then B A, ...), so both see the same machine.  Reports the median and p90 ms per
frame (median over rounds), ms per simulated second, the CPU seconds per dried leaf (the
child's process time: build and the whole drying; with a drying path the median frame is the
cheap path frame and hides the own mesh's, so this is the number that compares), and whether
the two trees' dried leaves are bit-identical (a SHA-256 of the final positions).

    git worktree add /tmp/before <commit>
    python tools/ab_cost.py --before /tmp/before --after . --species maple \\
        --quality fine,balanced,draft --rounds 3 --json docs/accuracy/ab_cost.json \\
        --errors docs/accuracy/maple_curl_anisotropy/accuracy.json --plot docs/accuracy/ab_front.png

With ``--errors`` (a ``leafsim accuracy`` report whose rows include the quality levels) and
bit-identical results, the errors are the study's and only the cost moves: ``--plot`` draws the
accuracy front (worst relative error against ms per simulated second) before and after, the
default level marked.  ``--replot`` redraws from a saved ``--json`` without running anything.
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
import hashlib, json, sys, time
import numpy as np
from leafsim.sim.metrics import Probe
try:
    from leafsim.measure.accuracy import Setting, run_setting
    from leafsim.pipeline import leaf_shape
    from leafsim.config.presets import QUALITY
    from leafsim.config.species import get_species
except ImportError:  # a tree from before the package's stage folders (2 December: the solver issue's day)
    from leafsim.accuracy import Setting, run_setting
    from leafsim.leaf import leaf_shape
    from leafsim.sim.presets import QUALITY
    from leafsim.species import get_species
species, quality = sys.argv[1], sys.argv[2]
sp = get_species(species)
base = sp.params
cpu0 = time.process_time()
probe = Probe(leaf_shape(sp, base))
run = run_setting(sp, base, Setting(quality, "quality", dict(QUALITY[quality])), None, probe)
cpu = time.process_time() - cpu0
q = np.ascontiguousarray(run.end["q"], np.float64)
print(json.dumps({"cpu_s": cpu, "ms_frame": run.ms_frame, "ms_frame_p90": run.ms_frame_p90, "ms_per_sim_s": run.ms_per_sim_s,
                  "frames": run.frames, "particles": run.particles, "sha": hashlib.sha256(q.tobytes()).hexdigest()}))
"""


def run_once(tree: Path, species: str, quality: str) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree.resolve())}
    res = subprocess.run([sys.executable, "-c", CHILD, species, quality], env=env, capture_output=True, text=True,
                         cwd=str(tree.resolve()))
    if res.returncode:
        raise SystemExit(f"ab_cost: {tree} {species} {quality} failed:\n{res.stderr[-2000:]}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def _study_errors(path: Path) -> dict:
    """Quality level → worst relative error of a ``leafsim accuracy`` report (its default row is
    the default level, ``fine``)."""
    rows = json.loads(Path(path).read_text())["rows"]
    out = {}
    for r in rows:
        if r["name"] == "default":
            out["fine"] = r["worst_rel"]
        elif r["name"].startswith("quality "):
            out[r["name"].split(" ", 1)[1]] = r["worst_rel"]
    return out


def plot_front(rows: list[dict], errors: dict, species: str, png: Path) -> None:
    """Worst relative error against ms per simulated second, before and after, default marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=120)
    for key, colour, label in (("before", "0.55", "before"), ("after", "tab:blue", "after")):
        pts = sorted((x[f"{key}_ms_per_sim_s"], 100 * errors[x["quality"]], x["quality"]) for x in rows
                     if x["quality"] in errors)
        ax.plot([p[0] for p in pts], [p[1] for p in pts], "o--", color=colour, label=label)
        for c, e, name in pts:
            ax.annotate(name, (c, e), fontsize=7, xytext=(4, 3), textcoords="offset points", color=colour)
            if name == "fine":
                ax.scatter([c], [e], marker="*", s=240, color="crimson" if key == "after" else "0.55", zorder=4,
                           label="default (fine), after" if key == "after" else None)
    ax.set_xscale("log")
    from matplotlib.ticker import FuncFormatter, NullFormatter

    ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x:,.0f}".replace(",", " ")))
    ax.xaxis.set_minor_formatter(NullFormatter())
    lo, hi = ax.get_xlim()
    ax.set_xticks([t for t in (500, 1000, 2000, 5000, 10000, 20000, 50000, 100000) if lo <= t <= hi])
    ax.set_xlabel("ms of one core per simulated second (whole drying, median frame)")
    ax.set_ylabel("worst relative error against the reference [%]")
    ax.set_title(f"{species}: accuracy front before and after (same errors: bit-identical results)", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--before", type=Path, required=True)
    ap.add_argument("--after", type=Path, default=Path("."))
    ap.add_argument("--species", default="maple")
    ap.add_argument("--quality", default="fine,balanced,draft")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--errors", type=Path, default=None, help="a leafsim accuracy report (accuracy.json)")
    ap.add_argument("--plot", type=Path, default=None, help="PNG of the front before and after (needs --errors)")
    ap.add_argument("--replot", type=Path, default=None, help="a saved --json to plot from, running nothing")
    a = ap.parse_args(argv)
    if (a.replot or a.plot) and not (a.errors and a.plot):
        ap.error("--plot and --replot need --errors (the accuracy report) and --plot (the PNG)")
    if a.replot:
        saved = json.loads(a.replot.read_text())
        plot_front(saved["rows"], _study_errors(a.errors), saved["species"], a.plot)
        return 0
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
                print(f"round {r + 1}/{a.rounds} {lv:9s} {t:6s} {runs[(lv, t)][-1]['ms_frame']:8.2f} ms/frame "
                      f"{runs[(lv, t)][-1]['cpu_s']:8.1f} CPU s",
                      file=sys.stderr, flush=True)
    rows = []
    for lv in levels:
        b, f = runs[(lv, "before")], runs[(lv, "after")]
        med = {t: float(np.median([x["ms_frame"] for x in runs[(lv, t)]])) for t in trees}
        p90 = {t: float(np.median([x["ms_frame_p90"] for x in runs[(lv, t)]])) for t in trees}
        sim = {t: float(np.median([x["ms_per_sim_s"] for x in runs[(lv, t)]])) for t in trees}
        cpu = {t: [x["cpu_s"] for x in runs[(lv, t)]] for t in trees}
        rows.append({"quality": lv, "particles": f[0]["particles"], "frames": f[0]["frames"],
                     "before_ms_frame": med["before"], "before_ms_frame_p90": p90["before"],
                     "after_ms_frame": med["after"], "after_ms_frame_p90": p90["after"],
                     "before_ms_per_sim_s": sim["before"], "after_ms_per_sim_s": sim["after"],
                     "speedup": med["before"] / med["after"],
                     "before_cpu_s": float(np.median(cpu["before"])), "after_cpu_s": float(np.median(cpu["after"])),
                     "before_cpu_s_p90": float(np.percentile(cpu["before"], 90)),
                     "after_cpu_s_p90": float(np.percentile(cpu["after"], 90)),
                     "cpu_ratio": float(np.median(cpu["before"]) / np.median(cpu["after"])),
                     "before_frames": b[0]["frames"], "before_particles": b[0]["particles"],
                     "identical": len({x["sha"] for x in b + f}) == 1, "rounds": a.rounds})
    print(f"{'quality':10s} {'particles':>9s} {'before ms/frame (p90)':>22s} {'after ms/frame (p90)':>21s} "
          f"{'speed-up':>8s} {'ms per sim. s before / after':>29s}  identical")
    for x in rows:
        print(f"{x['quality']:10s} {x['particles']:9d} {x['before_ms_frame']:12.2f} ({x['before_ms_frame_p90']:6.2f}) "
              f"{x['after_ms_frame']:11.2f} ({x['after_ms_frame_p90']:6.2f}) {x['speedup']:8.2f} "
              f"{x['before_ms_per_sim_s']:14.0f} / {x['after_ms_per_sim_s']:<12.0f}  {x['identical']}")
    print(f"\n{'quality':10s} {'CPU s per dried leaf before (p90)':>34s} {'after (p90)':>16s} {'ratio':>6s}")
    for x in rows:
        print(f"{x['quality']:10s} {x['before_cpu_s']:24.1f} ({x['before_cpu_s_p90']:6.1f}) "
              f"{x['after_cpu_s']:8.1f} ({x['after_cpu_s_p90']:6.1f}) {x['cpu_ratio']:6.2f}")
    if a.json:
        a.json.parent.mkdir(parents=True, exist_ok=True)
        a.json.write_text(json.dumps({"species": a.species, "rows": rows, "load": os.getloadavg()[0]}, indent=1))
    if a.plot and a.errors:
        plot_front(rows, _study_errors(a.errors), a.species, a.plot)
    return 0


if __name__ == "__main__":
    sys.exit(main())
