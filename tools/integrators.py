"""XPBD and Sun et al.'s explicit integrator side by side (docs/drying/integrators.md).

    python tools/integrators.py run SPECIES TAG   # one accuracy-protocol dry → /tmp/leafsim-integrators/SPECIES-TAG.pkl
    python tools/integrators.py table SPECIES...  # the table of every pickled run
    python tools/integrators.py pictures SPECIES OUT.png

TAG is one of :data:`SETTINGS`: every run is on the draft quality's mesh (0.028 L; Sun's
integrator costs too much on the finer ones), dries to 2 % water and on to 1.15 × that time
(the accuracy study's protocol), colour off.  ``converged`` is XPBD iterated far past the
default (160 substeps × ≤ 10 iterations to 1e-9 L): the equilibrium both solvers aim at.
"""

from __future__ import annotations

import json
import pickle
import sys
import time
from pathlib import Path

import numpy as np

from leafsim.config.presets import QUALITY
from leafsim.config.species import get_species
from leafsim.measure.accuracy import DRY_WATER, SETTLE
from leafsim.pipeline import build_leaf, leaf_shape
from leafsim.sim.metrics import Probe, field_errors
from leafsim.sim.simulator import Simulator

OUT = Path("/tmp/leafsim-integrators")
SETTINGS = {
    "balanced": {"quality": "balanced"},
    "converged": {"quality": "balanced", "dynamics.substeps": 160, "dynamics.iterations": 10, "dynamics.tolerance": 1e-9},
    "sun": {"quality": "draft", "dynamics.integrator": "sun"},
    "sun-turgor": {"quality": "draft", "dynamics.integrator": "sun", "material.turgor_pressure": 6e5},
}


def _params(species: str, tag: str):
    sp = get_species(species)
    base = sp.params.with_overrides({"effects.colour": False})
    over = dict(SETTINGS[tag])
    o = {"dynamics.path": "own", **QUALITY[over.pop("quality")], **over}
    return sp, base, base.with_overrides(o)


def run(species: str, tag: str) -> None:
    sp, base, p = _params(species, tag)
    m = build_leaf(sp, p, 0).model
    probe = Probe(leaf_shape(sp, base))
    sim = Simulator(m, p, seed=0)
    st = sim.state()
    w0 = float(m.particle_water0.sum())
    t0 = time.process_time()
    steps, n = [], 0
    while m.water_fraction(st.particle_water) > DRY_WATER:
        sim.step(st)
        n += 1
        steps.append(sim.iterations)
        if n % 250 == 0:
            print(n, "water", round(m.water_fraction(st.particle_water), 3), "steps", sim.iterations, "cpu",
                  round(time.process_time() - t0), flush=True)
    cpu_dry = time.process_time() - t0
    for _ in range(int(np.ceil(SETTLE * n)) - n):
        sim.step(st)
        steps.append(sim.iterations)
    cpu = time.process_time() - t0
    end = probe.fields(m, st)
    OUT.mkdir(exist_ok=True)
    with open(OUT / f"{species}-{tag}.pkl", "wb") as f:
        pickle.dump({"end": end, "cpu": cpu, "cpu_dry": cpu_dry, "n": n, "steps": steps, "particles": m.particle_count,
                     "q": st.particle_q.copy(), "water": st.particle_water.copy()}, f)
    print(f"{species}-{tag}: {m.particle_count} particles, {n} frames, cpu {cpu_dry:.0f} / {cpu:.0f} s")


def _load(species: str, tag: str):
    path = OUT / f"{species}-{tag}.pkl"
    return pickle.loads(path.read_bytes()) if path.exists() else None


def table(species_list) -> None:
    print("| species | run | CPU s to 2 % / end | Sun steps or XPBD iterations per frame (median / max) | margin lift / L | "
          "3D area | top-down area | against converged: position / height RMS (L) |")
    print("|---|---|---|---|---|---|---|---|")
    for s in species_list:
        ref = _load(s, "converged")
        L = Probe(leaf_shape(get_species(s), get_species(s).params)).length
        for tag in SETTINGS:
            r = _load(s, tag)
            if r is None:
                continue
            e = r["end"]
            against = "—"
            if ref is not None and tag != "converged":
                err = field_errors(e, ref["end"], L)
                against = f"{err['position_rms']:.4f} / {err['height_rms']:.4f}"
            print(f"| {s} | {tag} | {r['cpu_dry']:.0f} / {r['cpu']:.0f} | {np.median(r['steps']):.0f} / {max(r['steps'])} | "
                  f"{e['margin_lift']:.3f} | {100 * e['area_3d']:.1f} % | {100 * e['area_top']:.1f} % | {against} |")


def pictures(species: str, out: str) -> None:
    """Top-down and side views of each pickled run, one row per run (balanced, converged, sun)."""
    from leafsim.appearance.view import LeafView
    from leafsim.base.fileio import write_png_atomic
    from leafsim.render.offscreen import OffscreenRenderer, default_camera
    from leafsim.render.options import RenderOptions

    import cv2

    rows = []
    r = OffscreenRenderer(400, 320)
    for tag in SETTINGS:
        res = _load(species, tag)
        if res is None:
            continue
        sp, _, p = _params(species, tag)
        m = build_leaf(sp, p, 0).model
        st = m.state()
        st.particle_q[:] = res["q"]
        st.particle_water[:] = res["water"]
        view = LeafView(m, None, photo_tint=False)
        mesh = view.mesh(st, p)
        imgs = [r.render_array(mesh, camera=default_camera(mesh.positions, pitch=pitch, yaw=yaw),
                               options=RenderOptions(albedo="colours"))
                for pitch, yaw in ((89.0, -90.0), (8.0, -90.0), (8.0, 0.0))]
        row = np.hstack(imgs)
        cv2.putText(row, tag, (8, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (0, 0, 0), 2, cv2.LINE_AA)
        rows.append(row)
    r.release()
    write_png_atomic(Path(out), np.vstack(rows), rgb=True)


if __name__ == "__main__":
    cmd = sys.argv[1]
    if cmd == "run":
        run(sys.argv[2], sys.argv[3])
    elif cmd == "table":
        table(sys.argv[2:])
    elif cmd == "pictures":
        pictures(sys.argv[2], sys.argv[3])
    else:
        sys.exit(f"unknown command {cmd!r}: expected run, table or pictures; settings {json.dumps(list(SETTINGS))}")
