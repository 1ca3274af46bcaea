"""The sub-grid crinkle of a dried leaf (``render.crinkle``, :mod:`leafsim.sim.crinkle`):
pictures with and without it, and the lamina's excess length it draws.

    .venv/bin/python tools/crinkle_picture.py --species maple [--set mesh.spacing=0.0141]
        [--png docs/drying/maple_crinkle.png] [--cache DIR]

Dries the leaf on the ground by the drying report's protocol (to 2 % of its water, on to
1.15 × that time), then prints one JSON line: the blade's excess length Δ (area-weighted
mean and percentiles over the lamina, the share of the lamina with Δ > 0.5 %) and the RMS slope
√(2Δ) the renderer draws, in degrees (:func:`leafsim.sim.crinkle.crinkle_stats`).  With
``--png``: top-down, a close-up of the flank and an oblique view under a low sun, the crinkle
off (top row) and on (bottom row).  ``--cache DIR`` keeps the dried state (pickle) so a second
run only renders.
"""

from __future__ import annotations

import argparse
import json
import pickle
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

import drying_report as DR  # noqa: E402
from midrib_crease import _value  # noqa: E402

from leafsim.config.species import get_species  # noqa: E402
from leafsim.sim.crinkle import crinkle_stats  # noqa: E402

def dried(key: str, overrides: dict, cache: Path | None):
    """The drying report's dried leaf (:func:`drying_report.dried_state`), from ``cache`` when
    it holds one."""
    tag = "_".join([key] + [f"{k}={v}" for k, v in sorted(overrides.items())])
    hit = cache / f"{tag}.pkl" if cache is not None else None
    if hit is not None and hit.exists():
        model, st = pickle.loads(hit.read_bytes())
        sp = get_species(key)
        return sp, sp.params.with_overrides({**overrides, "dynamics.scene": "ground"}), model, st
    sp, p, model, st = DR.dried_state(key, overrides)
    if hit is not None:
        cache.mkdir(parents=True, exist_ok=True)
        hit.write_bytes(pickle.dumps((model, st)))
    return sp, p, model, st


def picture(sp, p, model, st, png: Path) -> None:
    from leafsim.appearance.photo import load_photo_rgba
    from leafsim.appearance.view import LeafView
    from leafsim.base.fileio import write_png_atomic
    from leafsim.render.offscreen import OffscreenRenderer, default_camera
    from leafsim.render.options import RenderOptions

    photo = load_photo_rgba(sp.image) if sp.image is not None else None
    view = LeafView(model, photo, photo_tint=False)
    opts = replace(RenderOptions(albedo="detail" if view.use_texture(p) else "colours"), light_dir=(0.9, -0.2, 0.35))
    r = OffscreenRenderer(560, 460)
    rows = []
    for gain in (0.0, float(p["render.crinkle"]) or 1.0):
        mesh = view.mesh(st, p.with_overrides({"render.crinkle": gain}))
        pts = DR._close_up_points(model, st.particle_q)
        cams = [default_camera(mesh.positions, pitch=89.0, yaw=-90.0),
                default_camera(pts, pitch=35.0, yaw=-30.0, aspect=560 / 460),
                default_camera(mesh.positions, pitch=25.0, yaw=-60.0, aspect=560 / 460)]
        rows.append(np.hstack([r.render_array(mesh, camera=c, options=opts) for c in cams]))
    r.release()
    write_png_atomic(png, np.vstack(rows), rgb=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--species", default="maple")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--png")
    ap.add_argument("--cache")
    a = ap.parse_args()
    overrides = {k: _value(v) for k, v in (s.split("=", 1) for s in a.set)}
    sp, p, model, st = dried(a.species, overrides, Path(a.cache) if a.cache else None)
    print(json.dumps({"species": a.species, "set": a.set, "particles": int(model.particle_count), **crinkle_stats(model, st)}))
    if a.png:
        picture(sp, p, model, st, Path(a.png))


if __name__ == "__main__":
    main()
