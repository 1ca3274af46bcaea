"""Performance benchmark (``leafsim bench [--quick] [--json]``, ``python -m leafsim.measure.bench``).

Three parts, each timed *interleaved*: one repetition of every contender per round, many
rounds, median and 90th percentile — the machine is shared, so contenders timed one after
another would each see a different load.

1. **Spring race**: 10 XPBD passes over the blade's own distance constraints, by our
   production kernel (float64, serial), the float32 *ceiling* (the same kernel compiled for
   float32 positions, int32 indices and float32 records), the former graph-coloured parallel
   kernel (one fork/join per colour), a two-block domain split (one fork/join per pass),
   vectorised-numpy Jacobi and — when installed (``pip install -e ".[peers]"``) — warp and
   Taichi on the CPU.  Every row reports the constraint residual max |C|/l after the passes
   (a kernel that does nothing cannot win) and how far its positions are from ours.
2. **Frame**: the production dynamics frame (``dynamics.*`` defaults, but 20 substeps at every
   size, :data:`BENCH_SETTINGS`; ≤ 2 iterations, hinges, thickness, ground, self-collision) on a flat leaf at rest and on a folded leaf in
   self-contact, each with and without self-collision (the contact share); the per-kind cost
   of one pass (ns per spring, hinge, volume); osmosis, shrink and the colour-only step.
3. **Parallel vs serial**: every parallel kernel against its serial twin on a quiet machine
   and with one CPU-bound process per core running (:func:`parallel_vs_serial`), p90 ratios.
4. **Memory**: bytes per particle of the model, state and solver arrays, and the peak RSS.

Example
-------
>>> print(format_bench(run_bench(sizes=("maple",))))    # doctest: +SKIP
"""

from __future__ import annotations

import os
import resource
import time

import numpy as np

from leafsim.appearance.reflectance import pigments_to_rgb
from leafsim.config.params import ParamSet
from leafsim.sim.model import Model
from leafsim.sim.pigments import init_pigments, step_pigments

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


# ----------------------------------------------------------------------------- timing
def interleaved(jobs: dict, rounds: int, warm: int = 1) -> dict:
    """Time ``jobs`` (name → (reset, run); ``reset`` untimed) round-robin: one run of each per
    round.  Returns name → list of ms."""
    for _ in range(warm):
        for reset, run in jobs.values():
            reset()
            run()
    out = {k: [] for k in jobs}
    for _ in range(rounds):
        for k, (reset, run) in jobs.items():
            reset()
            t0 = time.perf_counter()
            run()
            out[k].append((time.perf_counter() - t0) * 1e3)
    return out


def _stats(ms) -> dict:
    return {"median_ms": float(np.median(ms)), "p90_ms": float(np.percentile(ms, 90)), "rounds": len(ms)}


def _load() -> float:
    return float(os.getloadavg()[0])


def _nothing():
    return None


# ----------------------------------------------------------------------------- spring race
class SpringProblem:
    """The race's job on one model: perturbed positions (2 % of the spacing) of the rest leaf,
    the fresh leaf's inverse masses and the default compliances, springs in production order."""

    def __init__(self, model: Model, params: ParamSet | None = None):
        from leafsim.sim.effects.dynamics import Dynamics
        from leafsim.sim.kernels import pbd as kp

        params = params or bench_params(model)
        self.model = model
        d = Dynamics(model)
        d.configure(params, EFFECTS)
        st = model.state()
        d.gather(st)
        self.ij = d.sij
        self.rec = d.srec.copy()
        self.rest = self.rec[:, 0].copy()
        self.cs = model.spring_colour_start
        rng = np.random.default_rng(0)
        self.q0 = st.particle_q + rng.normal(0, 0.02 * model.spacing, st.particle_q.shape)
        self.residual0 = float(kp.residual(self.q0, self.ij, self.rest))

    def residual(self, q) -> float:
        from leafsim.sim.kernels import pbd as kp

        return float(kp.residual(np.ascontiguousarray(q, np.float64), self.ij, self.rest))


