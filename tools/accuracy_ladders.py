"""Is the reference converged?  The measurements behind docs/accuracy.md's "Convergence of
the reference" section: the sensitivity floor (the default dried again from perturbed
starts) and substep ladders (successive differences as Δt/substeps halves), for each species.

    .venv/bin/python tools/accuracy_ladders.py [--species maple,grapevine] [--substeps 20,40,80,160]
        [--floor 2] [--set KEY=VALUE ...] [--tag NAME] [--out docs/accuracy]
    .venv/bin/python tools/accuracy_ladders.py --key dynamics.precision --values float32,float64 --tag precision
    .venv/bin/python tools/accuracy_ladders.py --render docs/accuracy/ladders.json

Each run is recorded in ``<out>/ladders.json`` (appended under its tag, so ablations such as
``--set dynamics.friction=0 --tag friction0`` sit beside the defaults); ``--render`` prints the
markdown tables of everything recorded.  Runs are single-threaded: two can share 2 cores.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

from leafsim.config.params import PARAMS, parse_set_args
from leafsim.measure.accuracy import METRIC_NAMES, METRICS, floor_study, ladder_study

SHOWN = ("position", "height", "margin_lift", "area_3d", "area_top")


def render(db: dict) -> str:
    out = []
    for tag, per in db.items():
        for sp, rec in per.items():
            if "ladder" in rec:
                lad = rec["ladder"]
                ov = ", ".join(f"{k} = {v}" for k, v in lad["overrides"].items()) or "defaults"
                out += [f"**{sp}, {tag}** ({ov}; {lad['frames']} frames, {lad.get('seconds', 0):.0f} s):", "",
                        f"| {lad['key'].split('.')[-1].replace('_', ' ')} | margin lift / L | 3D area | top-down area | ms/frame | step to next: "
                        + " | ".join(METRIC_NAMES[m] for m in SHOWN) + " |",
                        "|---|---|---|---|---|" + "---|" * len(SHOWN)]
                for r in lad["rows"]:
                    st = r.get("step")
                    cells = " | ".join(f"{100 * st[m]:.1f} %" for m in SHOWN) if st else " | ".join("—" for _ in SHOWN)
                    out.append(f"| {r['value']} | {r['margin_lift']:.3f} | {r['area_3d']:.3f} | {r['area_top']:.3f} | "
                               f"{r['ms_frame']:.3g} | {cells} |")
                out.append("")
            if "floor" in rec:
                f = rec["floor"]
                worst = max(f[m]["max"] for m in METRICS if m != "area_top")
                out += [f"**{sp}, {tag}: sensitivity floor** — {f['runs']} runs from starts perturbed by "
                        f"{1e6 * f['amplitude_m']:.3g} µm: largest relative difference {worst:.2g} on the fields and "
                        f"scalars, {100 * f['area_top']['max']:.3f} % on the top-down area (its raster).", ""]
    return "\n".join(out)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--species", default="maple,grapevine")
    ap.add_argument("--substeps", default="20,40,80,160", help="the values of --key (kept under this name)")
    ap.add_argument("--key", default="dynamics.substeps", help="the setting the ladder walks (coarse to fine)")
    ap.add_argument("--values", default=None, help="its values, coarse to fine (default: --substeps)")
    ap.add_argument("--floor", type=int, default=0, help="perturbed runs for the sensitivity floor (0: none)")
    ap.add_argument("--amplitude", type=float, default=1e-4, help="start perturbation [m]")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--tag", default="defaults")
    ap.add_argument("--out", default=str(ROOT / "docs" / "accuracy"))
    ap.add_argument("--render", default=None, metavar="JSON")
    a = ap.parse_args()
    if a.render:
        print(render(json.loads(Path(a.render).read_text())))
        return
    path = Path(a.out) / "ladders.json"
    ov = parse_set_args(a.set)
    for sp in a.species.split(","):
        rec = {}
        values = a.values or a.substeps
        if values:
            kind = PARAMS[a.key].kind
            cast = int if kind == "int" else float if kind == "float" else str
            t0 = time.time()
            rec["ladder"] = ladder_study(sp, a.key, [cast(v) for v in values.split(",")], ov)
            rec["ladder"]["seconds"] = round(time.time() - t0, 1)
        if a.floor:
            rec["floor"] = floor_study(sp, a.floor, ov, amplitude=a.amplitude)
        db = json.loads(path.read_text()) if path.exists() else {}  # re-read: another run may have written
        db.setdefault(a.tag, {}).setdefault(sp, {}).update(rec)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(db, indent=1) + "\n")
        tmp.replace(path)
        print(render({a.tag: {sp: rec}}), flush=True)


if __name__ == "__main__":
    main()
