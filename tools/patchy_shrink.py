"""Probe: can the blade's mesh hold puckers at all?  Dry a leaf whose tissue shrinks unevenly
at a set length scale and measure the wrinkles, on several meshes.

Every shrink the shrink effect computes — the springs' rest-length loss (both layers, veins,
links), the bilayer's rest angles and the thickness volumes' loss — is multiplied by
(1 + a · z(x)), with z a smooth seeded random field (zero mean, unit spread, correlation length
ℓ; leafsim.sim.senescence.random_field, a function of the rest position only, so every mesh
sees the same field).  Patches that shrink less than their surroundings are compressed by them:
an incompatibility at a chosen scale, which a mesh either resolves as puckers or absorbs.  A probe
of the resolution; the model's own version is the parameter ``shrink.patchiness`` (its field
differs: own seed and salt, normalised over the blade only, the stalk uniform, the length in
metres; docs/drying/README.md).

    python tools/patchy_shrink.py SPECIES SPACING A ELL OUT.json [PICTURES_DIR]
    # e.g. maple 0.0199 0.5 0.05 out.json: ±50 % over 0.05 L on the default mesh
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from drying_report import dry  # noqa: E402
from leafsim.sim.effects import shrink as shrink_effect  # noqa: E402
from leafsim.sim.kernels import shrink as ks  # noqa: E402
from leafsim.sim.senescence import random_field  # noqa: E402

_apply = shrink_effect.Shrink.apply


def _fields(model, a: float, ell_L: float, seed: int = 7) -> tuple:
    """Per spring and per hinge the factor 1 + a z at their midpoints (clipped to ≥ 0)."""
    xy = model.particle_rest[:, :2]
    L = float(np.ptp(model.particle_rest[model.blade_T, 1]))
    z = random_field(xy, model.particle_area, ell_L * L, [seed, 0x9A7C])
    ij = model.spring_ij
    fs = np.clip(1.0 + a * 0.5 * (z[ij[:, 0]] + z[ij[:, 1]]), 0.0, None)
    h = model.hinge_idx
    # the hinge's two opposite vertices (c, d): their midpoint is near the shared edge's (the
    # parameter shrink.patchiness takes the shared edge itself, columns 2 and 3)
    fh = np.clip(1.0 + a * 0.5 * (z[h[:, 0]] + z[h[:, 1]]), 0.0, None)
    return fs, fh


def patched(a: float, ell_L: float):
    def apply(self, state):
        _apply(self, state)
        m = self.model
        if not hasattr(self, "_patchy"):
            self._patchy = _fields(m, a, ell_L)
        fs, fh = self._patchy
        r0 = m.spring_rest0
        state.spring_rest[:] = np.maximum(r0 - (r0 - state.spring_rest) * fs, self.l_min * r0)
        if m.hinge_count:
            np.multiply(state.hinge_rest, fh, out=state.hinge_rest)
        ks.tri_ratios(self.tri_springs, r0, state.spring_rest, self.ratios)
        ks.vol_targets(self.vol_tri, self.ratios, m.vol_rest0, state.vol_rest)
    return apply


def main(argv: list[str]) -> None:
    key, spacing, a, ell, out = argv[0], float(argv[1]), float(argv[2]), float(argv[3]), argv[4]
    pics = Path(argv[5]) if len(argv) > 5 else None
    if pics is not None:
        pics.mkdir(parents=True, exist_ok=True)
    shrink_effect.Shrink.apply = patched(a, ell)
    row = dry(key, "ground", 60.0, pics, {"mesh.spacing": spacing})
    row.update({"patchy_a": a, "patchy_ell_L": ell, "mesh_spacing_L": spacing})
    Path(out).write_text(json.dumps(row, indent=1))
    print(json.dumps(row))


if __name__ == "__main__":
    if len(sys.argv) < 6:
        sys.exit("usage: python tools/patchy_shrink.py SPECIES SPACING A ELL OUT.json [PICTURES_DIR]")
    main(sys.argv[1:])
