"""Measure the GUI: frames per second of the full app, UI frame-time p90, the simulation's
speed on its worker thread, and the time to first frame.

Run ``python -m leafsim.measure.gui_bench [--species maple] [--frames 120] [--scales 1,0.5]
[--ground 1,0] [--reps 3] [--set mesh.spacing=0.006] [--json]``.  Each configuration runs the
real application (``LeafApp`` on hello_imgui, moderngl renderer, live simulation on the worker,
panels and plots) in a fresh process, so start-up is measured honestly from process spawn
(numba's on-disk cache is warmed by a first, discarded run).  Configurations are run in
interleaved repetitions (A B C D A B C D ...) because the machine may be shared: each row is
the median over the repetitions, and the 1-minute load average is recorded at every run.
Without a DISPLAY an Xvfb server is started for the duration.

Reported per configuration: fps (from the median frame time while playing), the frame
time's median and 90th percentile, CPU milliseconds per frame of the UI (its thread and
llvmpipe's rasteriser threads) and of the simulation worker (from /proc, per thread), the
simulated seconds per wall second reached meanwhile, time to the first window frame and to
the first frame with the leaf.  On a shared machine the UI's CPU ms per frame is the stable
number: fps follows from it and from how much of the cores the other processes leave.

``--passes`` instead times each render pass with ``glFinish`` around it (CPU milliseconds
of all threads, median of interleaved repetitions), in an EGL offscreen context and in the
window's context, at the 3-D view's size -- the profile that located the cost of the ground.

Goals (checked here, never in unit tests): ≥ 30 fps at maple size at render scale 1 with
ground and shadows; UI ≥ 30 fps (p90 frame ≤ 33 ms) at any mesh size; ≤ 2 s to the first frame.

``--passes``: Each pass of :meth:`leafsim.render.renderer.Renderer.render` is wrapped with ``glFinish``
before and after, and timed in CPU milliseconds of all the process's threads (llvmpipe
rasterises in its own threads; wall time without a finish only measures command submission,
which is how the ground once looked free offscreen).  The same leaf and view size are
measured in an EGL offscreen context and in the window's (hello_imgui) context, with
interleaved repetitions of four configurations (ground on/off × shadows -- ground shadow and
self-shadow -- on/off), each as while playing (the leaf moved since the last frame).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time

GOAL_FPS = 30.0


def _start_xvfb():
    for n in range(90, 140):
        if os.path.exists(f"/tmp/.X{n}-lock") or os.path.exists(f"/tmp/.X11-unix/X{n}"):
            continue
        proc = subprocess.Popen(["Xvfb", f":{n}", "-screen", "0", "1280x800x24", "-nolisten", "tcp"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for _ in range(100):
            if os.path.exists(f"/tmp/.X11-unix/X{n}"):
                return proc, f":{n}"
            if proc.poll() is not None:
                break
            time.sleep(0.05)
        proc.kill()
    raise RuntimeError("could not start Xvfb")


def _loadavg() -> float:
    try:
        return round(os.getloadavg()[0], 2)
    except OSError:
        return float("nan")


def _run_one(env, args, scale, ground) -> dict:
    e = dict(env)
    e["LEAFSIM_BENCH_T0"] = repr(time.time())
    cmd = [sys.executable, "-m", "leafsim.gui.bench_child", "window", "--species", args.species,
           "--frames", str(args.frames), "--scale", str(scale), "--ground", str(ground)]
    for s in args.set:
        cmd += ["--set", s]
    load0 = _loadavg()
    r = subprocess.run(cmd, env=e, capture_output=True, text=True, timeout=900)
    line = [ln for ln in r.stdout.splitlines() if ln.startswith("BENCH ")]
    if not line:
        raise RuntimeError(f"run failed (rc {r.returncode}): {r.stderr.strip()[-800:]}")
    row = json.loads(line[-1][6:])
    row["load"] = round((load0 + _loadavg()) / 2, 2)
    return row


def _median_rows(runs: list[dict]) -> dict:
    import numpy as np

    out = dict(runs[0])
    for k, v in runs[0].items():
        if isinstance(v, float) and k not in ("scale",):
            out[k] = float(f"{float(np.median([r.get(k, float('nan')) for r in runs])):.3g}")
    out["loads"] = [r["load"] for r in runs]
    out["fps_runs"] = [round(r["fps"], 1) for r in runs]
    return out


def _table(rows) -> str:
    keys = ["particles", "scale", "ground", "fps", "frame_ms", "p90_ms", "ui_cpu_ms", "sim_cpu_ms", "sim_s_per_s",
            "first_frame_s",
            "first_leaf_s", "fps_runs", "loads"]
    lines = [" ".join(f"{k:>13s}" for k in keys)]
    for r in rows:
        lines.append(" ".join(f"{str(r.get(k)):>13s}" for k in keys))
    return "\n".join(lines)


# ------------------------------------------------------------------ per-pass render profile (--passes)

def run_passes(env: dict, species: str, reps: int, sets=()) -> str:
    """Both contexts, as a text table (CPU ms per pass, medians)."""
    env = dict(env)
    from leafsim.gui.threads import render_threads

    env.setdefault("LP_NUM_THREADS", render_threads())
    lines = []
    for where in ("egl", "window"):
        cmd = [sys.executable, "-m", "leafsim.gui.bench_child", f"passes-{where}", "--species", species,
               "--reps", str(max(reps, 5))] + [a for kv in sets for a in ("--set", kv)]
        r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
        got = [ln for ln in r.stdout.splitlines() if ln.startswith("PASSES ")]
        if not got:
            raise RuntimeError(f"passes ({where}) failed: {r.stderr.strip()[-600:]}")
        for cfg, row in json.loads(got[-1][7:]).items():
            lines.append(f"{where:>7s} {cfg:>20s}  " + "  ".join(f"{k} {v:.1f}" for k, v in row.items()))
    try:
        load = os.getloadavg()[0]
    except OSError:
        load = float("nan")
    lines.append(f"(CPU ms of all threads per pass with glFinish around it, {species}, 1-min load {load:.2f})")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m leafsim.measure.gui_bench", description=__doc__.split("\n")[0])
    ap.add_argument("--species", default="maple")
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--scales", default="1.0,0.5", help="render scales of the 3-D view to compare")
    ap.add_argument("--ground", default="1,0", help="ground plane + shadows on/off (comma-separated 1/0)")
    ap.add_argument("--reps", type=int, default=3, help="interleaved repetitions of every configuration")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="parameter override (e.g. mesh.spacing=0.006)")
    ap.add_argument("--passes", action="store_true", help="time each render pass (EGL and window context)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    env = dict(os.environ)
    xvfb = None
    if not env.get("DISPLAY"):
        if shutil.which("Xvfb") is None:
            print("bench_gui: no DISPLAY and no Xvfb", file=sys.stderr)
            return 2
        xvfb, env["DISPLAY"] = _start_xvfb()
    try:
        if args.passes:
            print(run_passes(env, args.species, args.reps, args.set))
            return 0
        configs = [(float(s), int(g)) for s in args.scales.split(",") for g in args.ground.split(",")]
        _run_one(env, args, *configs[0])  # warms numba's and Mesa's caches; discarded
        runs: dict = {c: [] for c in configs}
        for _ in range(max(args.reps, 1)):
            for c in configs:
                runs[c].append(_run_one(env, args, *c))
    except RuntimeError as e:
        print(f"bench_gui: {e}", file=sys.stderr)
        return 1
    finally:
        if xvfb is not None:
            xvfb.terminate()
            xvfb.wait(10)
    rows = [_median_rows(runs[c]) for c in configs]
    if args.json:
        print(json.dumps({"rows": rows, "runs": runs and {f"{k[0]}/{k[1]}": v for k, v in runs.items()}}))
    else:
        print(_table(rows))
        ok = [r for r in rows if r["scale"] >= 1.0 and r["ground"]]
        for r in ok:
            verdict = "meets" if r["fps"] >= GOAL_FPS else "misses"
            print(f"goal: {r['fps']:.1f} fps at scale 1 with ground and shadows {verdict} {GOAL_FPS:g} fps")
        print(f"(median of {args.reps} interleaved runs; 1-min load average per run in 'loads', {os.cpu_count()} cores)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
