"""Performance benchmark (``leafsim bench``): median ms per stage and per full step.

A *full step* is what the thesis ran per frame: osmosis + shrink + 10 PBD iterations over all
distance constraints (both layers and links).  It is timed for every PBD variant (serial
Gauss–Seidel, graph-coloured parallel Gauss–Seidel, atomics-free parallel Jacobi), next to a
vectorised-numpy implementation of the same step in the same run, and next to the default
production dynamics step (5 substeps × 2 iterations with bending hinges, thickness
constraints, ground and self-collision).  numba caches are warmed before timing; medians.

Example
-------
>>> print(format_bench(run_bench(sizes=("maple",))))    # doctest: +SKIP
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from .params import ParamSet
from .sim.model import LAYER_V, SPRING_VEIN, Model

#: name -> mesh.spacing on the built-in maple-like test outline (0.12 m long)
SIZES = {"maple": 0.0158, "100k": 0.00385, "tiny": 0.05}


def _maple_like():
    """A palmate five-lobed outline with midrib, laterals and sublaterals (no image needed)."""
    from .geometry import LeafShape, ray_polygon_hit, resample_polyline
    from .venation import Vein, VeinGraph

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
    from .blade import build_blade

    spacing = SIZES[size] if isinstance(size, str) else float(size)
    shape, veins = _maple_like()
    return build_blade(shape, veins, ParamSet({"mesh.spacing": spacing}), seed)


def _median_ms(fn, reps: int, warm: int = 2) -> float:
    for _ in range(warm):
        fn()
    out = []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        out.append((time.perf_counter() - t0) * 1e3)
    return float(np.median(out))


class NumpyStep:
    """Vectorised-numpy reference of the same full step (scipy LU osmosis, numpy shrink,
    bincount Jacobi PBD) — the baseline for the speed-up ratio."""

    def __init__(self, model: Model, params: ParamSet, osm_A):
        self.m = model
        self.lu = splu(osm_A.tocsc())
        t = model.spring_type
        self.sigma = np.where(t == SPRING_VEIN, params["shrink.sigma_vein"], params["shrink.sigma_surface_bottom"])
        self.sigma[t == 2] = params["shrink.sigma_surface_top"]
        self.l_min = params["shrink.l_min"]
        self.rate = np.where(model.particle_layer == LAYER_V, params["osmosis.loss_top"], params["osmosis.loss_bottom"])
        self.dt = params["dynamics.dt"]
        n = model.particle_count
        self.deg = np.bincount(model.spring_ij.ravel(), minlength=n).astype(float)

    def step(self, q, w, rest):
        m = self.m
        M = m.particle_cytosol
        c = w / M
        loss = np.minimum(self.rate * self.dt * m.particle_water0, w)
        cn = self.lu.solve(M * c - loss)
        w[:] = np.maximum(cn, 0) * M
        i, j = m.spring_ij[:, 0], m.spring_ij[:, 1]
        mass = M + w
        v = (mass[i] + mass[j]) / (m.particle_mass0[i] + m.particle_mass0[j])
        rest[:] = m.spring_rest0 * np.clip(1 - self.sigma * np.clip(1 - v, 0, None), self.l_min, 1)
        invm = 1.0 / mass
        wi, wj = invm[i], invm[j]
        n = len(q)
        for _ in range(10):
            d = q[i] - q[j]
            ln = np.sqrt((d * d).sum(1))
            f = ((rest - ln) / np.maximum(ln, 1e-12) / (wi + wj))[:, None] * d
            for k in range(3):
                q[:, k] += 1.5 * (np.bincount(i, f[:, k] * wi, n) - np.bincount(j, f[:, k] * wj, n)) / np.maximum(self.deg, 1)


def bench_model(model: Model, reps: int = 30, params: ParamSet | None = None) -> dict:
    """Time every stage on one model; returns a dict of medians (ms) and counts."""
    from .sim.effects import Dynamics, Osmosis, Shrink
    from .sim.kernels import osmosis as ko
    from .sim.kernels import pbd as kp

    params = params or ParamSet()
    out = {"particles": model.particle_count, "springs": model.spring_count, "ms": {}}
    ms = out["ms"]
    st = model.state()
    st.particle_water[:] *= np.linspace(0.6, 1.0, model.particle_count)
    # --- osmosis: direct (factor once) vs warm-started PCG
    osm = Osmosis(model)
    t0 = time.perf_counter()
    osm.configure(params.with_overrides({"osmosis.solver": "direct"}))
    ms["osmosis_factor"] = (time.perf_counter() - t0) * 1e3
    ms["osmosis_direct"] = _median_ms(lambda: osm.apply(st), reps)
    osm_cg = Osmosis(model)
    osm_cg.configure(params.with_overrides({"osmosis.solver": "cg", "osmosis.tolerance": 1e-8}))
    ms["osmosis_cg"] = _median_ms(lambda: osm_cg.apply(st), reps)
    out["cg_iterations"] = osm_cg.last_iterations
    try:
        import pyamg

        ml = pyamg.smoothed_aggregation_solver(osm.A, symmetry="hermitian")
        rhs = osm.rhs.copy()
        x0 = st.particle_water / osm.M
        ms["osmosis_amg"] = _median_ms(lambda: ml.solve(rhs, x0=x0, tol=1e-8, accel="cg"), max(5, reps // 3))
    except Exception:  # pragma: no cover - pyamg optional
        pass
    best_osm = min(ms["osmosis_direct"], ms["osmosis_cg"])
    # --- shrink
    sh = Shrink(model)
    sh.configure(params)
    ms["shrink"] = _median_ms(lambda: sh.apply(st), reps)
    # --- 10 PBD iterations over distance constraints: three variants
    dyn = Dynamics(model)
    dyn.configure(params, {e: True for e in ("gravity", "pbd", "bending", "ground", "self_collision", "shrink")})
    np.divide(1e6, model.particle_cytosol + st.particle_water, out=dyn.invm)
    q = st.particle_q
    rng = np.random.default_rng(0)
    q += rng.normal(0, 0.02 * model.spacing, q.shape)
    args = (dyn.invm, model.spring_ij, st.spring_rest, dyn.salpha, dyn.slam, model.spring_colour_start, dyn.change)
    ms["pbd10_gs_serial"] = _median_ms(lambda: [kp.springs_ser(q, *args) for _ in range(10)], reps)
    ms["pbd10_gs_coloured_parallel"] = _median_ms(lambda: [kp.springs_par(q, *args) for _ in range(10)], reps)
    # Jacobi adjacency (CSR of springs per particle)
    n = model.particle_count
    ij = model.spring_ij
    inc = np.concatenate([ij[:, 0], ij[:, 1]])
    sidx = np.concatenate([np.arange(len(ij)), np.arange(len(ij))])
    sign = np.concatenate([np.ones(len(ij)), -np.ones(len(ij))])
    order = np.argsort(inc, kind="stable")
    ptr = np.concatenate([[0], np.cumsum(np.bincount(inc, minlength=n))]).astype(np.int64)
    dq = np.zeros((len(ij), 3))
    jargs = (dyn.invm, ij, st.spring_rest, dyn.salpha, dyn.slam, ptr, sidx[order].astype(np.int64), sign[order], dq)
    ms["pbd10_jacobi_parallel"] = _median_ms(lambda: [kp.jacobi_springs(q, *jargs) for _ in range(10)], reps)
    pbd_best = min(ms["pbd10_gs_serial"], ms["pbd10_gs_coloured_parallel"])
    out["pbd_choice"] = "gs_serial" if ms["pbd10_gs_serial"] <= ms["pbd10_gs_coloured_parallel"] else "gs_coloured_parallel"
    ms["full_step"] = best_osm + ms["shrink"] + pbd_best
    # --- production dynamics step (defaults: substeps × iterations, hinges, volumes, ground, self-collision)
    st2 = model.state()
    ms["dynamics_default"] = _median_ms(lambda: dyn.apply(st2), reps)
    # --- numpy reference of the same full step
    ref = NumpyStep(model, params, osm.A)
    q2, w2, r2 = model.particle_rest.copy(), st.particle_water.copy(), st.spring_rest.copy()
    ms["numpy_full_step"] = _median_ms(lambda: ref.step(q2, w2, r2), max(5, reps // 3), warm=1)
    out["speedup_vs_numpy"] = ms["numpy_full_step"] / ms["full_step"]
    return out


def run_bench(sizes=("maple", "100k"), reps: int = 30) -> dict:
    """Benchmark each named size (see :data:`SIZES`) or explicit mesh.spacing; returns a dict."""
    res = {}
    for s in sizes:
        t0 = time.perf_counter()
        model = build_bench_model(s)
        build_s = time.perf_counter() - t0
        r = bench_model(model, reps=reps if model.particle_count < 50000 else max(7, reps // 4))
        r["build_s"] = build_s
        res[str(s)] = r
    return res


def format_bench(res: dict) -> str:
    """A plain-text table of :func:`run_bench` results."""
    keys = ["osmosis_factor", "osmosis_direct", "osmosis_cg", "osmosis_amg", "shrink", "pbd10_gs_serial",
            "pbd10_gs_coloured_parallel", "pbd10_jacobi_parallel", "full_step", "numpy_full_step", "dynamics_default"]
    names = list(res)
    lines = ["stage (median ms)".ljust(30) + "".join(n.rjust(14) for n in names)]
    lines.append("particles / springs".ljust(30) + "".join(f"{res[n]['particles']}/{res[n]['springs']}".rjust(14) for n in names))
    for k in keys:
        lines.append(k.ljust(30) + "".join((f"{res[n]['ms'][k]:.3f}" if k in res[n]["ms"] else "-").rjust(14) for n in names))
    lines.append("speed-up vs numpy".ljust(30) + "".join(f"{res[n]['speedup_vs_numpy']:.1f}x".rjust(14) for n in names))
    lines.append("cg iterations".ljust(30) + "".join(str(res[n]["cg_iterations"]).rjust(14) for n in names))
    lines.append("PBD choice".ljust(30) + "".join(res[n]["pbd_choice"].rjust(14) for n in names))
    return "\n".join(lines)


if __name__ == "__main__":  # pragma: no cover
    import sys

    sizes = tuple(sys.argv[1:]) or ("maple", "100k")
    print(format_bench(run_bench(sizes)))
