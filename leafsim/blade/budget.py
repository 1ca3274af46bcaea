"""Refusing a blade that is too large before anything is built: the particle count estimated
from the outline, against ``limits.max_particles`` and the machine's memory."""

from __future__ import annotations

import math
import os

import numpy as np

from leafsim.base.errors import LeafsimError
from leafsim.base.geometry import LeafShape, polygon_area
from leafsim.config.params import ParamSet

#: peak memory of a built and running model: a fixed part plus this much per particle
#: (measured with ``leafsim run``: 0.31 GB at 33 k particles, 0.58 GB at 122 k; rounded up)
MEMORY_BASE_BYTES = 300e6


MEMORY_PER_PARTICLE = 4e3


#: refuse a model whose estimated memory exceeds this share of the machine's RAM
MEMORY_SHARE = 0.75


def estimate_particles(shape: LeafShape, params: ParamSet) -> int:
    """Particles (both layers) the builder would make, from outline area / r² and perimeter / r.

    Layer T holds ≈ 0.58 A/r² + 2.2 P/r particles (Poisson-disk interior plus contour), layer V
    one per triangle (≈ 2× T).  Fitted on 5 species × 3 spacings: within −10 % … +5 %.
    """
    a, b = estimate_terms(shape)
    s = params["mesh.spacing"]
    return int(round(a / s**2 + b / s))


def estimate_terms(shape: LeafShape) -> tuple[float, float]:
    """(a, b) of the estimate ``a / spacing² + b / spacing`` (spacing relative to the length)."""
    c = np.asarray(shape.contour, float)
    L = float(shape.length)
    area = abs(polygon_area(c))
    per = float(np.linalg.norm(np.diff(np.vstack([c, c[:1]]), axis=0), axis=1).sum())
    return 3.0 * 0.58 * area / L**2, 3.0 * 2.2 * per / L


def physical_memory() -> float | None:
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, OSError, ValueError):
        return None


def check_mesh_budget(shape: LeafShape, params: ParamSet) -> int:
    """Refuse (one-line LeafsimError) a blade larger than ``limits.max_particles`` or than the
    machine's memory allows, before anything is built.  Returns the estimated particle count."""
    n = estimate_particles(shape, params)
    limit = int(params["limits.max_particles"])
    spacing = params["mesh.spacing"]
    gb = (MEMORY_BASE_BYTES + MEMORY_PER_PARTICLE * n) / 1e9
    # spacing at which the estimate meets the limit: limit·s² − b·s − a = 0
    ea, eb = estimate_terms(shape)
    ok_spacing = 1.01 * (eb + math.sqrt(eb * eb + 4.0 * limit * ea)) / (2.0 * limit) if n else spacing
    if n > limit:
        raise LeafsimError(
            f"mesh.spacing = {spacing:g} would build about {n:,} particles (≈ {gb:.1f} GB) for this outline, more than "
            f"limits.max_particles = {limit:,}; use mesh.spacing ≥ {ok_spacing:.3g}, or raise limits.max_particles")
    phys = physical_memory()
    if phys and gb * 1e9 > MEMORY_SHARE * phys:
        raise LeafsimError(
            f"mesh.spacing = {spacing:g} would build about {n:,} particles needing ≈ {gb:.1f} GB, more than "
            f"{100 * MEMORY_SHARE:.0f} % of this machine's {phys / 1e9:.1f} GB; use a larger mesh.spacing")
    return n
