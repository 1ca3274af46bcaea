"""Gauss–Seidel iterations per XPBD substep to reach a tolerance, by mesh (the solver issue's
"iterations to tolerance" table, for today's solver).

Oak (seed 0, ground, the mechanics on its own mesh) dries at the defaults to WATER of its
blade's water; from that state the same leaf runs FRAMES more frames with at most 200
iterations per substep, stopping a substep's iterations when the largest position change of
an iteration falls below TOL × L.  Printed: particles, substeps per frame, mean iterations per
substep, and the same with the substeps fixed at 40 (no (r₀/r)² scaling).

    .venv/bin/python tools/iterations_to_tolerance.py [--meshes 0.028,0.0199,0.0141] [--tol 1e-6]
        [--set KEY=VALUE ...]   # parameters over the leaf's (both the drying and the probe)
"""

from __future__ import annotations

import argparse
import json
import time

from leafsim.config.species import get_species
from leafsim.pipeline import build_leaf
from leafsim.sim.effects.dynamics import effective_substeps
from leafsim.sim.run import Run

WATER, FRAMES = 0.6, 3


def measure(spacing: float, tol: float, scaling: bool, extra: dict | None = None) -> dict:
    sp = get_species("oak")
    base = {**(extra or {}), "mesh.spacing": spacing, "dynamics.path": "own", "dynamics.scene": "ground"}
    p = sp.params.with_overrides(base)
    _, _, model = build_leaf(sp, p, 0)
    run = Run(model, p, seed=0, name="oak")
    for _ in run.frames(until=lambda st: model.water_fraction(st.particle_water) <= WATER):
        pass
    q = sp.params.with_overrides({**base, "dynamics.iterations": 200, "dynamics.tolerance": tol,
                                  "dynamics.substep_scaling": scaling})
    probe = Run(model, q, seed=0, name="oak", state=run.state.copy())
    sub = effective_substeps(q)
    its = []
    for _ in range(FRAMES):
        probe.step()
        its.append(probe.sim.iterations / sub)
    return {"particles": model.particle_count, "substeps": sub, "iterations": sum(its) / len(its)}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--meshes", default="0.028,0.0199,0.0141")
    ap.add_argument("--tol", type=float, default=1e-6)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    a = ap.parse_args()
    extra = {}
    for kv in a.set:
        k, _, v = kv.partition("=")
        try:
            extra[k] = json.loads(v)
        except ValueError:  # a bare word (a choice)
            extra[k] = v
    print(f"| mesh (× L) | particles | substeps (scaled) | iterations / substep | substeps (fixed) | iterations / substep |")
    print("|---|---|---|---|---|---|")
    for s in (float(x) for x in a.meshes.split(",")):
        t0 = time.perf_counter()
        r1 = measure(s, a.tol, True, extra)
        r2 = measure(s, a.tol, False, extra)
        print(f"| {s:g} | {r1['particles']} | {r1['substeps']} | {r1['iterations']:.1f} | {r2['substeps']} | "
              f"{r2['iterations']:.1f} |  ({time.perf_counter() - t0:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
