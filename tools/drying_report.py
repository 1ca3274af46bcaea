"""Dry every built-in species to the end, on the ground (g = 9.81) and free, with the default
physics; report margin lift, 3D and top-down area kept (resolution-independent probe metrics)
and save a top/side picture per species into docs/drying/.

    .venv/bin/python tools/drying_report.py [--species a,b] [--scenes ground,free] [--json FILE]
        [--set KEY=VALUE ...] [--pictures DIR]
    .venv/bin/python tools/drying_report.py --render docs/drying/curl.json   # the tables of docs/drying/README.md

Each leaf dries until less than 2 % of its water is left, then settles to 1.15 × that time, so
"frames" ("frames to dry") counts to the end of the settling: maple 3063, where
`leafsim run --until dry` and the GUI's "Dry to end" stop at 2 % water (frame 2663).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent

from leafsim.appearance.photo import load_photo_rgba
from leafsim.config.species import get_species, load_library
from leafsim.pipeline import build_leaf
from leafsim.sim.metrics import Probe
from leafsim.sim.run import Run
from leafsim.sim.crinkle import crinkle_stats
from leafsim.sim.curl import dried_shape
from leafsim.sim.shape import leaf_frame, shape_metrics
from leafsim.sim.veinframe import vein_frame_curl

#: dry below this water fraction, then settle this much longer
DRY, SETTLE = 0.02, 1.15


def dried_state(key: str, overrides: dict | None = None, max_time: float = 60.0):
    """(species, params, model, state) of ``key`` dried on the ground by this report's protocol
    (to 2 % of its water, on to 1.15 × that time, at most ``max_time`` simulated seconds), seed 0:
    what the picture tools (pleats, crinkle) draw."""
    sp = get_species(key)
    p = sp.params.with_overrides({**(overrides or {}), "dynamics.scene": "ground"})
    _, _, model = build_leaf(sp, p, 0)
    run = Run(model, p, seed=0, name=key)
    t_dry = None

    def done(st) -> bool:
        nonlocal t_dry
        if t_dry is None and model.water_fraction(st.particle_water) < DRY:
            t_dry = st.time
        return (t_dry is not None and st.time >= SETTLE * t_dry) or st.time >= max_time

    for _ in run.frames(until=done):
        pass
    return sp, p, model, run.state


def dry(key: str, scene: str, max_time: float, snap_dir: Path | None, overrides: dict | None = None,
        seed: int = 0) -> dict:
    sp = get_species(key)
    p = sp.params.with_overrides({**(overrides or {}), "dynamics.scene": scene})
    shape, _, model = build_leaf(sp, p, seed)
    run = Run(model, p, seed=seed, name=key)
    st = run.state
    t0, t_dry = time.perf_counter(), None

    def settled(st) -> bool:
        nonlocal t_dry
        if t_dry is None and model.water_fraction(st.particle_water) < DRY:
            t_dry = st.time
        return t_dry is not None and st.time >= SETTLE * t_dry

    for _ in run.frames(until=lambda st: settled(st) or st.time >= max_time):
        pass
    secs = time.perf_counter() - t0
    if scene == "free":  # measure the shape in the leaf's own frame, lying as at rest
        st.particle_q[:] = leaf_frame(model, st)
        st.particle_q[:, 2] -= st.particle_q[model.particle_layer == 0, 2].min()
    f = Probe(shape).fields(model, st)
    out = {"species": key, "scene": scene, **({"seed": seed} if seed else {}), "frames": st.frame, "seconds": round(secs, 1),
           "time_to_dry": None if t_dry is None else round(t_dry, 3), "water_left": round(f["water"], 4),
           "margin_lift": round(f["margin_lift"], 4), "area_3d": round(f["area_3d"], 4),
           "area_top": round(f["area_top"], 4), "inverted": shape_metrics(model, st)["inverted"],
           "vein_frame_curl": round(vein_frame_curl(model, st.particle_q), 4),
           **dried_shape(model, st),  # margin roll, midrib fold, wrinkles (leafsim.sim.curl)
           **crinkle_stats(model, st),  # the lamina's excess length, the sub-grid crinkle (leafsim.sim.crinkle)
           "particles": model.particle_count, "fresh_mass_g": round(1e3 * float(model.particle_mass0.sum()), 3)}
    if snap_dir is not None:
        _pictures(sp, p, model, st, snap_dir / f"{key}_{scene}{f'_s{seed}' if seed else ''}.png")
    return out


def _close_up_points(model, q: np.ndarray) -> np.ndarray:
    """Where the close-up looks: the blade (layer T) within 0.3 L, in the rest shape, of its
    widest margin point on the right (a lobe or the flank), at the current positions."""
    T = model.blade_T
    rest = model.particle_rest[:, :2]
    L = float(np.ptp(model.particle_rest[T, 1]))
    right = np.flatnonzero(T)[np.argmax(rest[T, 0])]
    near = T & (np.linalg.norm(rest - rest[right], axis=1) < 0.3 * L)
    return q[near]


def _pictures(sp, p, model, st, path: Path) -> None:
    """Top-down, end-on and side views and an oblique close-up of the right flank's margin,
    side by side (the GUI's look: photo detail where there is one)."""
    from leafsim.appearance.view import LeafView
    from leafsim.base.fileio import write_png_atomic
    from leafsim.render.offscreen import OffscreenRenderer, default_camera
    from leafsim.render.options import RenderOptions

    photo = load_photo_rgba(sp.image) if sp.image is not None else None
    view = LeafView(model, photo, photo_tint=False)
    opts = RenderOptions(albedo="detail" if view.use_texture(p) else "colours")
    r = OffscreenRenderer(480, 400)
    mesh = view.mesh(st, p)
    imgs = [r.render_array(mesh, camera=default_camera(mesh.positions, pitch=pitch, yaw=yaw), options=opts)
            for pitch, yaw in ((89.0, -90.0), (8.0, -90.0), (8.0, 0.0))]
    close = default_camera(_close_up_points(model, st.particle_q), pitch=30.0, yaw=-30.0, aspect=480 / 400)
    imgs.append(r.render_array(mesh, camera=close, options=opts))
    r.release()
    write_png_atomic(path, np.hstack(imgs), rgb=True)


def _pct(x) -> str:
    return f"{100 * x:.1f} %"


def render(rows: list) -> str:
    """The markdown tables made from a report, all in docs/drying/README.md: the summary (ground,
    with the free lift; its section "Summary", which the top-level README quoted until
    6 December), every measure in both scenes, and the dried shape's measures; plus the ranges
    the text quotes."""
    rows = [r for r in rows if not r.get("seed")]  # the tables are the seed-0 leaves'
    by = {(r["species"], r["scene"]): r for r in rows}
    keys = list(dict.fromkeys(r["species"] for r in rows))
    out = ["| species | top-down area kept (ground) | 3D area kept (ground) | margin lift / L, ground | "
           "margin lift / L, free | frames to dry | inverted |", "|---|---|---|---|---|---|---|"]
    for k in keys:
        g, f = by[(k, "ground")], by.get((k, "free"))
        out.append(f"| {k} | {_pct(g['area_top'])} | {_pct(g['area_3d'])} | {_pct(g['margin_lift'])} | "
                   f"{_pct(f['margin_lift']) if f else '—'} | {g['frames']} | {g['inverted']} |")
    out += ["", "| species | particles | fresh mass | frames | time to dry (s) | ground: top-down area kept | ground: 3D "
            "area kept | ground: margin lift / L | ground: vein-frame curl | free: top-down | free: 3D | free: margin lift / L | "
            "inverted (ground/free) | compute s (ground/free) |", "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for k in keys:
        g, f = by[(k, "ground")], by.get((k, "free")) or {}
        out.append(f"| {k} | {g['particles']} | {g.get('fresh_mass_g', float('nan')):.2f} g | {g['frames']} | "
                   f"{g['time_to_dry']:.2f} | {_pct(g['area_top'])} | {_pct(g['area_3d'])} | {_pct(g['margin_lift'])} | "
                   + (f"{g['vein_frame_curl']:+.3f} | " if "vein_frame_curl" in g else "— | ")
                   + (f"{_pct(f['area_top'])} | {_pct(f['area_3d'])} | {_pct(f['margin_lift'])} | " if f else "— | — | — | ")
                   + f"{g['inverted']}/{f.get('inverted', '—')} | {g['seconds']:.0f}/{f.get('seconds', float('nan')):.0f} |")
    if any("midrib_fold_deg" in by[(k, "ground")] for k in keys):  # reports made since leafsim.sim.curl
        out += ["", "| species | margin roll (mean / p90) | midrib fold | wrinkle RMS / L | wrinkle wavelength / L | "
                "lamina excess length: mean (p50 / p90) | crinkle RMS slope | one way |", "|---|---|---|---|---|---|---|---|"]
        for k in keys:
            g = by[(k, "ground")]
            if "midrib_fold_deg" in g:
                wl = g["wrinkle_wavelength_L"]
                ex = g.get("crinkle_excess_p10_p50_p90_p99_pct")
                crinkle = (f"{g['crinkle_excess_pct']:.2f} % ({ex[1]:.2f} / {ex[2]:.2f} %) | {g['crinkle_slope_rms_deg']:.1f}°"
                           if ex else "— | —")
                crinkle += f" | {g['crinkle_one_way_share']:.2f}" if "crinkle_one_way_share" in g else " | —"
                out.append(f"| {k} | {g['margin_roll_deg']:.0f}° / {g['margin_roll_p90_deg']:.0f}° | {g['midrib_fold_deg']:.0f}° | "
                           f"{g['wrinkle_rms_L']:.4f} | {'smooth' if wl is None else f'{wl:.3f}'} | {crinkle} |")
    ground = [by[(k, "ground")] for k in keys]
    for m in ("area_top", "area_3d", "margin_lift"):
        lo, hi = min(ground, key=lambda r: r[m]), max(ground, key=lambda r: r[m])
        out.append(f"\n{m} (ground): {_pct(lo[m])} ({lo['species']}) … {_pct(hi[m])} ({hi['species']})")
    out.append(f"\nsimulation seconds in all: {sum(r['seconds'] for r in rows):.0f}")
    return "\n".join(out)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--render", default=None, metavar="JSON", help="print the markdown tables of a report and stop")
    ap.add_argument("--max-time", type=float, default=30.0, help="simulated seconds at most")
    ap.add_argument("--species", default=None)
    ap.add_argument("--scenes", default="ground,free")
    ap.add_argument("--json", default=None)
    ap.add_argument("--no-pictures", action="store_true")
    ap.add_argument("--pictures", default=str(ROOT / "docs" / "drying"), metavar="DIR",
                    help="where the pictures go (default docs/drying)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="a parameter over every species' own (experiments; repeatable)")
    ap.add_argument("--seed", type=int, default=0, help="the leaf's seed (outline, veins, patches); pictures of "
                    "another seed than 0 are named KEY_SCENE_sN.png and its rows carry a 'seed' field (--render "
                    "tabulates seed 0 only)")
    a = ap.parse_args()
    if a.render:
        print(render(json.loads(Path(a.render).read_text())))
        return
    keys = a.species.split(",") if a.species else list(load_library())
    snap = None if a.no_pictures else Path(a.pictures)
    overrides = {}
    for kv in a.set:
        k, _, v = kv.partition("=")
        try:
            overrides[k] = json.loads(v)
        except ValueError:  # a choice such as free, a bare word: the text itself
            overrides[k] = v
    if snap:
        snap.mkdir(parents=True, exist_ok=True)
    rows = []
    print(f"{'species':16s} {'scene':7s} {'frames':>6s} {'t_dry':>6s} {'lift/L':>7s} {'3D':>6s} {'top':>6s} {'inv':>4s} {'s':>6s}")
    for k in keys:
        for sc in a.scenes.split(","):
            r = dry(k, sc, a.max_time, snap, overrides, a.seed)
            rows.append(r)
            print(f"{k:16s} {sc:7s} {r['frames']:6d} {r['time_to_dry'] or float('nan'):6.2f} {r['margin_lift']:7.3f} "
                  f"{r['area_3d']:6.3f} {r['area_top']:6.3f} {r['inverted']:4d} {r['seconds']:6.1f}", flush=True)
    if a.json:
        old = {}
        if Path(a.json).is_file():  # keep the rows of species not rerun
            old = {(r["species"], r["scene"], r.get("seed", 0)): r for r in json.loads(Path(a.json).read_text())}
        old.update({(r["species"], r["scene"], r.get("seed", 0)): r for r in rows})
        Path(a.json).write_text(json.dumps(list(old.values()), indent=1))


if __name__ == "__main__":
    main()
