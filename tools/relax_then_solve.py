"""Does relaxing the handed-over state with XPBD frames make the first static solve cheaper?
The measurement behind docs/performance.md ("A static finish, measured": relaxing first).

Dries ``species`` at its defaults with the XPBD finish (drying path) to the hand-over (whose
step is the own mesh's first XPBD frame), then after each count N of further own-mesh XPBD
frames solves the static equilibrium (:class:`Equilibrium`, fresh
friction) on a copy of the state and prints the Newton iterations, the largest force before
and after (× a particle's weight), the time and how far the solve moved the leaf.

    python tools/relax_then_solve.py maple 1,10,40,150
"""

from __future__ import annotations

import sys
import time

import numpy as np

from leafsim.config.species import get_species
from leafsim.pipeline import build_leaf
from leafsim.sim.effects.dynamics import Dynamics
from leafsim.sim.run import Run


def main(species: str, counts: list[int]) -> None:
    sp = get_species(species)
    p = sp.params.with_overrides({"dynamics.finish": "xpbd"})  # the own mesh relaxes with XPBD frames
    m = build_leaf(sp, p, 0).model
    r = Run(m, p, seed=0)
    while r.sim.on_path:
        r.step()
    handover = r.state.frame
    d = Dynamics(m)
    d.configure(p.with_overrides({"dynamics.integrator": "static"}), r.sim.effects)
    eq = d.equilibrium
    done = 0
    for n in sorted(counts):
        while done < n:
            r.step()
            done += 1
        st = r.state.copy()
        eq.reset()
        eq.anchor[:] = st.particle_q[:, :2]
        t, c = time.perf_counter(), time.process_time()
        info = eq.solve(st)
        moved = np.sqrt(((st.particle_q - r.state.particle_q) ** 2).sum(1)).max() / m.length
        print(f"{species}: {n} XPBD frames after the hand-over (frame {handover + n}): {info.iterations} Newton "
              f"iterations, largest force {info.residual0:.3g} → {info.residual:.3g} × weight, "
              f"{time.perf_counter() - t:.1f} s wall, {time.process_time() - c:.1f} s CPU, moved ≤ {moved:.4f} L", flush=True)


if __name__ == "__main__":
    main(sys.argv[1], [int(x) for x in sys.argv[2].split(",")])
