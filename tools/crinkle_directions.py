"""Which way a dried leaf's crinkle wrinkles (``render.crinkle``, :mod:`leafsim.sim.crinkle`):
the lamina's compression against the nearest main vein or lateral.

    .venv/bin/python tools/crinkle_directions.py --species maple [--set mesh.spacing=0.0141]
        [--cache DIR]

Dries the leaf as ``tools/crinkle_picture.py`` does (the drying report's protocol; ``--cache``
shares its pickles) and prints one JSON line: the lamina's one-way share and, in bands of
distance from the nearest main-vein or lateral segment (in the flat rest plane, × L), the
one-way share there and the shares of the excess (weights: particle area × tr K) whose squeeze
lies within 30° of that segment's direction or more than 60° from it.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parent))

from crinkle_picture import dried  # noqa: E402
from midrib_crease import _value  # noqa: E402

from leafsim.sim.crinkle import crinkle_stats, lamina_compression, principal  # noqa: E402

#: distance bands from the nearest main vein or lateral, × L
BANDS = ((0.0, 0.01), (0.01, 0.02), (0.02, 0.04), (0.04, np.inf))


def directions(model, state) -> list[dict]:
    K = lamina_compression(model, state)
    big, small, ang = principal(K)
    big, small = np.maximum(big, 0.0), np.maximum(small, 0.0)
    rest = np.asarray(model.particle_rest, np.float64)[:, :2]
    order = np.asarray(model.particle_vein_order)
    lamina = model.blade_T & ~((order >= 0) & (order <= 1))
    a, b = [], []
    for idx, _, o in model.vein_polylines():
        if o <= 1:
            p = rest[np.asarray(idx)]
            a.append(p[:-1])
            b.append(p[1:])
    A, B = np.concatenate(a), np.concatenate(b)
    dist, j = cKDTree(0.5 * (A + B)).query(rest)  # the nearest segment (by its midpoint)
    seg = (B - A)[j]
    seg /= np.maximum(np.linalg.norm(seg, axis=1, keepdims=True), 1e-300)
    d = np.stack([np.cos(ang), np.sin(ang)], 1)
    rel = np.degrees(np.arccos(np.clip(np.abs(np.sum(d * seg, axis=1)), 0.0, 1.0)))  # 0: squeezed along the vein
    tot = big + small
    one_way = np.where(tot > 0.0, (big - small) / np.where(tot > 0.0, tot, 1.0), 0.0)
    w = np.asarray(model.particle_area, np.float64) * tot
    L = float(np.ptp(rest[model.blade_T, 1]))
    out = []
    for lo, hi in BANDS:
        m = lamina & (dist >= lo * L) & (dist < hi * L) & (w > 0.0)
        if not m.any():
            continue
        ww = w[m]
        out.append({"band_L": [lo, None if np.isinf(hi) else hi], "particles": int(m.sum()),
                    "one_way": round(float(np.average(one_way[m], weights=ww)), 3),
                    "along_within_30deg": round(float(np.average(rel[m] < 30.0, weights=ww)), 3),
                    "across_beyond_60deg": round(float(np.average(rel[m] > 60.0, weights=ww)), 3)})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--species", default="maple")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--cache")
    a = ap.parse_args()
    overrides = {k: _value(v) for k, v in (s.split("=", 1) for s in a.set)}
    _, _, model, st = dried(a.species, overrides, Path(a.cache) if a.cache else None)
    print(json.dumps({"species": a.species, "set": a.set, "particles": int(model.particle_count),
                      "one_way_share": crinkle_stats(model, st)["crinkle_one_way_share"], "bands": directions(model, st)}))


if __name__ == "__main__":
    main()
