"""Where a leaf turns first: the seeded senescence field of one blade.

Autumn colour is not uniform.  Chlorophyll breakdown starts in the interveinal tissue and at the
margin and reaches the tissue along the veins last, which stays green longest ("green islands"
along the main and lateral veins: the veins keep supplying water and cytokinins; Keskitalo
et al. 2005, Plant Physiol. 139:1635 for aspen's autumn programme; Lim et al. 2007, Annu. Rev.
Plant Biol. 58:115 on the spatial order of senescence).  It proceeds in patches (neighbouring
areoles of one leaf differ by days), and fungi leave spots: necrotic lesions with a yellow halo
(the chlorotic ring around a leaf spot) or the black stromata of maple tar spot (*Rhytisma
acerinum*, 1–2 cm across, each ringed with yellow; Weber & Webster 2002, Mycologist 16:3).

This module turns that into two per-particle fields, functions of the rest position only (so the
same seed gives the same pattern at any mesh spacing):

* ``rate`` — a multiplier (mean about one) of the senescence exposure of
  :func:`leafsim.sim.pigments.step_pigments`::

      rate = exp(p·z − p²/2) · (1 + margin·exp(−d_margin / w_margin))
             · (1 − islands·exp(−(d_vein / w_island)²)) · halo

  with ``z`` a smooth seeded random field (zero mean, unit spread, correlation length
  ``colour.patch_size``), ``p = colour.patchiness``, ``d_margin`` the distance to the outline,
  ``d_vein`` the distance to the nearest main or lateral vein, and ``halo = 1 +
  HALO_BOOST·exp(−((d_spot − r)/r)²)`` outside each spot of radius ``r``.

* ``spot`` ∈ [0, 1] — lesion tissue: spots of radius ``colour.spot_radius`` (each × a
  log-normal factor) at a seeded Poisson density ``colour.spots`` per m² of blade.  Spot
  tissue dies while it is still green as soon as its senescence runs (``SPOT_KILL`` × its
  exposure turns into necrosis), so it turns dark inside a yellow ring.

Units: lengths in metres, density per m² — the same field on a 7 cm aspen and a 20 cm pokeweed
means the same patches and spots per unit area.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from leafsim.base.geometry import points_in_polygon

__all__ = ["random_field", "senescence_field", "FIELD_KEYS", "SPOT_KILL", "HALO_BOOST"]

#: necrosis exposure of spot tissue per unit of its senescence exposure (it dies green)
SPOT_KILL = 12.0
#: senescence speed-up in the ring just outside a spot (the yellow halo)
HALO_BOOST = 3.0
#: the parameters the field depends on (a change rebuilds it)
FIELD_KEYS = ("colour.patchiness", "colour.patch_size", "colour.margin_first", "colour.margin_width",
              "colour.vein_islands", "colour.island_width", "colour.spots", "colour.spot_radius")
_SALT = 0x5E7E5C


def random_field(xy: np.ndarray, weights: np.ndarray, length: float, seed, features: int = 64) -> np.ndarray:
    """(n,) smooth seeded Gaussian random field at the points ``xy`` (n, 2) [m]: zero mean and
    unit spread under ``weights`` (n,), correlation length ``length`` [m], from ``features``
    random Fourier features seeded by ``seed`` (an int or a list of ints for
    ``numpy.random.default_rng``).  A function of position only: refining the points samples the
    same field."""
    rng = np.random.default_rng(seed)
    omega = rng.standard_normal((features, 2)) / float(length)
    phase = rng.uniform(0.0, 2.0 * np.pi, features)
    f = np.cos(np.asarray(xy, float) @ omega.T + phase).sum(1) * math.sqrt(2.0 / features)
    w = np.asarray(weights, float)
    mean = float(np.dot(w, f) / max(w.sum(), 1e-300))
    sd = math.sqrt(float(np.dot(w, (f - mean) ** 2) / max(w.sum(), 1e-300)))
    return (f - mean) / max(sd, 1e-12)


def _vein_distance(model, xy: np.ndarray, max_order: int = 1) -> np.ndarray:
    """Distance [m] from each point to the nearest vein of order ≤ ``max_order`` (main and
    lateral), the veins' polylines resampled finer than the mesh; inf without veins."""
    from scipy.spatial import cKDTree

    rest = model.particle_rest[:, :2]
    pts = []
    step = 0.25 * float(model.spacing)
    stalk = ~model.blade_particles
    for idx, _, order in model.vein_polylines():
        if order > max_order or len(idx) < 2 or stalk[idx].any():  # the blade's veins, not the petiole
            continue
        p = rest[idx]
        seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
        for a, b, s in zip(p[:-1], p[1:], seg):
            k = max(1, int(math.ceil(s / step)))
            t = np.arange(k)[:, None] / k
            pts.append(a + t * (b - a))
        pts.append(p[-1:])
    if not pts:
        return np.full(len(xy), np.inf)
    return cKDTree(np.vstack(pts)).query(xy)[0]


def senescence_field(model, params: Mapping[str, Any], seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(rate (n,) float32, spot (n,) float32) of ``model``'s particles (module docstring); the
    rate is 1 and the spot 0 everywhere when every field parameter is 0."""
    n = model.particle_count
    xy = model.particle_rest[:, :2]
    g = {k: float(params[k]) for k in FIELD_KEYS}
    rate = np.ones(n)
    p = g["colour.patchiness"]
    if p > 0.0:
        z = random_field(xy, model.particle_area, g["colour.patch_size"], [int(seed), _SALT])
        rate *= np.exp(p * z - 0.5 * p * p)
    if g["colour.margin_first"] > 0.0:
        rate *= 1.0 + g["colour.margin_first"] * np.exp(-model.particle_margin_distance / g["colour.margin_width"])
    if g["colour.vein_islands"] > 0.0:
        d = _vein_distance(model, xy)
        rate *= 1.0 - g["colour.vein_islands"] * np.exp(-((d / g["colour.island_width"]) ** 2))
    spot = np.zeros(n)
    area = float(model.particle_area[model.blade_T].sum())
    if g["colour.spots"] > 0.0 and area > 0.0:
        rng = np.random.default_rng([int(seed), _SALT, 1])
        count = int(rng.poisson(g["colour.spots"] * area))
        if count:
            lo, hi = xy.min(0), xy.max(0)
            centres = rng.uniform(lo, hi, (4 * count + 16, 2))
            centres = centres[points_in_polygon(centres, xy[model.contour_particles])][:count]  # on the blade
            radii = g["colour.spot_radius"] * np.exp(0.3 * rng.standard_normal(len(centres)))
            halo = np.zeros(n)
            for c, r in zip(centres, radii):  # one spot at a time: memory O(n), not O(n·spots)
                rel = (np.linalg.norm(xy - c, axis=1) - r) / r
                np.maximum(spot, np.clip(0.5 - 2.0 * rel, 0.0, 1.0), out=spot)  # 1 inside, a soft edge of r/2
                np.maximum(halo, np.where(rel > 0.0, np.exp(-(rel ** 2)), 1.0), out=halo)
            rate *= 1.0 + HALO_BOOST * halo
    stalk = ~model.blade_particles
    if stalk.any():  # the petiole turns with the blade: its mean rate, no spots, no islands of its own
        b = model.blade_T
        rate[stalk] = float(np.dot(rate[b], model.particle_area[b]) / max(float(model.particle_area[b].sum()), 1e-300))
        spot[stalk] = 0.0
    return rate.astype(np.float32), spot.astype(np.float32)