class _Kernel:
    """A numba contender: positions/lambdas of ``dtype`` reset from the problem; ``fn(q, lam)``."""

    def __init__(self, prob: SpringProblem, fn, dtype=np.float64):
        self.q0 = prob.q0.astype(dtype)
        self.q = self.q0.copy()
        self.lam = np.zeros(len(prob.ij), dtype)
        self.fn = fn

    def reset(self):
        self.q[:] = self.q0
        self.lam[:] = 0.0

    def run(self, npass=PASSES):
        self.fn(self.q, self.lam)

    def positions(self):
        return self.q.astype(np.float64)


class _NumpyJacobi:
    """Vectorised numpy: Jacobi passes with bincount gathers, relaxation 1.5 / degree."""

    def __init__(self, prob: SpringProblem):
        self.prob = prob
        n = len(prob.q0)
        self.i, self.j = prob.ij[:, 0].astype(np.int64), prob.ij[:, 1].astype(np.int64)
        self.deg = np.maximum(np.bincount(np.r_[self.i, self.j], minlength=n), 1).astype(float)
        self.q = prob.q0.copy()

    def reset(self):
        self.q[:] = self.prob.q0

    def run(self, npass=PASSES):
        r, i, j, q, n = self.prob.rec, self.i, self.j, self.q, len(self.q)
        for _ in range(npass):
            d = q[i] - q[j]
            ln = np.sqrt((d * d).sum(1))
            f = ((r[:, 0] - ln) * r[:, 2] / np.maximum(ln, 1e-12))[:, None] * d
            for k in range(3):
                q[:, k] += 1.5 * (np.bincount(i, f[:, k] * r[:, 3], n) - np.bincount(j, f[:, k] * r[:, 4], n)) / self.deg

    def positions(self):
        return self.q


def spring_contenders(prob: SpringProblem, peers: bool = True, numpy: bool = True, parallel: bool = True) -> dict:
    """name → contender (reset(), run(), positions()).  The first is ours (production)."""
    from leafsim.measure import contenders as kc
    from leafsim.sim.kernels import pbd as kp

    ij, rec, cs = prob.ij, prob.rec, prob.cs
    ij32, rec32 = ij.astype(np.int32), rec.astype(np.float32)
    perm, bs = kc.block_order(ij, prob.model.particle_rest)
    bij, brec = np.ascontiguousarray(ij[perm]), np.ascontiguousarray(rec[perm])
    out = {
        "ours (f64, serial)": _Kernel(prob, lambda q, lam: kp.springs_passes(q, ij, rec, lam, PASSES, 0.0)),
        "ceiling (f32, serial)": _Kernel(prob, lambda q, lam: kp.springs_passes(q, ij32, rec32, lam, PASSES, 0.0),
                                         np.float32),
    }
    if parallel:
        out["coloured parallel (before)"] = _Kernel(prob, lambda q, lam: kc.coloured_passes(q, ij, rec, lam, cs, 2, PASSES))
        out["2-block parallel"] = _Kernel(prob, lambda q, lam: kc.block_passes(q, bij, brec, lam, bs, PASSES))
    if numpy:
        out["numpy Jacobi"] = _NumpyJacobi(prob)
    if peers:
        from leafsim.measure.peers import available

        for name, Peer in available().items():
            out[name] = _PeerAdapter(Peer(prob.q0, ij, rec, cs))
    return out


class _PeerAdapter:
    def __init__(self, peer):
        self.peer = peer
        self.reset = peer.reset
        self.positions = peer.positions

    def run(self, npass=PASSES):
        self.peer.run(npass)


