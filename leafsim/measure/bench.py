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
import time

import numpy as np

from leafsim.appearance.reflectance import pigments_to_rgb
from leafsim.config.params import ParamSet
from leafsim.measure.memory import memory, memory_subprocess
from leafsim.measure.models import EFFECTS, PASSES, bench_params, build_bench_model, folded_state
from leafsim.measure.parallel import parallel_vs_serial
from leafsim.measure.springs import spring_race
from leafsim.measure.timing import interleaved, load_average, nothing, summary
from leafsim.sim.model import Model
from leafsim.sim.pigments import init_pigments, step_pigments


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
    from leafsim.sim.effects.osmosis import Osmosis
    from leafsim.sim.effects.shrink import Shrink

    st = model.state()
    st.particle_water[:] *= np.linspace(0.6, 1.0, model.particle_count)
    osm = Osmosis(model)
    osm.configure(params)
    sh = Shrink(model)
    sh.configure(params)
    return {"osmosis": (nothing, lambda: osm.apply(st)), "shrink": (nothing, lambda: sh.apply(st)),
            "colour step": (nothing, _colour_step_fn(model, params))}


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
            reset = nothing  # the flat leaf keeps lying on the ground: no reset needed
        jobs[name], dyn[name] = (reset, run), d
    jobs.update(_pass_jobs(model, params))
    jobs.update(_stage_jobs(model, params))
    load = load_average()
    ms = {k: summary(v) for k, v in interleaved(jobs, rounds).items()}
    med = {k: v["median_ms"] for k, v in ms.items()}
    ns = {k: med[job] * 1e6 / PASSES / c for k, job, c in
          (("spring", "springs ×10", model.spring_count), ("hinge", "hinges ×10", model.hinge_count),
           ("volume", "volumes ×10", model.vol_count),
           ("hinge, one at a time", "hinges ×10, one at a time", model.hinge_count),
           ("volume, one at a time", "volumes ×10, one at a time", model.vol_count))}
    d = dyn["frame"]
    sun = sun_bench(model, params, rounds=min(rounds, 5)) if model.particle_count < 50000 else None
    return {"ms": ms, "load": load, "sun": sun, "ns_per": ns, "hinge_vs_spring": ns["hinge"] / ns["spring"],
            "volume_vs_spring": ns["volume"] / ns["spring"],
            "hinge_vs_spring_one_at_a_time": ns["hinge, one at a time"] / ns["spring"],
            "volume_vs_spring_one_at_a_time": ns["volume, one at a time"] / ns["spring"],
            "contact_share": max(0.0, 1.0 - med["frame, no self-collision"] / med["frame"]),
            "contact_share_folded": max(0.0, 1.0 - med["frame folded, no self-collision"] / med["frame folded"]),
            "contact_searches": d.contact_searches, "substeps": d.substeps, "iterations": d.iters,
            "full_step_ms": med["osmosis"] + med["shrink"] + med["frame"]}


def sun_bench(model: Model, params: ParamSet, rounds: int = 5) -> dict:
    """Sun's explicit integrator (``dynamics.integrator = sun``) against the XPBD frame on the
    fresh leaf, interleaved (few rounds: a Sun frame takes thousands of steps); returns both
    frames' stats, the steps per frame, the largest ω h allowed and the cost ratio."""
    sp = params.with_overrides({"dynamics.integrator": "sun"})
    _, run_x, _ = _frame_job(model, params, EFFECTS, model.state)
    reset, run_s, ds = _frame_job(model, sp, EFFECTS, model.state)
    ms = {k: summary(v) for k, v in interleaved({"xpbd": (nothing, run_x), "sun": (reset, run_s)}, rounds).items()}
    return {"ms": ms, "steps": ds.sun_steps, "courant": ds.sun_courant,
            "ratio": ms["sun"]["median_ms"] / ms["xpbd"]["median_ms"]}


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
        if f.get("sun"):
            u = f["sun"]
            lines.append(f"  Sun's explicit integrator (ω h ≤ {u['courant']:g}): {u['steps']} steps per frame, "
                         f"{u['ms']['sun']['median_ms']:.1f} ms (p90 {u['ms']['sun']['p90_ms']:.1f}) against the XPBD "
                         f"frame's {u['ms']['xpbd']['median_ms']:.2f} ms (p90 {u['ms']['xpbd']['p90_ms']:.2f}): "
                         f"{u['ratio']:.0f}×")
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



def _cpu_name() -> str | None:
    """The processor's model name (Linux), for the record of a benchmark."""
    try:
        for line in open("/proc/cpuinfo", encoding="utf-8", errors="replace"):
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return None

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
    if json_out:
        from leafsim.base.provenance import provenance

        from leafsim.base.provenance import command_line

        res = {**res, "provenance": provenance(command=command_line(), cpus=os.cpu_count(),
                                               cpu=_cpu_name())}
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
