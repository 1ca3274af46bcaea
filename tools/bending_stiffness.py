"""The blade's effective bending stiffness against the plate rigidity it is given.

    .venv/bin/python tools/bending_stiffness.py [--species maple] [--set mesh.spacing=0.0141]
        [--curvature 2.0] [--dry]

Bends the fresh blade (or, with ``--dry``, the same blade with every particle's water gone, so
the hinges carry their dry stiffening) into a cylinder of curvature κ [1/m] about the leaf's
length axis and about its width axis: layer T is put on the cylinder (lengths kept), layer V is
left free and relaxed to its least energy (L-BFGS on the elastic energy of the static
integrator, :mod:`leafsim.sim.kernels.static`).  The veins' modulus is set to 10⁵ Pa so that
the lamina alone is measured.  Prints, per bending axis, the elastic energy of each kind of
constraint over ½ D κ² A (A the blade's area, D = E h³ / 12(1 − ν²) × the hinges' dry factor):
the hinges, the springs (the two membrane layers a thickness apart, and the links between them:
a sandwich's bending), the thickness volumes, and their sum, the blade's D_eff / D, with the
relaxation's iterations and the force it left.  Layer T is held to the cylinder without
stretching, so the neutral surface cannot move off it: the springs' share is an upper bound
(half of it if the layers could share the strain equally); ``T_sliding`` repeats the bend with
layer T free to slide and stretch on the cylinder, which gives the blade's own share.  Then
the hinges alone in a
cylinder, a cup and a saddle against the plate's energy in each (``hinges_by_mode``,
:func:`leafsim.sim.bending.mode_ratios`).  A blade that bends as the plate it stands for reads
1 throughout (docs/method.md §5, "Bending stiffness, measured").
"""

from __future__ import annotations

import argparse
import json

import numpy as np
from scipy.optimize import minimize

from leafsim.config.species import get_species
from leafsim.pipeline import build_leaf
from leafsim.sim.bending import hinge_weights, mode_ratios
from leafsim.sim.kernels import static as kst
from leafsim.sim.model import LAYER_T
from leafsim.sim.simulator import Simulator


def _pairs(items):
    out = {}
    for kv in items:
        k, _, v = kv.partition("=")
        try:
            out[k] = json.loads(v)
        except ValueError:
            out[k] = v
    return out


def _sliding(q_start, T, axis, R, c, rec, eq, kinds, base, scale) -> dict:
    """The bend of :func:`measure` with layer T's particles free on the cylinder: each has an arc
    coordinate s (position c + R sin(s/R), height R (1 − cos(s/R))) and a free coordinate along
    the cylinder's axis; layer V free in 3D.  The energy by kind, over ½ D κ² A."""
    other = 1 - axis
    Ti, Vi = np.flatnonzero(T), np.flatnonzero(~T)
    grad = np.zeros_like(q_start)
    s0 = R * np.arcsin(np.clip((q_start[Ti, axis] - c) / R, -1.0, 1.0))
    x0 = np.concatenate([s0, q_start[Ti, other], q_start[Vi].ravel()])
    nT = len(Ti)

    def place(x):
        q = q_start.copy()
        s, w = x[:nT], x[nT:2 * nT]
        q[Ti, axis] = c + R * np.sin(s / R)
        q[Ti, other] = w
        q[Ti, 2] = R * (1.0 - np.cos(s / R))
        q[Vi] = x[2 * nT:].reshape(-1, 3)
        return q, s

    def f(x):
        q, s = place(x)
        e = kst.elastic(q, *rec, eq.smap, eq.hmap, eq.vmap, grad, eq.data, False)
        gT = grad[Ti]
        ds = gT[:, axis] * np.cos(s / R) + gT[:, 2] * np.sin(s / R)
        return e, np.concatenate([ds, gT[:, other], grad[Vi].ravel()])

    r = minimize(f, x0, jac=True, method="L-BFGS-B", options={"maxiter": 40000, "gtol": 1e-16, "ftol": 1e-16})
    q, _ = place(r.x)
    e = kinds(q)
    row = {k: round((e[k] - base[k]) * scale, 3) for k in e}
    row["D_eff_over_D"] = round(sum(row.values()), 3)
    row["iterations"] = int(r.nit)
    return row