def spring_race(model: Model, rounds: int = 30, peers: bool = True, numpy: bool = True, parallel: bool = True) -> list[dict]:
    """Race every contender on ``model``'s springs; rows with median/p90 ms, ratio to ours,
    ns per spring, the residual after the passes and the largest distance of its positions
    from ours (in mesh spacings)."""
    prob = SpringProblem(model)
    cons = spring_contenders(prob, peers, numpy, parallel)
    load = _load()
    times = interleaved({k: (c.reset, c.run) for k, c in cons.items()}, rounds)
    ours = next(iter(cons))
    for c in cons.values():
        c.reset()
        c.run()
    q_ours = cons[ours].positions()
    rows = []
    for k, c in cons.items():
        q = c.positions()
        rows.append({"contender": k, **_stats(times[k]), "residual0": prob.residual0, "residual": prob.residual(q),
                     "agree": float(np.abs(q - q_ours).max() / model.spacing),
                     "ns_per_spring": float(np.median(times[k])) * 1e6 / PASSES / model.spring_count})
    base = rows[0]["median_ms"]
    for r in rows:
        r["ratio"] = r["median_ms"] / base
        r["load"] = load
    return rows


# ----------------------------------------------------------------------------- parallel vs serial
class _Busy:
    """``n`` processes spinning on the CPU while the block runs: the bench's own, reproducible
    "machine under load" (the project's machines are shared; a parallel path must not lose
    when another job holds a core)."""

    def __init__(self, n: int):
        self.n, self.procs = n, []

    def __enter__(self):
        import subprocess
        import sys

        try:
            for _ in range(self.n):
                self.procs.append(subprocess.Popen([sys.executable, "-c", "while True: pass"]))
            time.sleep(0.3)
        except BaseException:  # a failed start or Ctrl-C: no burner outlives the bench
            self.__exit__()
            raise
        return self

    def __exit__(self, *exc):
        for p in self.procs:
            p.kill()
        for p in self.procs:
            p.wait()
        self.procs = []
        return False


def parallel_vs_serial(model: Model, rounds: int = 30, busy: int | None = None) -> list[dict]:
    """Every parallel kernel against its serial twin, interleaved, on a quiet machine and with
    ``busy`` CPU-bound processes running (default: one per core): 10 spring passes (the
    coloured fork/join per colour and the 2-block domain split against the serial sweep) and
    the shrink step (``prange`` over springs against the serial loop).  Rows: job, load,
    median / p90 ms, and p90 ÷ the serial twin's p90 (load: the 1-minute load average at the
    end of the block, which lags the burners)."""
    from leafsim.sim.effects.shrink import Shrink
    from leafsim.sim.kernels import shrink as ks

    prob = SpringProblem(model)
    cons = spring_contenders(prob, peers=False, numpy=False, parallel=True)
    cons.pop("ceiling (f32, serial)")
    st = model.state()
    st.particle_water[:] *= np.linspace(0.6, 1.0, model.particle_count)
    sh = Shrink(model)
    sh.configure(bench_params(model))
    m = model

    def shrink(fn):
        return lambda: fn(m.spring_ij, m.spring_rest0, sh.sigma, sh.alpha, sh.l_min, m.particle_cytosol,
                          st.particle_water, m.particle_mass0, st.spring_rest)

    jobs = {f"springs ×10: {k}": (c.reset, c.run) for k, c in cons.items()}
    jobs["shrink: serial"] = (_nothing, shrink(ks.shrink_springs))
    jobs["shrink: parallel (prange)"] = (_nothing, shrink(ks.shrink_springs_par))
    twin = {k: ("springs ×10: ours (f64, serial)" if k.startswith("springs") else "shrink: serial") for k in jobs}
    busy = (os.cpu_count() or 2) if busy is None else busy
    rows = []
    for n_busy in (0, busy):
        if n_busy:
            with _Busy(n_busy):
                ms = interleaved(jobs, rounds)
                load = _load()
        else:
            ms = interleaved(jobs, rounds)
            load = _load()
        st_ = {k: _stats(v) for k, v in ms.items()}
        for k, v in st_.items():
            rows.append({"job": k, "busy": n_busy, "load": load, **v,
                         "p90_vs_serial": v["p90_ms"] / st_[twin[k]]["p90_ms"]})
    return rows


