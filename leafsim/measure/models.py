"""The benchmark's leaves: a maple-like outline at the bench sizes (``maple`` 5.5 k particles,
``100k``, ``tiny``), the bench's solver settings and a folded state (self-contacts)."""

from __future__ import annotations

import numpy as np

from leafsim.config.params import ParamSet
from leafsim.sim.model import Model

#: name -> mesh.spacing on the built-in maple-like test outline (0.12 m long)
SIZES = {"maple": 0.0158, "100k": 0.00385, "tiny": 0.05}


#: passes of the spring race
PASSES = 10


#: the solver settings every bench job uses: 20 substeps per frame at any size (the count the
#: bench's history was measured with; the default at the fine maple mesh is 40, and
#: dynamics.substep_scaling would give a 100 k mesh ≈ 1000), mesh.spacing set to the model's
BENCH_SETTINGS = {"dynamics.substeps": 20, "dynamics.substep_scaling": False}


def bench_params(model: Model) -> ParamSet:
    """The bench's parameters for ``model``: :data:`BENCH_SETTINGS` at the model's own spacing."""
    return ParamSet({**BENCH_SETTINGS, "mesh.spacing": round(model.spacing / model.length, 6)})


EFFECTS = {e: True for e in ("gravity", "pbd", "bending", "ground", "self_collision", "shrink")}


def _maple_like():
    """A palmate five-lobed outline with midrib, laterals and sublaterals (no image needed)."""
    from leafsim.base.geometry import LeafShape, ray_polygon_hit, resample_polyline
    from leafsim.veins.graph import Vein, VeinGraph

    L = 0.12
    t = np.linspace(-np.pi / 2, 1.5 * np.pi, 400, endpoint=False)
    ang = t - np.pi / 2
    rad = (1.0 - 0.35 * (0.5 - 0.5 * np.cos(5 * ang)) ** 0.7) * (0.6 + 0.4 * np.cos(ang / 2) ** 2)
    c = np.column_stack([rad * np.cos(t), rad * np.sin(t)])
    c -= c[0]
    c *= L / c[:, 1].max()
    shape = LeafShape(contour=c, base=np.zeros(2), apex=np.array([0.0, L]), lobes=np.empty((0, 2)), length=L)
    veins = [Vein(0, resample_polyline(np.array([[0, 0], [0, 0.97 * L]]), 0.0024), np.zeros(0))]
    veins[0].widths = np.linspace(0.0015, 0.0004, len(veins[0].points))
    for k in range(6):
        y = L * (0.1 + 0.7 * k / 5)
        side = 1 if k % 2 == 0 else -1
        d = np.array([side * np.cos(np.radians(35)), np.sin(np.radians(35))])
        hit = ray_polygon_hit(np.array([0.0, y]), d, c)
        if hit:
            p = resample_polyline(np.array([[0.0, y], [0.0, y] + 0.85 * hit * d]), 0.0024)
            veins.append(Vein(1, p, np.full(len(p), 0.0005), parent=0))
    return shape, VeinGraph(veins=veins)


def build_bench_model(size: str | float, seed: int = 1) -> Model:
    from leafsim.blade.build import build_blade

    spacing = SIZES[size] if isinstance(size, str) else float(size)
    shape, veins = _maple_like()
    return build_blade(shape, veins, ParamSet({"mesh.spacing": spacing}), seed)


def folded_state(model: Model, seed: int = 1):
    """A state with the right half of the blade folded over the left, 0.3 r above it, and a
    random bilayer curl: a leaf in self-contact (the contact-heavy case)."""
    st = model.state()
    q = st.particle_q
    right = q[:, 0] > 0
    q[right, 0] *= -1
    q[right, 2] = -q[right, 2] + 3 * model.thickness + 0.3 * model.spacing
    st.hinge_rest[:] = np.random.default_rng(seed).uniform(-0.2, 0.2, model.hinge_count)
    return st
