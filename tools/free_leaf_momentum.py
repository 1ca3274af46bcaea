"""A free maple without gravity, dried for 6000 frames: angular momentum, kinetic energy (rigid
and internal) and spin every 500 frames (internal forces must neither spin nor move it).

    .venv/bin/python tools/free_leaf_momentum.py [--species maple] [--frames 6000]
"""

from __future__ import annotations

import argparse

import numpy as np

from leafsim.config.species import get_species
from leafsim.pipeline import build_leaf
from leafsim.sim.run import Run
from leafsim.sim.watchdog import momenta


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--species", default="maple")
    ap.add_argument("--frames", type=int, default=6000)
    a = ap.parse_args()
    sp = get_species(a.species)
    p = sp.params.with_overrides({"dynamics.scene": "free", "dynamics.gravity": 0.0, "effects.colour": False})
    _, _, m = build_leaf(sp, p, 0)
    run = Run(m, p)
    st = run.state
    print("| frame | water | |L| [kg·m²/s] | spin [°/s] | KE rigid [J] | KE internal [J] | max internal speed [m/s] |")
    print("|---|---|---|---|---|---|---|")
    for k in range(1, a.frames + 1):
        run.step()
        if k in (1, 10, 100) or k % 500 == 0:
            mom = momenta(m.particle_cytosol + st.particle_water, st.particle_q, st.particle_qd)
            print(f"| {k} | {st.particle_water.sum() / m.particle_water0.sum():.3f} | {np.linalg.norm(mom['angular_momentum']):.2e} | "
                  f"{np.degrees(np.linalg.norm(mom['omega'])):.2e} | {mom['kinetic_rigid']:.2e} | {mom['kinetic_internal']:.2e} | "
                  f"{mom['max_internal_speed']:.2e} |", flush=True)


if __name__ == "__main__":
    main()