# ----------------------------------------------------------------------------- frame
def _frame_job(model, params, effects, state_fn):
    """(reset, run, dynamics) of one production frame on the state ``state_fn()`` (reset to
    that state before every repetition when it is a fixed snapshot)."""
    from leafsim.sim.effects.dynamics import Dynamics

    d = Dynamics(model)
    d.configure(params, effects)
    snap = state_fn()
    st = snap.copy()

    def reset():
        for a, b in ((st.particle_q, snap.particle_q), (st.particle_qd, snap.particle_qd)):
            a[:] = b

    return reset, lambda: d.apply(st), d


def _pass_jobs(model, params):
    """10 passes of each constraint kind on a perturbed folded leaf: the production kernels
    (springs one at a time, hinges and volumes in SIMD blocks) and the one-at-a-time hinge and
    volume kernels they replaced (bit-identical results)."""
    from leafsim.sim.effects.dynamics import Dynamics
    from leafsim.sim.kernels import blocked as kb
    from leafsim.sim.kernels import pbd as kp

    d = Dynamics(model)
    d.configure(params, EFFECTS)
    st = folded_state(model)
    d.gather(st)
    q0 = st.particle_q + np.random.default_rng(3).normal(0, 0.02 * model.spacing, st.particle_q.shape)
    q = q0.copy()
    S, H, V = model.spring_count, model.hinge_count, model.vol_count

    def reset():
        q[:] = q0
        d.slam[:] = 0.0
        d.hlam[:] = 0.0

    def passes(one):
        def run():
            for _ in range(PASSES):
                one()
        return run

    return {"springs ×10": (reset, passes(lambda: kp.spring_pass(q, d.sij, d.srec, d.slam, 0, S))),
            "hinges ×10": (reset, passes(lambda: kb.hinges_blocked(q, d.hidx, d.hrec, d.hlam, 1.0, d.hblocks, d.blockbuf))),
            "volumes ×10": (reset, passes(lambda: kb.volumes_blocked(q, d.vidx, d.vrec, d.vblocks, d.blockbuf))),
            "hinges ×10, one at a time": (reset, passes(
                lambda: kp.hinge_pass(q, d.invm, d.hidx, d.hrest, d.halpha, d.hlam, 1.0, 0, H))),
            "volumes ×10, one at a time": (reset, passes(lambda: kp.volume_pass(q, d.invm, d.vidx, d.vrest, 0, V)))}


def _stage_jobs(model, params):
    from leafsim.sim.effects.shrink import Shrink
    from leafsim.sim.effects.osmosis import Osmosis

    st = model.state()
    st.particle_water[:] *= np.linspace(0.6, 1.0, model.particle_count)
    osm = Osmosis(model)
    osm.configure(params)
    sh = Shrink(model)
    sh.configure(params)
    return {"osmosis": (_nothing, lambda: osm.apply(st)), "shrink": (_nothing, lambda: sh.apply(st)),
            "colour step": (_nothing, _colour_step_fn(model, params))}


