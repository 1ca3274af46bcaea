"""What a cheaper own-mesh phase of the drying path costs in accuracy: the measurements behind
docs/performance.md ("Fewer sweeps on the own mesh, measured").

The default drying runs its mechanics on the coarse path mesh until 15 % of the water is left
and on the leaf's own mesh after that (leafsim.sim.path); on maple the own mesh's frames are
two thirds of "Dry to end".  This tool runs the accuracy protocol (dry to 2 % water, on to
1.15 × that time) with the default path, and from the hand-over on gives the own mesh's
dynamics other solver settings (``key=value``, e.g. ``dynamics.iterations=1``); a key written
``all:key=value`` changes the whole run's parameters instead (the drying path then runs only if
they keep the default solver settings).  It pickles the probe fields at 2 % water and at the
protocol's end with the CPU seconds of each phase.

    python tools/own_phase_settings.py run maple base.pkl
    python tools/own_phase_settings.py run maple i1.pkl dynamics.iterations=1
    python tools/equilibrium_lag.py direct maple reference ref.pkl       # the XPBD reference
    python tools/own_phase_settings.py score ref.pkl base.pkl i1.pkl    # against it
    python tools/own_phase_settings.py limit oak CACHE_DIR base.pkl i1.pkl   # against the static limit

``score`` prints the errors as ``leafsim accuracy`` reports them (position and height relative
to the reference's own deformation) at 2 % water and at the end; ``limit`` scores the end
states against the extrapolated limit of ``leafsim accuracy --limit`` (its static runs are kept
in CACHE_DIR and reused).
"""

from __future__ import annotations

import json
import pickle
import sys
import time
import types
from pathlib import Path

import numpy as np

from equilibrium_lag import _relative
from leafsim.config.species import get_species
from leafsim.measure.accuracy import DRY_WATER, SETTLE, errors
from leafsim.pipeline import build_leaf, leaf_shape
from leafsim.sim.metrics import Probe
from leafsim.sim.run import Run


def _overrides(args: list[str]) -> tuple[dict, dict]:
    own, whole = {}, {}
    for a in args:
        key, _, text = a.partition("=")
        try:
            value = json.loads(text)
        except json.JSONDecodeError:
            value = text
        (whole if key.startswith("all:") else own)[key.removeprefix("all:")] = value
    return own, whole


def run(species: str, out: str, args: list[str]) -> None:
    """The protocol's run with the own-mesh phase on ``args``' settings; pickled to ``out``."""
    own, whole = _overrides(args)
    sp = get_species(species)
    base = sp.params.with_overrides({"effects.colour": False, **whole})
    model = build_leaf(sp, base, 0).model
    probe = Probe(leaf_shape(sp, sp.params))
    r = Run(model, base, seed=0)
    t0 = time.process_time()
    n, handover, cpu_path = 0, None, float("nan")
    while model.water_fraction(r.state.particle_water) > DRY_WATER:
        r.step()
        n += 1
        if handover is None and not r.sim.on_path:
            handover, cpu_path = n, time.process_time() - t0
            if own:
                r.sim._dynamics.configure(base.with_overrides(own), r.sim.effects)
    cpu_dry = time.process_time() - t0
    at_dry = probe.fields(model, r.state)
    for _ in range(int(np.ceil(SETTLE * n)) - n):
        r.step()
    end = probe.fields(model, r.state)
    cpu = time.process_time() - t0
    with open(out, "wb") as f:
        pickle.dump({"species": species, "level": " ".join(args) or "defaults", "particles": model.particle_count,
                     "dry_frames": n, "handover": handover, "cpu_path": cpu_path, "cpu_dry": cpu_dry, "cpu": cpu,
                     "dry": at_dry, "end": end}, f)
    print(f"{out}: hand-over at frame {handover} ({cpu_path:.1f} s CPU), 2 % water at frame {n} ({cpu_dry:.1f} s), "
          f"protocol end {cpu:.1f} s; end: margin lift {end['margin_lift']:.4f}, 3D {end['area_3d']:.4f}, "
          f"top-down {end['area_top']:.4f}")


def _load(path: str) -> dict:
    with open(path, "rb") as f:
        return pickle.load(f)


def score(ref_path: str, runs: list[str]) -> None:
    ref = _load(ref_path)
    sp = get_species(ref["species"])
    probe = Probe(leaf_shape(sp, sp.params))
    for path in runs:
        r = _load(path)
        print(f"{path} [{r['level']}] CPU to 2 % {r['cpu_dry']:.1f} s, to the end {r['cpu']:.1f} s | at 2 %: "
              f"{_relative(r['dry'], ref['dry'], probe)} | at the end: {_relative(r['end'], ref['end'], probe)}")


def score_limit(species: str, cache: str, runs: list[str]) -> None:
    from leafsim.measure.limit import limit_study

    keep: dict = {}
    limit_study(species, cache=Path(cache), candidates=[], progress=False, keep=keep)
    lim, probe = keep["limit"], keep["probe"]
    for path in runs:
        r = _load(path)
        e = errors(types.SimpleNamespace(end=r["end"], water=[], time_to_dry=lim.time_to_dry), lim, probe)
        print(f"{path} [{r['level']}] CPU to 2 % {r['cpu_dry']:.1f} s: position {e['position_rel']:.1%}, "
              f"height {e['height_rel']:.1%}, lift {e['margin_lift_rel']:.1%}, 3D {e['area_3d_rel']:.1%}, "
              f"top {e['area_top_rel']:.1%}")


if __name__ == "__main__":
    a = sys.argv[1:]
    if len(a) >= 3 and a[0] == "run":
        run(a[1], a[2], a[3:])
    elif len(a) >= 3 and a[0] == "score":
        score(a[1], a[2:])
    elif len(a) >= 4 and a[0] == "limit":
        score_limit(a[1], a[2], a[3:])
    else:
        sys.exit("usage: python tools/own_phase_settings.py run SPECIES OUT.pkl [key=value ...] | "
                 "score REF.pkl RUN.pkl ... | limit SPECIES CACHE_DIR RUN.pkl ...")
