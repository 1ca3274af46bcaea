"""Markdown tables of a ``leafsim bench --json`` result (docs/performance.md).

    .venv/bin/leafsim bench --json > docs/bench.json
    python tools/bench_tables.py docs/bench.json            # every table
    python tools/bench_tables.py docs/bench.json --readme   # the summary table (docs/performance.md, "Summary")

The summary table was the top-level README's until 6 December; the flag keeps its name.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

SIZES = ("maple", "100k")


def _n(x: float) -> str:
    """A time in ms with 3 significant figures, never in exponent form."""
    return f"{x:.0f}" if x >= 100 else f"{x:.1f}" if x >= 10 else f"{x:.2f}" if x >= 1 else f"{x:.3f}"


def _ms(v: dict) -> str:
    return f"{_n(v['median_ms'])} / {_n(v['p90_ms'])}"


def race_table(res: dict) -> str:
    rows = {s: {r["contender"]: r for r in res[s]["race"]} for s in SIZES}
    names = list(rows["maple"])
    head = (f"| contender | maple ({res['maple']['particles'] / 1e3:.1f} k particles, {res['maple']['springs'] / 1e3:.0f} k "
            f"springs): median / p90 ms | ratio | 100 k ({res['100k']['particles'] / 1e3:.0f} k, "
            f"{res['100k']['springs'] / 1e3:.0f} k): median / p90 ms | ratio | residual after (maple / 100 k) | "
            "Δq / spacing (maple / 100 k) |")
    out = [head, "|---|---|---|---|---|---|---|"]
    for n in names:
        a, b = rows["maple"][n], rows["100k"].get(n)
        if b is None:
            continue
        out.append(f"| {n} | {_ms(a)} | {a['ratio']:.2f} | {_ms(b)} | {b['ratio']:.2f} | {a['residual']:.3g} / {b['residual']:.3g} | "
                   f"{a['agree']:.1g} / {b['agree']:.1g} |")
    r0 = [res[s]["race"][0] for s in SIZES]
    out.append("")
    out.append(f"(residual before the passes {r0[0]['residual0']:.2g} / {r0[1]['residual0']:.2g}; 1-minute load "
               f"{r0[0]['load']:.1f} / {r0[1]['load']:.1f})")
    return "\n".join(out)


def frame_table(res: dict) -> str:
    f = {s: res[s]["frame"] for s in SIZES}
    ms = {s: f[s]["ms"] for s in SIZES}

    def row(label, fn):
        return f"| {label} | " + " | ".join(fn(s) for s in SIZES) + " |"

    out = ["| | maple | 100 k |", "|---|---|---|",
           row("frame, flat leaf at rest: median / p90 ms", lambda s: _ms(ms[s]["frame"])),
           row("frame, folded leaf in self-contact", lambda s: _ms(ms[s]["frame folded"])),
           row("10 passes: springs / hinges / volumes (ms)",
               lambda s: " / ".join(_n(ms[s][k]['median_ms']) for k in ("springs ×10", "hinges ×10", "volumes ×10"))),
           row("ns per spring / hinge / volume", lambda s: " / ".join(f"{f[s]['ns_per'][k]:.1f}" for k in ("spring", "hinge", "volume"))),
           row("hinge ÷ spring, volume ÷ spring", lambda s: f"{f[s]['hinge_vs_spring']:.2f}×, {f[s]['volume_vs_spring']:.2f}×"),
           row("the same, one constraint at a time (before)",
               lambda s: f"{f[s]['ns_per']['hinge, one at a time']:.1f} / {f[s]['ns_per']['volume, one at a time']:.1f} ns: "
                         f"{f[s]['hinge_vs_spring_one_at_a_time']:.2f}×, {f[s]['volume_vs_spring_one_at_a_time']:.2f}×"),
           row("self-collision share of a frame: flat / folded",
               lambda s: f"{100 * f[s]['contact_share']:.1f} % / {100 * f[s]['contact_share_folded']:.1f} %"),
           row("osmosis / shrink / colour step (ms)",
               lambda s: " / ".join(_n(ms[s][k]['median_ms']) for k in ("osmosis", "shrink", "colour step"))),
           row("memory per particle; peak RSS",
               lambda s: f"{res[s]['memory']['bytes_per_particle_total'] / 1e3:.1f} kB; {res[s]['memory']['peak_rss_mb']:.0f} MB"),
           "", f"(1-minute load {f['maple']['load']:.1f} / {f['100k']['load']:.1f})"]
    return "\n".join(out)


def parallel_table(res: dict) -> str:
    out = ["| kernel | maple, quiet | maple, 2 busy processes | 100 k, quiet | 100 k, 2 busy processes |",
           "|---|---|---|---|---|"]
    jobs = [r["job"] for r in res["maple"]["parallel"] if r["busy"] == 0]
    for j in jobs:
        cells = []
        for s in SIZES:
            for busy in (False, True):
                r = next(x for x in res[s]["parallel"] if x["job"] == j and bool(x["busy"]) == busy)
                cells.append(f"{r['p90_vs_serial']:.2f}")
        out.append(f"| {j} | " + " | ".join(cells) + " |")
    out.append("")
    out.append("(p90 ÷ the serial twin's p90; medians quiet: "
               + "; ".join(f"{s} " + ", ".join(f"{x['job']} {_n(x['median_ms'])} ms"
                                            for x in res[s]["parallel"] if x["busy"] == 0) for s in SIZES) + ")")
    return "\n".join(out)


def readme_table(res: dict) -> str:
    f = {s: res[s]["frame"] for s in SIZES}
    race = {s: {r["contender"]: r for r in res[s]["race"]} for s in SIZES}

    def race_cell(s):
        names = ["ours (f64, serial)", "ceiling (f32, serial)", "warp CPU", "taichi CPU"]
        return " / ".join(_n(race[s][n]['median_ms']) for n in names if n in race[s]) + " ms"

    def par(s):
        rows = {x["job"]: x for x in res[s]["parallel"] if x["busy"]}
        return (f"{rows['springs ×10: 2-block parallel']['p90_vs_serial']:.2f} / "
                f"{rows['shrink: parallel (prange)']['p90_vs_serial']:.2f}")

    def row(label, fn):
        return f"| {label} | " + " | ".join(fn(s) for s in SIZES) + " |"

    return "\n".join([
        f"| | maple ({res['maple']['particles'] / 1e3:.1f} k particles) | 100 k ({res['100k']['particles'] / 1e3:.0f} k particles) |",
        "|---|---|---|",
        row("10 spring passes: ours / f32 ceiling / warp CPU / Taichi CPU", race_cell),
        row("frame of 20 substeps × ≤ 2 iterations, flat / folded",
            lambda s: f"{_n(f[s]['ms']['frame']['median_ms'])} / {_n(f[s]['ms']['frame folded']['median_ms'])} ms"),
        row("hinge ÷ spring, volume ÷ spring (one at a time before)",
            lambda s: f"{f[s]['hinge_vs_spring']:.2f}× ({f[s]['hinge_vs_spring_one_at_a_time']:.1f}×), "
                      f"{f[s]['volume_vs_spring']:.2f}× ({f[s]['volume_vs_spring_one_at_a_time']:.1f}×)"),
        row("self-collision share, flat / folded",
            lambda s: f"{100 * f[s]['contact_share']:.1f} % / {100 * f[s]['contact_share_folded']:.1f} %"),
        row("osmosis / shrink / colour-only step",
            lambda s: " / ".join(_n(f[s]['ms'][k]['median_ms']) for k in ("osmosis", "shrink", "colour step")) + " ms"),
        row("parallel ÷ serial p90, 2 busy processes: 2-block springs / shrink", par),
    ])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bench_json", type=Path)
    ap.add_argument("--readme", action="store_true",
                    help="print only the summary table (docs/performance.md, section Summary)")
    a = ap.parse_args(argv)
    res = json.loads(a.bench_json.read_text())
    missing = [s for s in SIZES if s not in res] + [f"{s}: {k}" for s in SIZES if s in res
                                                     for k in ("race", "frame", "parallel", "memory") if k not in res[s]]
    if missing:
        print(f"bench_tables: {a.bench_json} lacks {', '.join(missing)} (needs a full `leafsim bench --json`, "
              "not --quick)", file=sys.stderr)
        return 2
    if a.readme:
        print(readme_table(res))
    else:
        print("## Spring race\n\n" + race_table(res) + "\n\n## Frame\n\n" + frame_table(res)
              + "\n\n## Parallel against serial\n\n" + parallel_table(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
