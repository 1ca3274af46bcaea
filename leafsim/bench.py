"""Performance benchmark (``leafsim bench`` / ``python -m leafsim.bench [--quick] [--json]``):
median ms per stage and per full step.

A *full step* is what the thesis ran per frame: osmosis + shrink + 10 PBD iterations over all
distance constraints (both layers and links).  Every PBD variant is timed (fused serial
Gauss–Seidel: all 10 passes in one numba call; graph-coloured parallel Gauss–Seidel: same,
prange per colour; atomics-free parallel Jacobi), the full step is timed as one sequence with
the faster variant, next to a vectorised-numpy implementation of the same step (per stage and
whole) in the same run, next to the default production dynamics step (5 substeps × 2
iterations with bending hinges, thickness constraints, ground and self-collision; one numba
call per frame), and next to the colour-only step (pigments + RGB).  numba caches are warmed
before timing; medians of many repetitions (the machine is shared and noisy).

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
        self.rate = np.where(model.particle_layer == LAYER_V, params["osmosis.evaporation_top"], params["osmosis.evaporation_bottom"])
        self.dt = params["dynamics.dt"]
        n = model.particle_count
        self.deg = np.bincount(model.spring_ij.ravel(), minlength=n).astype(float)

    def osmosis(self, w):
        m = self.m
        M = m.particle_cytosol
        c = w / M
        loss = np.minimum(self.rate * self.dt * m.particle_area, w)
        cn = self.lu.solve(M * c - loss)
        w[:] = np.maximum(cn, 0) * M

    def shrink(self, w, rest):
        m = self.m
        M = m.particle_cytosol
        i, j = m.spring_ij[:, 0], m.spring_ij[:, 1]
        mass = M + w
        v = (mass[i] + mass[j]) / (m.particle_mass0[i] + m.particle_mass0[j])
        rest[:] = m.spring_rest0 * np.clip(1 - self.sigma * np.clip(1 - v, 0, None), self.l_min, 1)

    def pbd(self, q, w, rest, iterations=10):
        m = self.m
        i, j = m.spring_ij[:, 0], m.spring_ij[:, 1]
        invm = 1.0 / (m.particle_cytosol + w)
        wi, wj = invm[i], invm[j]
        n = len(q)
        for _ in range(iterations):
            d = q[i] - q[j]
            ln = np.sqrt((d * d).sum(1))
            f = ((rest - ln) / np.maximum(ln, 1e-12) / (wi + wj))[:, None] * d
            for k in range(3):
                q[:, k] += 1.5 * (np.bincount(i, f[:, k] * wi, n) - np.bincount(j, f[:, k] * wj, n)) / np.maximum(self.deg, 1)

    def step(self, q, w, rest):
        self.osmosis(w)
        self.shrink(w, rest)
        self.pbd(q, w, rest)


def _colour_step_fn(model: Model, params: ParamSet):
    """One colour-only frame (``effects.colour`` alone): pigments aged by one Δt and converted
    to linear RGB for every particle."""
    from .sim import colour as kc

    pig = kc.init_pigments(model.particle_count, params, seed=0, rest_relative_mass=model.areal_mass0)
    w = np.linspace(0.3, 1.0, model.particle_count).astype(np.float32)
    dt = params["dynamics.dt"]
    clock = [0.3]

    def step():
        clock[0] += params["colour.age_rate"] * dt
        kc.step_pigments(pig, w, clock[0], dt, params)
        kc.pigments_to_rgb(pig, params)

    return step


def bench_model(model: Model, reps: int = 30, params: ParamSet | None = None, jacobi: bool = True) -> dict:
    """Time every stage on one model; returns a dict of medians (ms) and counts."""
    from .sim.effects import PARALLEL_MIN_PARTICLES, Dynamics, Osmosis, Shrink
    from .sim.kernels import pbd as kp

    params = params or ParamSet()
    out = {"particles": model.particle_count, "springs": model.spring_count, "ms": {}}
    ms = out["ms"]
    st = model.state()
    st.particle_water[:] *= np.linspace(0.6, 1.0, model.particle_count)
    # --- osmosis: direct (factor once, fused numba triangular solves) vs warm-started PCG
    osm = Osmosis(model)
    t0 = time.perf_counter()
    osm.configure(params.with_overrides({"osmosis.solver": "direct"}))
    ms["osmosis_factor"] = (time.perf_counter() - t0) * 1e3
    ms["osmosis_direct"] = _median_ms(lambda: osm.apply(st), reps)
    osm_cg = Osmosis(model)
    osm_cg.configure(params.with_overrides({"osmosis.solver": "cg", "osmosis.tolerance": 1e-8}))
    ms["osmosis_cg"] = _median_ms(lambda: osm_cg.apply(st), max(5, reps // 3))
    out["cg_iterations"] = osm_cg.last_iterations
    best_osm = osm if ms["osmosis_direct"] <= ms["osmosis_cg"] else osm_cg
    # --- shrink
    sh = Shrink(model)
    sh.configure(params)
    ms["shrink"] = _median_ms(lambda: sh.apply(st), reps)
    # --- 10 PBD iterations over distance constraints: fused serial / coloured parallel / Jacobi
    dyn = Dynamics(model)
    dyn.configure(params, {e: True for e in ("gravity", "pbd", "bending", "ground", "self_collision", "shrink")})
    np.divide(1.0, model.particle_cytosol + st.particle_water, out=dyn.invm)
    q = st.particle_q
    rng = np.random.default_rng(0)
    q += rng.normal(0, 0.02 * model.spacing, q.shape)
    base = (dyn.invm, model.spring_ij, st.spring_rest, dyn.salpha, dyn.slam, model.spring_colour_start)
    ser = lambda: kp.springs_multi_ser(q, *base, 10, 0.0)  # noqa: E731
    par = lambda: kp.springs_multi_par(q, *base, dyn.change, 10, 0.0)  # noqa: E731
    ms["pbd10_gs_serial"] = _median_ms(ser, reps)
    ms["pbd10_gs_coloured_parallel"] = _median_ms(par, reps)
    if jacobi:
        n = model.particle_count
        ij = model.spring_ij
        inc = np.concatenate([ij[:, 0], ij[:, 1]])
        sidx = np.concatenate([np.arange(len(ij)), np.arange(len(ij))])
        sign = np.concatenate([np.ones(len(ij)), -np.ones(len(ij))])
        order = np.argsort(inc, kind="stable")
        ptr = np.concatenate([[0], np.cumsum(np.bincount(inc, minlength=n))]).astype(np.int64)
        dq = np.zeros((len(ij), 3))
        jargs = (dyn.invm, ij, st.spring_rest, dyn.salpha, dyn.slam, ptr, sidx[order].astype(np.int64), sign[order], dq)
        ms["pbd10_jacobi_parallel"] = _median_ms(lambda: [kp.jacobi_springs(q, *jargs) for _ in range(10)], max(5, reps // 3))
    use_par = ms["pbd10_gs_coloured_parallel"] < ms["pbd10_gs_serial"]
    out["pbd_choice"] = "gs_coloured_parallel" if use_par else "gs_serial"
    out["production_pbd"] = "timed ser|par" if model.particle_count >= PARALLEL_MIN_PARTICLES else "gs_serial"
    pbd = par if use_par else ser
    ms["pbd10"] = ms["pbd10_gs_coloured_parallel"] if use_par else ms["pbd10_gs_serial"]

    def full():
        best_osm.apply(st)
        sh.apply(st)
        np.divide(1.0, model.particle_cytosol + st.particle_water, out=dyn.invm)
        pbd()

    ms["full_step"] = _median_ms(full, reps)
    # --- production dynamics step (defaults: substeps × iterations, hinges, volumes, ground, self-collision)
    st2 = model.state()
    ms["dynamics_default"] = _median_ms(lambda: dyn.apply(st2), reps)
    out["dynamics_iterations"] = dyn.last_iterations
    # --- colour-only step (pigment aging + RGB)
    ms["colour_step"] = _median_ms(_colour_step_fn(model, params), max(reps, 50))
    # --- numpy reference of the same full step, per stage and whole
    ref = NumpyStep(model, params, osm.A)
    q2, w2, r2 = model.particle_rest.copy(), st.particle_water.copy(), st.spring_rest.copy()
    nr = max(5, reps // 3)
    np_ms = out["numpy_ms"] = {}
    np_ms["osmosis_direct"] = _median_ms(lambda: ref.osmosis(w2), nr, warm=1)
    np_ms["shrink"] = _median_ms(lambda: ref.shrink(w2, r2), nr, warm=1)
    np_ms["pbd10"] = _median_ms(lambda: ref.pbd(q2, w2, r2), nr, warm=1)
    np_ms["full_step"] = ms["numpy_full_step"] = _median_ms(lambda: ref.step(q2, w2, r2), nr, warm=1)
    out["speedup_vs_numpy"] = ms["numpy_full_step"] / ms["full_step"]
    out["colour_vs_full"] = ms["full_step"] / ms["colour_step"]
    return out


def run_bench(sizes=("maple", "100k"), reps: int = 30, jacobi: bool = True) -> dict:
    """Benchmark each named size (see :data:`SIZES`) or explicit mesh.spacing; returns a dict."""
    res = {}
    for s in sizes:
        t0 = time.perf_counter()
        model = build_bench_model(s)
        build_s = time.perf_counter() - t0
        r = bench_model(model, reps=reps if model.particle_count < 50000 else max(7, reps // 4), jacobi=jacobi)
        r["build_s"] = build_s
        res[str(s)] = r
    return res


#: (key, label) rows of the table; rows with a numpy reference get baseline and ratio columns
ROWS = [
    ("osmosis_factor", "osmosis factor (once)"),
    ("osmosis_direct", "osmosis direct solve"),
    ("osmosis_cg", "osmosis PCG"),
    ("shrink", "shrink"),
    ("pbd10_gs_serial", "PBD 10 passes GS serial"),
    ("pbd10_gs_coloured_parallel", "PBD 10 passes GS coloured par"),
    ("pbd10_jacobi_parallel", "PBD 10 passes Jacobi par"),
    ("pbd10", "PBD 10 passes (best)"),
    ("full_step", "full step (osm+shrink+10 PBD)"),
    ("dynamics_default", "dynamics default (GUI frame)"),
    ("colour_step", "colour-only step"),
]


def format_bench(res: dict) -> str:
    """A plain-text table of :func:`run_bench` results: stage, ms per size, numpy baseline
    per size and the speed-up ratio numpy / leafsim per size."""
    names = list(res)
    w0, w = 32, 11
    hdr = "stage".ljust(w0) + "".join(f"{n} ms".rjust(w) for n in names)
    hdr += "".join(f"numpy {n}".rjust(w + 2) for n in names) + "".join(f"ratio {n}".rjust(w + 1) for n in names)
    lines = [hdr, "-" * len(hdr)]
    lines.append("particles / springs".ljust(w0) + "  ".join(f"{res[n]['particles']}/{res[n]['springs']}" for n in names))
    for k, label in ROWS:
        if not any(k in res[n]["ms"] for n in names):
            continue
        row = label.ljust(w0)
        row += "".join((f"{res[n]['ms'][k]:.3f}" if k in res[n]["ms"] else "-").rjust(w) for n in names)
        row += "".join((f"{res[n]['numpy_ms'][k]:.3f}" if k in res[n].get("numpy_ms", {}) else "").rjust(w + 2) for n in names)
        row += "".join((f"{res[n]['numpy_ms'][k] / res[n]['ms'][k]:.1f}x" if k in res[n].get("numpy_ms", {}) else "").rjust(w + 1)
                       for n in names)
        lines.append(row.rstrip())
    lines.append("")
    for n in names:
        r = res[n]
        lines.append(f"[{n}] full step {r['ms']['full_step']:.3f} ms = {r['speedup_vs_numpy']:.1f}x numpy; colour-only step "
                     f"{r['ms']['colour_step']:.3f} ms, {r['colour_vs_full']:.1f}x cheaper than the full step; "
                     f"PBD choice {r['pbd_choice']} (production {r['production_pbd']}); cg iterations {r['cg_iterations']}")
    return "\n".join(lines)


def main(json_out: bool = False, quick: bool = False) -> int:
    """CLI entry (``leafsim bench``): ``quick`` = maple size only with few repetitions (well
    under a minute); otherwise maple and 100k (a few minutes).  Prints the table, or the raw
    result dict as JSON with ``json_out``.  Returns the exit status."""
    import json

    if quick:
        res = run_bench(("maple",), reps=15, jacobi=False)
    else:
        res = run_bench(("maple", "100k"), reps=40)
    if json_out:
        print(json.dumps(res, indent=1, sort_keys=True))
    else:
        print(format_bench(res))
    return 0


if __name__ == "__main__":  # pragma: no cover
    import sys

    argv = sys.argv[1:]
    flags = {a for a in argv if a.startswith("--")}
    sizes = tuple(a for a in argv if not a.startswith("--"))
    if sizes:
        res = run_bench(sizes)
        if "--json" in flags:
            import json

            print(json.dumps(res, indent=1, sort_keys=True))
        else:
            print(format_bench(res))
    else:
        sys.exit(main(json_out="--json" in flags, quick="--quick" in flags))
