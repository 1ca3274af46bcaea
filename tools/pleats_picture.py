"""Close-ups of a dried leaf with and without its pleats (``shrink.plication``), side by side,
under a low sun, so the valleys along the laterals show (docs/drying/README.md, "Pleats").

    .venv/bin/python tools/pleats_picture.py [--species hornbeam] [--depth D] [--out docs/drying/hornbeam_pleats.png]

Each leaf dries on the ground by the drying report's protocol (tools/drying_report.py: below 2 %
of its water, then 1.15 × that time); drawn in the model's own colours (not the photo's painted veins) under a
low sun from the side; the top row looks down from 35°, the bottom row from 12°, the left column without pleats, the right with them.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tools"))

import drying_report as DR  # noqa: E402

from leafsim.appearance.photo import load_photo_rgba  # noqa: E402
from leafsim.appearance.view import LeafView  # noqa: E402
from leafsim.base.fileio import write_png_atomic  # noqa: E402
from leafsim.config.species import get_species  # noqa: E402
from leafsim.render.offscreen import OffscreenRenderer, default_camera  # noqa: E402
from leafsim.render.options import RenderOptions  # noqa: E402


def dried(key: str, depth: float):
    return DR.dried_state(key, {"shrink.plication": depth})


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--species", default="hornbeam")
    ap.add_argument("--depth", type=float, default=None, help="shrink.plication (default: the species' own)")
    ap.add_argument("--out", default=str(ROOT / "docs" / "drying" / "hornbeam_pleats.png"))
    a = ap.parse_args()
    r = OffscreenRenderer(640, 420)
    cols = []
    asked = a.depth if a.depth is not None else get_species(a.species).params["shrink.plication"]
    for depth in (0.0, asked):
        sp, p, model, st = dried(a.species, depth)
        photo = load_photo_rgba(sp.image) if sp.image is not None else None
        view = LeafView(model, photo, photo_tint=False)
        # the model's own colours, not the photo's painted veins, and a low sun from the side:
        # what shades the blade is its shape
        opts = replace(RenderOptions(albedo="colours"), light_dir=(0.9, -0.2, 0.35))
        mesh = view.mesh(st, p)
        pts = DR._close_up_points(model, st.particle_q)
        shots = [r.render_array(mesh, camera=default_camera(pts, pitch=pitch, yaw=yaw, aspect=640 / 420), options=opts)
                 for pitch, yaw in ((35.0, -30.0), (12.0, -60.0))]
        cols.append(np.vstack(shots))
    r.release()
    write_png_atomic(Path(a.out), np.hstack(cols), rgb=True)
    print(a.out)


if __name__ == "__main__":
    main()
