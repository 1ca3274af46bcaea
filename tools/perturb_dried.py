"""Is a dried leaf's compressed lamina stable? Dry a leaf by the drying report's protocol, push
its blade out of plane by a smooth random bump field, run on, and print how the wrinkles and
the lamina's excess length evolve (docs/drying/README.md, "The midrib fold, measured across
the midrib": the compressed lamina is stable on the mesh).

    .venv/bin/python tools/perturb_dried.py --species maple [--amp-mm 0.2] [--frames 400]
        [--set KEY=VALUE ...]      # parameters of the drying (and of the run after it)
        [--after KEY=VALUE ...]    # parameters of the run after the bumps only

The bump field is the sum of forty plane waves of random direction and phase, wavelengths
uniform in 2-10 mm (seeded), scaled to ``--amp-mm`` RMS, the same on both layers (the blade's
thickness is left as it is).  One JSON line before the bumps, right after them, and four during
the run: the dried-shape measures (leafsim.sim.curl) and the lamina's mean excess length
(leafsim.sim.crinkle).  If the bumps decay back to the unbumped measures, the compressed state
is stable against buckling at those wavelengths; if they grow into a pattern, it was not.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from drying_report import dried_state  # noqa: E402

from leafsim.sim.crinkle import crinkle_stats  # noqa: E402
from leafsim.sim.curl import dried_shape  # noqa: E402
from leafsim.sim.run import Run, Stop  # noqa: E402


def _pairs(items: list[str]) -> dict:
    out = {}
    for kv in items:
        k, _, v = kv.partition("=")
        try:
            out[k] = json.loads(v)
        except ValueError:  # a bare word such as static
            out[k] = v
    return out


def bumps(rest_xy: np.ndarray, amp: float, seed: int = 1, waves: int = 40) -> np.ndarray:
    """(n,) heights [m]: ``waves`` plane waves of 2-10 mm over the rest positions, ``amp`` RMS."""
    rng = np.random.default_rng(seed)
    dz = np.zeros(len(rest_xy))
    for _ in range(waves):
        lam, th, ph = rng.uniform(0.002, 0.010), rng.uniform(0.0, np.pi), rng.uniform(0.0, 2.0 * np.pi)
        dz += np.cos(2.0 * np.pi * (rest_xy @ np.array([np.cos(th), np.sin(th)])) / lam + ph)
    return dz * (amp / max(float(dz.std()), 1e-300))


def _line(tag, model, state) -> str:
    return json.dumps({"at": tag, "frame": int(state.frame), **dried_shape(model, state),
                       "excess_pct": crinkle_stats(model, state)["crinkle_excess_pct"]}, default=float)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--species", default="maple")
    ap.add_argument("--amp-mm", type=float, default=0.2)
    ap.add_argument("--frames", type=int, default=400)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--after", action="append", default=[], metavar="KEY=VALUE")
    a = ap.parse_args()
    sp, params, model, state = dried_state(a.species, _pairs(a.set))
    print(_line("dried", model, state), flush=True)
    state.particle_q[:, 2] += bumps(model.particle_rest[:, :2], 1e-3 * a.amp_mm)
    print(_line("bumped", model, state), flush=True)
    after = params.with_overrides(_pairs(a.after)) if a.after else params
    run = Run(model, after, state=state, seed=0, name=a.species)
    n0, every = state.frame, max(1, a.frames // 4)
    for i, _ in enumerate(run.frames(Stop(frames=n0 + a.frames))):
        if (i + 1) % every == 0:
            print(_line(f"+{i + 1} frames", model, run.state), flush=True)


if __name__ == "__main__":
    main()
