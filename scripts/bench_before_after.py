"""Before/after of the issue-10 kernel work, interleaved in one process (same load for both):
the pre-rewrite kernels (frozen in tests/_pbd_reference.py, driven as the old
``Dynamics.apply`` did) against today's, on the bench's models.

    .venv/bin/python scripts/bench_before_after.py [maple|100k ...] [--rounds N] [--json OUT]

Rows: the production frame on a flat leaf at rest and on a folded leaf in self-contact, each
with and without self-collision (the contact share); one pass of each constraint kind (ns per
constraint, hinge/spring ratio); the old coloured-parallel frame next to the old serial one.
Every row records the 1-minute load average when its size was measured."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

import leafsim  # noqa: E402,F401  (first: it keys numba's cache to the kernel sources)
import _pbd_reference as ref  # noqa: E402
from _reference_dynamics import RefDynamics  # noqa: E402

from leafsim.bench import EFFECTS, PASSES, build_bench_model, folded_state, interleaved  # noqa: E402
from leafsim.params import ParamSet  # noqa: E402
from leafsim.sim.effects import Dynamics  # noqa: E402
from leafsim.sim.kernels import blocked as kb  # noqa: E402
from leafsim.sim.kernels import pbd as kp  # noqa: E402


def _frame_pair(m, p, eff, state_fn, reset_each, par_before=False):
    """(before job, after job) for one frame setting."""
    d = Dynamics(m)
    d.configure(p, eff)
    r = RefDynamics(m, d, p, par=par_before)
    snap = state_fn()
    a, b = snap.copy(), snap.copy()

    def resetter(st):
        def reset():
            if reset_each:
                st.particle_q[:] = snap.particle_q
                st.particle_qd[:] = snap.particle_qd
        return reset

    return (resetter(a), lambda: r.apply(a)), (resetter(b), lambda: d.apply(b))


def _kind_jobs(m, p):
    """One pass ×10 of each constraint kind, before (reference colour loops) and after."""
    d = Dynamics(m)
    d.configure(p, EFFECTS)
    st = folded_state(m)
    d.gather(st)
    halpha_m = np.empty_like(d.halpha)
    halpha_m[d.hperm] = d.halpha
    q0 = st.particle_q + np.random.default_rng(3).normal(0, 0.02 * m.spacing, st.particle_q.shape)
    q = q0.copy()
    e = np.zeros(1, np.int64)
    S, H, V = m.spring_count, m.hinge_count, m.vol_count
    lam_s, lam_h, lam_v = np.zeros(S), np.zeros(H), np.zeros(V)

    def reset():
        q[:] = q0

    def old(scs, hcs, vcs):
        def run():
            for _ in range(PASSES):
                ref.iteration_ser(q, d.invm, m.spring_ij, st.spring_rest, d.salpha, lam_s, scs, m.hinge_idx,
                                  st.hinge_rest, halpha_m, lam_h, hcs, 1.0, m.vol_idx, st.vol_rest, lam_v, vcs, e)
        return run

    def new(kind):
        def run():
            for _ in range(PASSES):
                if kind == "spring":
                    kp.spring_pass(q, d.sij, d.srec, lam_s, 0, S)
                elif kind == "hinge":
                    kb.hinges_blocked(q, d.hidx, d.hrec, lam_h, 1.0, d.hblocks, d.blockbuf)
                else:
                    kb.volumes_blocked(q, d.vidx, d.vrec, d.vblocks, d.blockbuf)
        return run

    return {"before spring": (reset, old(m.spring_colour_start, e, e)), "after spring": (reset, new("spring")),
            "before hinge": (reset, old(e, m.hinge_colour_start, e)), "after hinge": (reset, new("hinge")),
            "before volume": (reset, old(e, e, m.vol_colour_start)), "after volume": (reset, new("volume"))}


def measure(size: str, rounds: int) -> dict:
    m = build_bench_model(size)
    p = ParamSet()
    noself = {**EFFECTS, "self_collision": False}
    jobs = {}
    for name, eff, sfn, reset_each in (("frame", EFFECTS, m.state, False), ("frame, no self-collision", noself, m.state, False),
                                       ("frame folded", EFFECTS, lambda: folded_state(m), True),
                                       ("frame folded, no self-collision", noself, lambda: folded_state(m), True)):
        jobs[f"before {name}"], jobs[f"after {name}"] = _frame_pair(m, p, eff, sfn, reset_each)
    jobs["before frame, coloured parallel"], _ = _frame_pair(m, p, EFFECTS, m.state, False, par_before=True)
    jobs.update(_kind_jobs(m, p))
    load0 = os.getloadavg()[0]
    ms = interleaved(jobs, rounds)
    st = {k: {"median_ms": float(np.median(v)), "p90_ms": float(np.percentile(v, 90))} for k, v in ms.items()}
    out = {"particles": m.particle_count, "load_start": load0, "load_end": os.getloadavg()[0], "rows": st}
    for when in ("before", "after"):
        ns = {k: st[f"{when} {k}"]["median_ms"] * 1e6 / PASSES / c
              for k, c in (("spring", m.spring_count), ("hinge", m.hinge_count), ("volume", m.vol_count))}
        out[when] = {"ns_per": ns, "hinge_vs_spring": ns["hinge"] / ns["spring"], "volume_vs_spring": ns["volume"] / ns["spring"],
                     "contact_share": 1 - st[f"{when} frame, no self-collision"]["median_ms"] / st[f"{when} frame"]["median_ms"],
                     "contact_share_folded": 1 - st[f"{when} frame folded, no self-collision"]["median_ms"]
                     / st[f"{when} frame folded"]["median_ms"]}
    return out


def main(argv):
    sizes = [a for a in argv if not a.startswith("--") and not a.isdigit() and not a.endswith(".json")] or ["maple"]
    rounds = int(argv[argv.index("--rounds") + 1]) if "--rounds" in argv else 15
    res = {s: measure(s, rounds if s != "100k" else max(3, rounds // 4)) for s in sizes}
    for s, r in res.items():
        print(f"[{s}] {r['particles']} particles, 1-min load {r['load_start']:.1f} → {r['load_end']:.1f}")
        for k, v in r["rows"].items():
            print(f"  {k:42s} {v['median_ms']:10.3f} ms  p90 {v['p90_ms']:10.3f}")
        for when in ("before", "after"):
            w = r[when]
            print(f"  {when}: ns/spring {w['ns_per']['spring']:.1f}, hinge {w['ns_per']['hinge']:.1f} "
                  f"({w['hinge_vs_spring']:.1f}×), volume {w['ns_per']['volume']:.1f} ({w['volume_vs_spring']:.1f}×); "
                  f"contact share flat {100 * w['contact_share']:.1f} %, folded {100 * w['contact_share_folded']:.1f} %")
    if "--json" in argv:
        Path(argv[argv.index("--json") + 1]).write_text(json.dumps(res, indent=1))


if __name__ == "__main__":
    main(sys.argv[1:])
