"""Dry every built-in species to the end, on the ground (g = 9.81) and free, and report
margin lift and 3D area kept; saves a top/side picture per species into docs/drying/.

    .venv/bin/python scripts/curl_report.py [--frames N] [--species a,b] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from leafsim.session import Session  # noqa: E402
from leafsim.sim.run import shape_metrics  # noqa: E402
from leafsim.species import load_library  # noqa: E402


def dry(key: str, scene: str, max_frames: int, snap_dir: Path | None):
    s = Session(key, seed=0, overrides={"dynamics.scene": scene}, build=True)
    t0 = time.perf_counter()
    frames = 0
    while frames < max_frames and s.water_fraction() > 0.02:
        s.step(50)
        frames += 50
    secs = time.perf_counter() - t0
    m = shape_metrics(s.model, s.state, own_frame=(scene == "free"))
    out = {"species": key, "scene": scene, "frames": frames, "seconds": round(secs, 1),
           "water_left": round(s.water_fraction(), 4), "margin_lift": round(m["margin_lift"], 4),
           "area_ratio": round(m["area_ratio"], 4), "inverted": int(m["inverted"]),
           "particles": s.model.particle_count}
    if snap_dir is not None:
        from leafsim.fileio import write_png_atomic
        from leafsim.render.camera import OrbitCamera
        from leafsim.render.offscreen import OffscreenRenderer, default_camera

        from leafsim.render.options import RenderOptions

        s.photo_tint = False  # photo species: pigment colour with the photo's detail, as in the GUI
        opts = RenderOptions(albedo="detail" if s.use_texture() else "colours")
        r = OffscreenRenderer(480, 400)
        mesh = s.render_mesh()
        imgs = []
        for pitch, yaw in ((89.0, -90.0), (8.0, -90.0), (8.0, 0.0)):
            cam = default_camera(mesh.positions, pitch=pitch, yaw=yaw)
            imgs.append(r.render_array(mesh, camera=cam, options=opts))
        r.release()
        write_png_atomic(snap_dir / f"{key}_{scene}.png", np.hstack(imgs), rgb=True)
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=6000)
    ap.add_argument("--species", default=None)
    ap.add_argument("--scenes", default="ground,free")
    ap.add_argument("--json", default=None)
    ap.add_argument("--no-pictures", action="store_true")
    a = ap.parse_args()
    keys = a.species.split(",") if a.species else list(load_library())
    snap = None if a.no_pictures else ROOT / "docs" / "drying"
    if snap:
        snap.mkdir(parents=True, exist_ok=True)
    rows = []
    print(f"{'species':16s} {'scene':7s} {'frames':>6s} {'water':>6s} {'lift/L':>7s} {'area':>6s} {'inv':>4s} {'s':>6s}")
    for k in keys:
        for sc in a.scenes.split(","):
            r = dry(k, sc, a.frames, snap)
            rows.append(r)
            print(f"{k:16s} {sc:7s} {r['frames']:6d} {r['water_left']:6.3f} {r['margin_lift']:7.3f} {r['area_ratio']:6.3f} {r['inverted']:4d} {r['seconds']:6.1f}", flush=True)
    if a.json:
        old = {}
        if Path(a.json).is_file():  # keep the rows of species not rerun
            old = {(r["species"], r["scene"]): r for r in json.loads(Path(a.json).read_text())}
        old.update({(r["species"], r["scene"]): r for r in rows})
        Path(a.json).write_text(json.dumps(list(old.values()), indent=1))


if __name__ == "__main__":
    main()
