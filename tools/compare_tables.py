"""The markdown tables of docs/compare/README.md from the saved `leafsim compare --json` outputs
(docs/compare/KEY.json), so the docs quote exactly what the command measured. The last table
printed is the summary (docs/compare/README.md, section "Summary"; the top-level README quoted
it until 6 December); the others go under its "Numbers".

    .venv/bin/python tools/compare_tables.py [docs/compare]
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
ORDER = ("grapevine", "oak", "aspen", "aspen_senescent", "hornbeam")


def _stage(r) -> str:
    s = r["stage"]
    if r["kind"] == "young":
        return f"{s['frame']}, {100 * s['water']:.1f} %"
    if "grown_back" in r:  # the note's first pass, then the grown-back run's match
        return f"{s['frame']}, {100 * s['water']:.1f} % (grown back × {r['grown_back']:.3f})"
    return f"{s['frame']}, {100 * s['water']:.1f} % ({r['note'].replace(' stages every 50 frames', '')})"


def _pct(x) -> str:
    """A share as a percentage (— where the run did not measure it)."""
    return "—" if x is None else f"{100 * x:.1f} %"


def _row_name(key, r) -> str:
    return r["kind"] + (" (another leaf)" if r["kind"] == "senescent" and key == "aspen" else "")


def render(folder: Path) -> str:
    reps = {k: json.loads((folder / f"{k}.json").read_text()) for k in ORDER if (folder / f"{k}.json").is_file()}
    out = ["| species | row | reference photo | matched stage: frame, water left | IoU | margin ratio (model/photo) | "
           "colour TV | mean ΔE | lightness TV | hue TV | veins precision (chance) | veins recall (chance) | time in the command |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for k, rep in reps.items():
        for r in rep["rows"]:
            v = r["veins"]
            out.append(f"| {k} | {_row_name(k, r)} | {Path(r['reference']).name} | {_stage(r)} | {r['iou']:.4f} | "
                       f"{r['margin_ratio']:.4f} | {r['colour_tv']:.4f} | {r['mean_delta_e']:.2f} | {r['lightness_tv']:.4f} | "
                       f"{r['hue_tv']:.4f} | {v['precision']:.3f} ({v['chance_precision']:.3f}) | "
                       f"{v['recall']:.3f} ({v['chance_recall']:.3f}) | {rep['seconds']:.1f} s |")
    out += ["", "| species | photo | model |", "|---|---|---|"]
    for k, rep in reps.items():
        for r in rep["rows"]:
            if r["kind"] != "senescent":
                continue
            mix = [", ".join(f"{c} {f:.3f}" for c, f in sorted(d.items(), key=lambda x: -x[1]) if f >= 0.005)
                   for d in (r["colour_photo"], r["colour_model"])]
            out.append(f"| {k}{' (other leaf)' if k == 'aspen' else ''} | {mix[0]} | {mix[1]} |")
    out += ["", "| species | senescent window: stages | median TV | p90 TV | worst TV | share ≤ 0.35 | dried stage TV |",
            "|---|---|---|---|---|---|---|"]
    for k, rep in reps.items():
        for r in rep["rows"]:
            w = r.get("senescent_window")
            if w and w.get("stages"):
                out.append(f"| {k}{' (other leaf)' if k == 'aspen' else ''} | {w['stages']} | {w['median_tv']:.3f} | {w['p90_tv']:.3f} | "
                           f"{w['max_tv']:.3f} | {w['share_tv_le_0.35']:.2f} | {w['dried_tv']:.3f} |")
    out += ["", "| species | row | hue spread photo / model (°) | L* spread photo / model | ratio hue / L* | dark spots photo / model | dark share of the blade photo / model |",
            "|---|---|---|---|---|---|---|"]
    for k, rep in reps.items():
        for r in rep["rows"]:
            sp, sm, q = r.get("spread_photo"), r.get("spread_model"), r.get("spread_ratio")
            if sp and sm:
                out.append(f"| {k} | {_row_name(k, r)} | {sp['hue_sd_deg']} / {sm['hue_sd_deg']} | {sp['lightness_sd']} / "
                           f"{sm['lightness_sd']} | {q['hue']} / {q['lightness']} | {sp['spots']} / {sm['spots']} | "
                           f"{_pct(sp.get('dark_share'))} / {_pct(sm.get('dark_share'))} |")
    out += ["", "| species | vein offset along the photo's traced veins: mean px (× L) | p90 px (× L) | midrib mean px (× L) |",
            "|---|---|---|---|"]
    for k, rep in reps.items():
        o = rep["rows"][0].get("vein_offset")
        if o:
            out.append(f"| {k} | {o['mean_px']} ({o['mean_L']}) | {o['p90_px']} ({o['p90_L']}) | {o['midrib_mean_px']} ({o['midrib_mean_L']}) |")
    out += ["", "| species | row | matched stage | IoU | margin ratio | colour TV | mean ΔE |", "|---|---|---|---|---|---|---|"]
    for k, rep in reps.items():
        for r in rep["rows"]:
            if k == "aspen" and r["kind"] == "senescent" or r["kind"] == "young" and k in ("aspen_senescent", "hornbeam"):
                continue
            st = "—" if r["kind"] == "young" else f"frame {r['stage']['frame']}, {100 * r['stage']['water']:.0f} % water" + (
                f", grown back × {r['grown_back']:.3f}" if "grown_back" in r else "")
            out.append(f"| {k} | {r['kind']} | {st} | {r['iou']:.4f} | {r['margin_ratio']:.3f} | {r['colour_tv']:.3f} | "
                       f"{r['mean_delta_e']:.1f} |")
    return "\n".join(out)


if __name__ == "__main__":
    print(render(Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "docs" / "compare"))