def frame_bench(model: Model, rounds: int = 20, params: ParamSet | None = None) -> dict:
    """Interleaved production frames (flat / folded leaf, with and without self-collision),
    per-kind passes and the other stages; returns stats per job and the derived ratios."""
    params = params or bench_params(model)
    noself = {**EFFECTS, "self_collision": False}
    jobs, dyn = {}, {}
    for name, eff, sfn in (("frame", EFFECTS, model.state), ("frame, no self-collision", noself, model.state),
                           ("frame folded", EFFECTS, lambda: folded_state(model)),
                           ("frame folded, no self-collision", noself, lambda: folded_state(model))):
        reset, run, d = _frame_job(model, params, eff, sfn)
        if sfn is model.state:
            reset = _nothing  # the flat leaf keeps lying on the ground: no reset needed
        jobs[name], dyn[name] = (reset, run), d
    jobs.update(_pass_jobs(model, params))
    jobs.update(_stage_jobs(model, params))
    load = _load()
    ms = {k: _stats(v) for k, v in interleaved(jobs, rounds).items()}
    med = {k: v["median_ms"] for k, v in ms.items()}
    ns = {k: med[job] * 1e6 / PASSES / c for k, job, c in
          (("spring", "springs ×10", model.spring_count), ("hinge", "hinges ×10", model.hinge_count),
           ("volume", "volumes ×10", model.vol_count),
           ("hinge, one at a time", "hinges ×10, one at a time", model.hinge_count),
           ("volume, one at a time", "volumes ×10, one at a time", model.vol_count))}
    d = dyn["frame"]
    return {"ms": ms, "load": load, "ns_per": ns, "hinge_vs_spring": ns["hinge"] / ns["spring"],
            "volume_vs_spring": ns["volume"] / ns["spring"],
            "hinge_vs_spring_one_at_a_time": ns["hinge, one at a time"] / ns["spring"],
            "volume_vs_spring_one_at_a_time": ns["volume, one at a time"] / ns["spring"],
            "contact_share": max(0.0, 1.0 - med["frame, no self-collision"] / med["frame"]),
            "contact_share_folded": max(0.0, 1.0 - med["frame folded, no self-collision"] / med["frame folded"]),
            "contact_searches": d.contact_searches, "substeps": d.substeps, "iterations": d.iters,
            "full_step_ms": med["osmosis"] + med["shrink"] + med["frame"]}


def bench_colour(n: int = 5700, steps: int = 2000, params: ParamSet | None = None) -> float:
    """Median µs of one :func:`step_pigments` call on ``n`` particles (drying, senescing leaf)."""
    if params is None:
        params = ParamSet()
    pig = init_pigments(n, params, seed=0)
    rng = np.random.default_rng(0)
    w = rng.uniform(0.2, 1.0, n).astype(np.float32)
    dt = 0.002
    step_pigments(pig, w, 0.3, dt, params)  # compile / warm up
    times = np.empty(steps)
    age = 0.3
    for s in range(steps):
        age += 1e-4
        t0 = time.perf_counter()
        step_pigments(pig, w, age, dt, params)
        times[s] = time.perf_counter() - t0
    return float(np.median(times) * 1e6)


def _colour_step_fn(model: Model, params: ParamSet):
    """One colour-only frame (``effects.colour`` alone): pigments aged by one Δt and converted
    to linear RGB for every particle."""
    from leafsim.sim import pigments as kc

    pig = kc.init_pigments(model.particle_count, params, seed=0, rest_relative_mass=model.areal_mass0)
    w = np.linspace(0.3, 1.0, model.particle_count).astype(np.float32)
    dt = params["dynamics.dt"]
    clock = [0.3]

    def step():
        clock[0] += params["colour.age_rate"] * dt
        kc.step_pigments(pig, w, clock[0], dt, params)
        pigments_to_rgb(pig, params)

    return step


# ----------------------------------------------------------------------------- memory
def memory(model: Model, params: ParamSet | None = None) -> dict:
    """Bytes per particle of the model, one state and the stages' arrays (dynamics, osmosis
    with its factors, shrink), and this process's peak RSS so far."""
    from leafsim.sim.simulator import Simulator

    sim = Simulator(model, params or bench_params(model), watchdog=False)
    st = sim.state()
    sim.step(st)
    n = model.particle_count
    parts = {"model": _nbytes(model), "state": _nbytes(st), "dynamics": _nbytes(sim._dynamics),
             "osmosis": _nbytes(sim._osmosis), "shrink": _nbytes(sim._shrink)}
    return {"bytes_per_particle": {k: v / n for k, v in parts.items()},
            "bytes_per_particle_total": sum(parts.values()) / n,
            "peak_rss_mb": peak_rss_mb()}