def measure(key: str, overrides: dict, kappa: float, dry: bool) -> dict:
    sp = get_species(key)
    p = sp.params.with_overrides({**overrides, "material.vein_modulus": 1e5, "dynamics.integrator": "static",
                                  "dynamics.scene": "ground", "effects.osmosis": False, "effects.shrink": False})
    _, _, model = build_leaf(sp, p, 0)
    sim = Simulator(model, p, seed=0)
    st = sim.state()
    if dry:
        st.particle_water[:] = 0.0
    dyn = sim._dynamics  # the elastic records the static integrator minimises
    ij, sk, srest, _, hidx, hk, hrest, vidx, vk, vrest = dyn.sun_elastic(st)
    eq = dyn.equilibrium
    rec = (ij, sk, srest, hidx, hk, hrest, vidx, vk, vrest)
    rest = model.particle_rest
    T = model.particle_layer == LAYER_T
    blade = model.blade_particles
    # the blade's own constraints only (the stalk is a rod of its own, bent here too)
    sb, hb, vb = blade[ij].all(1), blade[hidx].all(1), blade[vidx].all(1)
    area = float(model.particle_area[model.blade_T].sum())
    D = dyn.kbend * (1.0 + (dyn.kdry if dry else 0.0))
    free = np.flatnonzero(~T)
    grad = np.zeros_like(rest)

    def kinds(q):
        none_s, none_h, none_v = (ij[:0], sk[:0], srest[:0]), (hidx[:0], hk[:0], hrest[:0]), (vidx[:0], vk[:0], vrest[:0])
        return {"hinges": kst.elastic_energy(q, *none_s, hidx[hb], hk[hb], hrest[hb], *none_v),
                "springs": kst.elastic_energy(q, ij[sb], sk[sb], srest[sb], *none_h, *none_v),
                "volumes": kst.elastic_energy(q, *none_s, *none_h, vidx[vb], vk[vb], vrest[vb])}

    base = kinds(rest)
    out = {"species": key, "particles": model.particle_count, "blade_area_m2": area, "D_Nm": D, "dry": dry,
           "kappa_per_m": kappa}
    centre = rest[blade].mean(0)
    for name, axis in (("across the width", 0), ("along the length", 1)):
        R = 1.0 / kappa
        u = rest[:, axis] - centre[axis]
        z = rest[:, 2]
        q0 = rest.copy()
        q0[:, axis] = centre[axis] + (R - z) * np.sin(u / R)
        q0[:, 2] = R - (R - z) * np.cos(u / R)

        def f(v, q0=q0):
            q = q0.copy()
            q[free] = v.reshape(-1, 3)
            e = kst.elastic(q, *rec, eq.smap, eq.hmap, eq.vmap, grad, eq.data, False)
            return e, grad[free].ravel().copy()

        r = minimize(f, q0[free].ravel(), jac=True, method="L-BFGS-B",
                     options={"maxiter": 20000, "gtol": 1e-16, "ftol": 1e-16})
        q = q0.copy()
        q[free] = r.x.reshape(-1, 3)
        e = kinds(q)
        scale = 1.0 / (0.5 * D * kappa * kappa * area)
        row = {k: round((e[k] - base[k]) * scale, 3) for k in e}
        row["D_eff_over_D"] = round(sum(row.values()), 3)
        # the relaxation: iterations, the largest force left on a free particle against the
        # largest at the start (layer V placed along the normal)
        _, g0 = f(q0[free].ravel())
        row["relaxation"] = {"iterations": int(r.nit), "force_left": float(np.abs(r.jac).max() / max(np.abs(g0).max(), 1e-300))}
        # layer T free to slide and stretch on the cylinder (its arc position and its position
        # along the axis free, the radius held): the neutral surface may move off layer T
        row["T_sliding"] = _sliding(q, T, axis, R, centre[axis], rec, eq, kinds, base, scale)
        out[name] = row
    # the hinges alone in a cylinder, a cup and a saddle, against the plate (ν of the parameters)
    w = hinge_weights(model, p["material.hinge_weights"])
    out["hinges_by_mode"] = {k: round(v, 3) for k, v in mode_ratios(model, w, p["material.poisson"]).items()}
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--species", default="maple")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--curvature", type=float, default=2.0, help="κ [1/m] (2: a radius of 0.5 m)")
    ap.add_argument("--dry", action="store_true", help="every particle's water gone: the hinges' dry stiffening")
    a = ap.parse_args()
    print(json.dumps(measure(a.species, _pairs(a.set), a.curvature, a.dry)))


if __name__ == "__main__":
    main()