def peak_rss_mb() -> float:
    """This process's peak resident memory [MB]: the kernel's high-water mark of its address
    space (VmHWM), which starts afresh at exec.  (``ru_maxrss`` does not on Linux: a process
    started by a 1 GB bench inherits the 1 GB as its 'peak'.)  ``ru_maxrss`` where /proc is
    missing."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return float(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _nbytes(obj, seen=None) -> int:
    """Bytes of the numpy arrays and scipy sparse matrices an object holds (one level of
    tuples/lists, no double counting)."""
    import scipy.sparse as sp

    seen = set() if seen is None else seen
    vals = obj if isinstance(obj, (tuple, list)) else (vars(obj).values() if hasattr(obj, "__dict__") else
                                                       [getattr(obj, f) for f in getattr(obj, "__dataclass_fields__", {})])
    total = 0
    for v in vals:
        if id(v) in seen:
            continue
        seen.add(id(v))
        if isinstance(v, np.ndarray):
            total += v.nbytes
        elif sp.issparse(v):
            total += sum(getattr(v, a).nbytes for a in ("data", "indices", "indptr") if hasattr(v, a))
        elif isinstance(v, (tuple, list)):
            total += _nbytes(v, seen)
    return total


def memory_subprocess(size: str) -> dict:
    """:func:`memory` of a fresh process that builds only ``size`` (a clean peak RSS)."""
    import json
    import subprocess
    import sys

    code = ("import json, resource; from leafsim.measure.bench import build_bench_model, memory; "
            "from leafsim.measure.bench import peak_rss_mb; r0 = peak_rss_mb(); "
            f"m = build_bench_model({size!r}); r = memory(m); r['rss_after_imports_mb'] = r0; print(json.dumps(r))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


# ----------------------------------------------------------------------------- driver
def run_bench(sizes=("maple", "100k"), rounds: int = 30, peers: bool = True, mem: bool = True,
              parallel: bool = True) -> dict:
    """Benchmark each named size (see :data:`SIZES`) or explicit mesh.spacing; returns a dict."""
    res = {}
    for s in sizes:
        t0 = time.perf_counter()
        model = build_bench_model(s)
        build_s = time.perf_counter() - t0
        big = model.particle_count >= 50000
        r = {"particles": model.particle_count, "springs": model.spring_count, "hinges": model.hinge_count,
             "volumes": model.vol_count, "build_s": build_s}
        r["race"] = spring_race(model, rounds=max(7, rounds // 3) if big else rounds, peers=peers, parallel=parallel)
        r["frame"] = frame_bench(model, rounds=max(5, rounds // 6) if big else rounds)
        if parallel:
            r["parallel"] = parallel_vs_serial(model, rounds=max(7, rounds // 3) if big else rounds)
        if mem:
            r["memory"] = memory_subprocess(s) if big else memory(model)
        res[str(s)] = r
    return res


def format_bench(res: dict) -> str:
    """Plain-text tables of :func:`run_bench` results."""
    lines = []
    for name, r in res.items():
        lines.append(f"[{name}] {r['particles']} particles, {r['springs']} springs, {r['hinges']} hinges, "
                     f"{r['volumes']} volumes")
        lines.append(f"  spring race, {PASSES} passes (1-min load {r['race'][0]['load']:.1f}):")
        lines.append(f"  {'contender':28s} {'median ms':>10s} {'p90 ms':>9s} {'ratio':>6s} {'ns/spring':>9s} "
                     f"{'residual':>9s} {'Δq / r':>8s}")
        for row in r["race"]:
            lines.append(f"  {row['contender']:28s} {row['median_ms']:10.3f} {row['p90_ms']:9.3f} {row['ratio']:6.2f} "
                         f"{row['ns_per_spring']:9.2f} {row['residual']:9.2e} {row['agree']:8.1e}")
        lines.append(f"  (residual before the passes {r['race'][0]['residual0']:.2e})")
        if "parallel" in r:
            lines.append(f"  parallel vs serial, quiet and with {max(x['busy'] for x in r['parallel'])} busy processes:")
            lines.append(f"  {'job':44s} {'busy':>4s} {'load':>5s} {'median ms':>10s} {'p90 ms':>9s} {'p90 ÷ serial':>12s}")
            for x in r["parallel"]:
                lines.append(f"  {x['job']:44s} {x['busy']:4d} {x['load']:5.1f} {x['median_ms']:10.3f} {x['p90_ms']:9.3f} "
                             f"{x['p90_vs_serial']:12.2f}")
        f = r["frame"]
        lines.append(f"  frame ({f['substeps']} substeps × ≤ {f['iterations']} iterations; 1-min load {f['load']:.1f}):")
        for k, v in f["ms"].items():
            lines.append(f"  {k:34s} {v['median_ms']:9.3f} ms  p90 {v['p90_ms']:9.3f}")
        lines.append(f"  ns per spring / hinge / volume: {f['ns_per']['spring']:.1f} / {f['ns_per']['hinge']:.1f} / "
                     f"{f['ns_per']['volume']:.1f}; hinge {f['hinge_vs_spring']:.2f}× a spring, volume "
                     f"{f['volume_vs_spring']:.2f}× (one at a time: {f['ns_per']['hinge, one at a time']:.1f} / "
                     f"{f['ns_per']['volume, one at a time']:.1f} ns, {f['hinge_vs_spring_one_at_a_time']:.2f}× / "
                     f"{f['volume_vs_spring_one_at_a_time']:.2f}×)")
        lines.append(f"  self-collision share of a frame: flat {100 * f['contact_share']:.1f} %, folded "
                     f"{100 * f['contact_share_folded']:.1f} %; full step (osmosis + shrink + frame) "
                     f"{f['full_step_ms']:.2f} ms")
        if "memory" in r:
            m = r["memory"]
            lines.append(f"  memory: {m['bytes_per_particle_total']:.0f} B per particle "
                         + ", ".join(f"{k} {v:.0f}" for k, v in m["bytes_per_particle"].items())
                         + f"; peak RSS {m['peak_rss_mb']:.0f} MB")
        lines.append("")
    return "\n".join(lines)


def _c_flush() -> None:
    """fflush(NULL): write out the C library's stdio buffers (text a C extension printf'd)."""
    import ctypes

    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):  # no C library handle on this platform: nothing to flush
        pass


def main(json_out: bool = False, quick: bool = False) -> int:
    """CLI entry (``leafsim bench``): ``quick`` = maple size only, few rounds, no peers and no
    parallel contenders (under a minute); otherwise maple and 100k with the peers that are installed (several
    minutes).  Prints the tables, or the raw result dict as JSON with ``json_out``."""
    import contextlib
    import json
    import sys

    def bench():
        return run_bench(("maple",), rounds=8, peers=False, parallel=False) if quick else run_bench(("maple", "100k"), rounds=30)

    if json_out:  # the peers print banners on stdout (from Python and C): keep stdout pure JSON
        sys.stdout.flush()
        _c_flush()
        saved = os.dup(1)
        os.dup2(2, 1)
        try:
            with contextlib.redirect_stdout(sys.stderr):
                res = bench()
        finally:
            sys.stdout.flush()
            _c_flush()  # C stdio buffers what the peers printf'd: out to stderr before fd 1 returns
            os.dup2(saved, 1)
            os.close(saved)
    else:
        res = bench()
    print(json.dumps(res, indent=1, sort_keys=True) if json_out else format_bench(res))
    return 0


if __name__ == "__main__":  # pragma: no cover
    import sys

    argv = sys.argv[1:]
    flags = {a for a in argv if a.startswith("--")}
    sizes = tuple(a for a in argv if not a.startswith("--"))
    if sizes:
        import json

        out = run_bench(sizes, peers="--no-peers" not in flags)
        print(json.dumps(out, indent=1, sort_keys=True) if "--json" in flags else format_bench(out))
    else:
        sys.exit(main(json_out="--json" in flags, quick="--quick" in flags))
